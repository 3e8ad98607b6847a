//! A cheap, deterministic, noisy stand-in for a walking robot over the same
//! parameter names as the NAO model, so the evolving loop and the farm can be
//! tested in milliseconds and benchmarked without physics.
//!
//! Forward distance, lateral drift and fall probability are smooth functions
//! of p with an optimum inside the paper's space L; all noise comes from the
//! trial's seed. It must never be mistaken for the robot: it exists for tests.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::TrialRun;

/// (name, optimum, width): the penalty is Σ ((v − optimum) / width)².
const SHAPE: &[(&str, f64, f64)] = &[
    ("ThighRelHip2_Z", -0.038, 0.03),
    ("ratio_flexion", 0.80, 0.12),
    ("long_offset_MidAnkles_2_Torso_Init", 0.014, 0.02),
    ("height_lift", 0.038, 0.03),
];

fn value(params: &[(String, f64)], name: &str) -> f64 {
    params
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, v)| *v)
        .or_else(|| protocol::params::find(name).map(|p| p.default))
        .unwrap_or(0.0)
}

pub(crate) fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    // Box–Muller; one value per call keeps the stream simple.
    let u1: f64 = rng.random_range(f64::EPSILON..1.0);
    let u2: f64 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Runs one synthetic trial of `duration_s` simulated seconds.
#[must_use]
pub fn trial(params: &[(String, f64)], seed: u64, duration_s: f64) -> TrialRun {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let penalty: f64 = SHAPE
        .iter()
        .map(|(n, c, w)| ((value(params, n) - c) / w).powi(2))
        .sum();
    let step = value(params, "xlength_step_max");
    // Speed grows with the step length and saturates; too long a step hurts balance.
    let speed = 0.6 * (step / 0.12).min(1.2) * (-0.5 * penalty).exp();
    let step_risk = ((step - 0.12) / 0.03).max(0.0).powi(2);
    let p_fall = 1.0 / (1.0 + (-(2.0 * (penalty + step_risk) - 4.0)).exp());
    let x_clean = speed * duration_s;
    let x = x_clean * (1.0 + 0.025 * gauss(&mut rng));
    let y = x_clean * (0.04 + 0.02 * penalty.min(5.0)) * gauss(&mut rng);
    let fall: f64 = rng.random();
    if fall < p_fall {
        let t = duration_s * rng.random_range(0.05..1.0);
        TrialRun {
            fell: true,
            x_m: x * t / duration_s,
            y_m: y * t / duration_s,
            fall_time_s: Some(t),
            sim_time_s: t,
        }
    } else {
        TrialRun {
            fell: false,
            x_m: x,
            y_m: y,
            fall_time_s: None,
            sim_time_s: duration_s,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(thigh: f64, step: f64) -> Vec<(String, f64)> {
        vec![
            ("ThighRelHip2_Z".into(), thigh),
            ("xlength_step_max".into(), step),
        ]
    }

    #[test]
    fn deterministic_in_the_seed() {
        let a = trial(&p(-0.04, 0.08), 5, 10.0);
        let b = trial(&p(-0.04, 0.08), 5, 10.0);
        assert_eq!(a, b);
        assert_ne!(a, trial(&p(-0.04, 0.08), 6, 10.0));
    }

    #[test]
    fn optimum_inside_the_space_and_falls_near_the_edges() {
        let run = |thigh, step| {
            let rs: Vec<TrialRun> = (0..200).map(|s| trial(&p(thigh, step), s, 10.0)).collect();
            let ok: Vec<&TrialRun> = rs.iter().filter(|r| !r.fell).collect();
            #[allow(clippy::cast_precision_loss)]
            let s = ok.len() as f64 / 200.0;
            #[allow(clippy::cast_precision_loss)]
            let mx = ok.iter().map(|r| r.x_m).sum::<f64>() / ok.len().max(1) as f64;
            (s, mx)
        };
        let (s_mid, mx_mid) = run(-0.038, 0.12);
        let (s_edge, mx_edge) = run(-0.10, 0.12);
        let (s_long, _) = run(-0.038, 0.20);
        assert!(s_mid > 0.9 && mx_mid > 4.0, "{s_mid} {mx_mid}");
        assert!(mx_edge < mx_mid);
        assert!(s_edge < s_mid && s_long < 0.5, "{s_edge} {s_long}");
    }
}
