//! The one measurement of a trial, from the trial model to the journal and
//! the wire: whether the robot fell, where its torso went, when.

use serde::{Deserialize, Serialize};

/// What one trial measured (the field order is the journal's encoding).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Measurement {
    /// Whether the robot fell.
    pub fell: bool,
    /// Torso displacement forward (x), m.
    pub x_m: f64,
    /// Torso displacement left (y), m.
    pub y_m: f64,
    /// Simulated time of the fall, s (present exactly when it fell).
    pub fall_time_s: Option<f64>,
    /// Simulated time run, s.
    pub sim_time_s: f64,
}

/// The most a trial's torso can travel, m.
pub const PLAUSIBLE_DISTANCE_M: f64 = 100.0;

impl Measurement {
    /// Whether this could be a real trial of `duration_s` (the coordinator's
    /// check of every outcome, and a worker's of every program's answer).
    pub fn plausible(&self, duration_s: f64) -> Result<(), String> {
        if self.x_m.abs() > PLAUSIBLE_DISTANCE_M || self.y_m.abs() > PLAUSIBLE_DISTANCE_M {
            return Err(format!(
                "x {} m, y {} m (beyond {PLAUSIBLE_DISTANCE_M} m)",
                self.x_m, self.y_m
            ));
        }
        if !(0.0..=duration_s + 1e-6).contains(&self.sim_time_s) {
            return Err(format!(
                "simulated time {} s outside [0, {duration_s}] s",
                self.sim_time_s
            ));
        }
        if self
            .fall_time_s
            .is_some_and(|t| t > self.sim_time_s + 1e-9 || t < 0.0)
        {
            return Err("fall time after the simulated time".into());
        }
        Ok(())
    }

    /// Checks every number is finite and the fall is consistent.
    pub fn check(&self) -> Result<(), String> {
        for (name, v) in [
            ("x_m", self.x_m),
            ("y_m", self.y_m),
            ("sim_time_s", self.sim_time_s),
        ] {
            if !v.is_finite() {
                return Err(format!("non-finite result: {name} = {v}"));
            }
        }
        match self.fall_time_s {
            Some(t) if !t.is_finite() => Err(format!("non-finite result: fall_time_s = {t}")),
            _ if self.sim_time_s < 0.0 => Err("sim_time_s is negative".into()),
            f if f.is_some() != self.fell => {
                Err("fall_time_s must be present exactly when fell is true".into())
            }
            _ => Ok(()),
        }
    }
}
