//! A worker's fingerprint: the hash of fixed probe trials it runs at start,
//! and of its naofarm version. Two workers with one fingerprint return the
//! same bits for the same trial; the probe catches a different build as well
//! as a host whose maths library (glibc picks FMA variants per CPU at run
//! time) or architecture gives other bits. A run takes trials from workers of
//! one fingerprint only (the coordinator journals it), so its history never
//! mixes bits of two kinds of machine.

use std::sync::OnceLock;

use protocol::{Physics, TrialModel, TrialRequest};
use sha3::{Digest, Sha3_256};

/// `NAOFARM_FAULT_FINGERPRINT=1` (a test hook, switched on at run time): the
/// worker reports another fingerprint, as a worker of another build would.
pub const FINGERPRINT_FAULT_VAR: &str = "NAOFARM_FAULT_FINGERPRINT";

/// The probe trials: the expert NAO walking for 3 simulated seconds on
/// type 0 and on type 4, whose toes have joints of their own, and the
/// synthetic model.
fn probes() -> Vec<TrialRequest> {
    let req = |model, robot_type, duration_s| TrialRequest {
        run: "probe".into(),
        iteration: 0,
        trial: 0,
        seed: 0x6e61_6f66_6172_6d00,
        model,
        program: None,
        robot_type,
        duration_s,
        params: vec![],
        dispatch: 0,
        physics: Physics::default(),
    };
    vec![
        req(TrialModel::Nao, 0, 3.0),
        req(TrialModel::Nao, 4, 3.0),
        req(TrialModel::Synthetic, 0, 10.0),
    ]
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
        // Type 4's toes run code that type 0 never reaches: they have a probe.
        assert!(probes().iter().any(|p| p.robot_type == 4));
    }
}
