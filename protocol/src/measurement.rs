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

impl Measurement {
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
