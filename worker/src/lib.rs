//! The worker side of naofarm: trial models and the stateless zenoh worker service.
//!
//! Modules: [`synthetic`] (a cheap stand-in model for tests and farm benchmarks).
//! [`run_trial`] is the one trial interface, a pure function of the request.
//!
//! This crate must not keep state between trials or decide anything about
//! the optimisation: it runs what it is asked and reports what happened.
#![warn(missing_docs)]

pub mod nao;
pub mod service;
pub mod synthetic;

use protocol::{TrialModel, TrialRequest};

/// What one trial produced, before the worker adds its identity.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialRun {
    /// Whether the robot fell.
    pub fell: bool,
    /// Final torso x (forward), m.
    pub x_m: f64,
    /// Final torso y (left), m.
    pub y_m: f64,
    /// Simulated time of the fall, s.
    pub fall_time_s: Option<f64>,
    /// Simulated time run, s.
    pub sim_time_s: f64,
}

/// Why a trial could not run.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TrialError {
    /// The requested model is not available in this build.
    #[error("trial model {0:?} is not available in this worker build")]
    Unavailable(TrialModel),
    /// The parameters cannot build a robot.
    #[error("cannot build the robot: {0}")]
    Model(String),
}

/// Runs one trial: a pure function of the request.
pub fn run_trial(req: &TrialRequest) -> Result<TrialRun, TrialError> {
    match req.model {
        TrialModel::Synthetic => Ok(synthetic::trial(&req.params, req.seed, req.duration_s)),
        TrialModel::Nao => Err(TrialError::Unavailable(TrialModel::Nao)),
    }
}
