//! A cheap, deterministic, noisy stand-in for a walking robot over the same
//! parameter names as the NAO model, so the evolving loop and the farm can be
//! tested in milliseconds and benchmarked without physics.
//!
//! Forward distance, lateral drift and fall probability are smooth functions
//! of p with an optimum inside the paper's space L; all noise comes from the
//! trial's seed. It must never be mistaken for the robot: it exists for tests.

use protocol::params::{Param, ParamValues};
use rand::Rng;

use crate::{
    noise::{gauss, stream},
    Measurement,
};

/// (parameter, optimum, width): the penalty is Σ ((v − optimum) / width)².
pub const SHAPE: &[(Param, f64, f64)] = &[
    (Param::ThighRelHip2Z, -0.038, 0.03),
    (Param::RatioFlexion, 0.80, 0.12),
    (Param::LongOffset, 0.014, 0.02),
    (Param::HeightLift, 0.038, 0.03),
];

/// The step length where speed saturates just before the balance penalty
/// (the best `xlength_step_max` when the rest of [`SHAPE`] is at its optimum), m.
pub const STEP_OPTIMUM: f64 = 0.125;

/// Runs one synthetic trial of `duration_s` simulated seconds.
#[must_use]
pub fn trial(params: &ParamValues, seed: u64, duration_s: f64) -> Measurement {
    let mut rng = stream(seed);
    let penalty: f64 = SHAPE
        .iter()
        .map(|(p, c, w)| ((params.value(*p) - c) / w).powi(2))
        .sum();
    let step = params.value(Param::StepLength);
    // Speed grows with the step length and saturates; too long a step hurts balance.
    let speed = 0.6 * (step / 0.12).min(1.2) * libm::exp(-0.5 * penalty);
    let step_risk = ((step - 0.12) / 0.03).max(0.0).powi(2);
    let p_fall = 1.0 / (1.0 + libm::exp(-(2.0 * (penalty + step_risk) - 4.0)));
    let x_clean = speed * duration_s;
    let x = x_clean * (1.0 + 0.025 * gauss(&mut rng));
    let y = x_clean * (0.04 + 0.02 * penalty.min(5.0)) * gauss(&mut rng);
    let fall: f64 = rng.random();
    if fall < p_fall {
        let t = duration_s * rng.random_range(0.05..1.0);
        Measurement {
            fell: true,
            x_m: x * t / duration_s,
            y_m: y * t / duration_s,
            fall_time_s: Some(t),
            sim_time_s: t,
        }
    } else {
        Measurement {
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

    fn p(thigh: f64, step: f64) -> ParamValues {
        let mut v = ParamValues::default();
        v.set(Param::ThighRelHip2Z, thigh).unwrap();
        v.set(Param::StepLength, step).unwrap();
        v
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
            let rs: Vec<Measurement> = (0..200).map(|s| trial(&p(thigh, step), s, 10.0)).collect();
            let ok: Vec<&Measurement> = rs.iter().filter(|r| !r.fell).collect();
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
