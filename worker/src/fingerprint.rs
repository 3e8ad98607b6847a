//! A worker's fingerprint: the hash of fixed probe trials it runs at start,
//! and of its naofarm version. Two workers with one fingerprint return the
//! same bits for the same trial; the probe catches a different build as well
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
/// seconds at the default physics; the closed loop on type 4, whose toes
/// have physics of their own (`nao::sim::TOE_STOP_WINDOW_DEG`), and on the
/// firm file's physics, the vendored rapier's stops; and the synthetic
/// model.
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
    let closed = req(TrialModel::Nao, WalkEngine::ClosedLoop, 3.0);
    v.push(TrialRequest {
        robot_type: 4,
        ..closed.clone()
    });
    v.push(TrialRequest {
        physics: Physics::firm(),
        ..closed
    });
    v.push(req(TrialModel::Synthetic, WalkEngine::default(), 10.0));
    v
}

/// Computes the fingerprint (about 0.1 s of CPU: the probes are real trials).
#[must_use]
pub fn compute() -> u64 {
    let mut h = Sha3_256::new();
    h.update(env!("CARGO_PKG_VERSION").as_bytes());
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
        // Type 4's toes and the firm stops run code that type 0 at the
        // default physics never reaches: each has a probe.
        assert!(probes().iter().any(|p| p.robot_type == 4));
        assert!(probes().iter().any(|p| p.physics.firm_stops));
    }
}
