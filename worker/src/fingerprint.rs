//! A worker's fingerprint: the hash of fixed probe trials it runs at start,
//! of the parameter registry it accepts, and of its naofarm version. Two
//! workers with one fingerprint return the same bits for the same trial and
//! accept the same parameters (a build that does not know a parameter a run
//! sends would fail its trials, and stop the run, instead of being refused);
//! the probe catches a different build as well
//! as a host whose maths library (glibc picks FMA variants per CPU at run
//! time) or architecture gives other bits. A run takes trials from workers of
//! one fingerprint only (the coordinator journals it), so its history never
//! mixes bits of two kinds of machine.

use std::sync::OnceLock;

use protocol::{Physics, TrialModel, TrialRequest, WalkEngine};
use sha3::{Digest, Sha3_256};

/// `NAOFARM_FAULT_FINGERPRINT=1` (a test hook, switched on at run time): the
/// worker reports another fingerprint, as a worker of another build would.
pub const FINGERPRINT_FAULT_VAR: &str = "NAOFARM_FAULT_FINGERPRINT";

/// The probe trials: the expert NAO on each walk engine for 3 simulated
/// seconds, and the synthetic model, at the default physics.
fn probes() -> Vec<TrialRequest> {
    let req = |model, walk, duration_s| TrialRequest {
        run: "probe".into(),
        iteration: 0,
        trial: 0,
        seed: 0x6e61_6f66_6172_6d00,
        model,
        robot_type: 0,
        duration_s,
        params: vec![],
        dispatch: 0,
        physics: Physics::default(),
        walk,
    };
    let mut v: Vec<TrialRequest> = WalkEngine::ALL
        .iter()
        .map(|(_, w)| req(TrialModel::Nao, *w, 3.0))
        .collect();
    v.push(req(TrialModel::Synthetic, WalkEngine::default(), 10.0));
    v
}

/// Computes the fingerprint (about 0.1 s of CPU: the probes are real trials).
#[must_use]
pub fn compute() -> u64 {
    compute_with(protocol::params::KNOWN)
}

/// The fingerprint of a worker that accepts the parameters of `registry`.
fn compute_with(registry: &[protocol::params::KnownParam]) -> u64 {
    let mut h = Sha3_256::new();
    h.update(env!("CARGO_PKG_VERSION").as_bytes());
    for k in registry {
        h.update(k.name.as_bytes());
        for v in [k.min, k.max, k.default] {
            h.update(v.to_bits().to_le_bytes());
        }
    }
    for p in probes() {
        match crate::run_trial(&p) {
            Ok(m) => {
                h.update([u8::from(m.fell)]);
                for v in [m.x_m, m.y_m, m.fall_time_s.unwrap_or(-1.0), m.sim_time_s] {
                    h.update(v.to_bits().to_le_bytes());
                }
            }
            Err(e) => h.update(e.to_string().as_bytes()),
        }
    }
    let d = h.finalize();
    let mut b = [0u8; 8];
    b.copy_from_slice(&d[..8]);
    let fp = u64::from_le_bytes(b);
    if std::env::var_os(FINGERPRINT_FAULT_VAR).is_some() {
        fp ^ 0xdead_beef
    } else {
        fp
    }
}

/// This process's fingerprint, computed once.
pub fn of_this_worker() -> u64 {
    static FP: OnceLock<u64> = OnceLock::new();
    *FP.get_or_init(compute)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A build that knows one parameter fewer (as before `step_period` and
    /// `double_support`), or the same names with other ranges, has another
    /// fingerprint, so a run refuses it rather than have it fail trials.
    #[test]
    fn the_fingerprint_covers_the_parameter_registry() {
        let known = protocol::params::KNOWN;
        let all = compute_with(known);
        assert_eq!(all, compute());
        assert_ne!(all, compute_with(&known[..known.len() - 2]));
        let mut wider = known.to_vec();
        wider[0].max += 0.01;
        assert_ne!(all, compute_with(&wider));
    }

    #[test]
    fn the_fingerprint_is_a_function_of_the_probe_bits() {
        assert_eq!(compute(), compute());
        assert_eq!(protocol::wire::show_fingerprint(0xab), "00000000000000ab");
        // The probes are real trials whose bits feed the hash: a probe of
        // another physics gives other bits.
        let p = &probes()[0];
        let a = crate::run_trial(p).unwrap();
        let b = crate::run_trial(&TrialRequest {
            physics: Physics {
                substeps: p.physics.substeps + 1,
                ..p.physics
            },
            ..p.clone()
        })
        .unwrap();
        assert_ne!(a.x_m.to_bits(), b.x_m.to_bits());
    }
}
