//! The worker side of naofarm: trial models and the stateless zenoh worker service.
//!
//! Modules: [`nao`] (the league's NAO in rapier3d, its walk and trials),
//! [`synthetic`] (a cheap stand-in model for tests and farm benchmarks),
//! [`service`] (the zenoh worker), [`share`] (which run gets a free slot:
//! fair shares by priority), [`fault`] (run-time fault hooks for tests),
//! [`noise`] (the seeded noise both models draw from), [`fingerprint`] (the
//! hash of probe trials that tells workers of the same bits), [`program`]
//! (trial programs the worker's owner registered: any simulator, run once
//! per trial with the trial as JSON), [`served`] (programs kept running in
//! a slot between a run's trials, for those that serve), [`job`] (a
//! program's processes as one job: contained, limited, tied to the worker,
//! in a slot of the host's).
//! [`run_trial`] is the one trial interface, a pure function of the request.
//!
//! This crate must not keep state between trials or decide anything about
//! the optimisation: it runs what it is asked and reports what happened. A
//! program kept between trials ([`served`]) is a process it runs, not state
//! it keeps: the program answers each trial as a fresh one would.
#![warn(missing_docs)]

pub mod fault;
pub mod fingerprint;
pub mod job;
pub mod nao;
pub mod noise;
pub mod program;
pub mod served;
pub mod service;
pub mod share;
pub mod synthetic;

use protocol::{TrialModel, TrialRequest};

pub use protocol::measurement::Measurement;

/// Why a trial could not run.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TrialError {
    /// The parameters cannot build a robot.
    #[error("cannot build the robot: {0}")]
    Model(String),
    /// A program's trial: the worker service runs it ([`program::run`]).
    #[error("a trial of the program `{0}` runs in the worker service, not as a function")]
    Program(String),
}

/// The request's parameters by name (unset ones at expert).
fn params_of(req: &TrialRequest) -> Result<protocol::params::ParamValues, TrialError> {
    protocol::params::ParamValues::from_named(&req.params)
        .map_err(|e| TrialError::Model(e.to_string()))
}

/// How far the request's walk plans to carry the robot over its trial, m
/// ([`nao::trial::planned_travel_m`]); none for the synthetic model.
pub fn planned_x_m(req: &TrialRequest) -> Result<Option<f64>, TrialError> {
    planned(req, |params| {
        nao::trial::planned_travel_m(req.robot_type, params, req.duration_s)
            .map_err(|e| e.to_string())
    })
}

/// The full step the request's walk plans, m: `xlength_step_max`, or
/// shorter where `step_reach` caps it ([`nao::trial::planned_step_m`]);
/// none for the synthetic model.
pub fn planned_step_m(req: &TrialRequest) -> Result<Option<f64>, TrialError> {
    planned(req, |params| {
        nao::trial::planned_step_m(req.robot_type, params).map_err(|e| e.to_string())
    })
}

/// What `plan` says of a NAO request's parameters; none for other models.
fn planned(
    req: &TrialRequest,
    plan: impl FnOnce(&protocol::params::ParamValues) -> Result<f64, String>,
) -> Result<Option<f64>, TrialError> {
    if req.model != TrialModel::Nao {
        return Ok(None);
    }
    plan(&params_of(req)?).map(Some).map_err(TrialError::Model)
}

/// Runs one trial of a built-in model: a pure function of the request.
pub fn run_trial(req: &TrialRequest) -> Result<Measurement, TrialError> {
    run_trial_with_footwork(req).map(|(m, _)| m)
}

/// [`run_trial`], with how the NAO's feet covered the distance
/// ([`nao::footwork`]; none for the synthetic model).
pub fn run_trial_with_footwork(
    req: &TrialRequest,
) -> Result<(Measurement, Option<nao::footwork::Footwork>), TrialError> {
    if req.model == TrialModel::Program {
        return Err(TrialError::Program(req.program.clone().unwrap_or_default()));
    }
    let params = params_of(req)?;
    match req.model {
        TrialModel::Program => Err(TrialError::Program(req.program.clone().unwrap_or_default())),
        TrialModel::Synthetic => Ok((synthetic::trial(&params, req.seed, req.duration_s), None)),
        TrialModel::Nao => {
            let t = nao::trial::run(
                req.robot_type,
                &params,
                req.seed,
                req.duration_s,
                nao::sim::SimSettings::with_physics(&req.physics),
                nao::trial::Engine::WALK,
            )
            .map_err(|e| TrialError::Model(e.to_string()))?;
            Ok((t.measurement, Some(t.footwork)))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::Physics;

    fn request(physics: Physics) -> TrialRequest {
        TrialRequest {
            run: "r".into(),
            iteration: 0,
            trial: 0,
            seed: 3,
            model: TrialModel::Nao,
            program: None,
            robot_type: 0,
            duration_s: 2.0,
            params: vec![],
            dispatch: 0,
            physics,
        }
    }

    #[test]
    fn the_experiments_physics_drive_the_simulation() {
        let d = Physics::default();
        let s = nao::sim::SimSettings::default();
        assert_eq!(
            (
                d.substeps,
                d.solver_iterations as usize,
                d.pgs_iterations as usize
            ),
            (s.substeps, s.solver_iterations, s.pgs_iterations)
        );
        let coarse = run_trial(&request(d)).unwrap();
        assert_eq!(coarse, run_trial(&request(d)).unwrap());
        let fine = run_trial(&request(Physics { substeps: 5, ..d })).unwrap();
        assert_ne!(coarse.x_m.to_bits(), fine.x_m.to_bits());
        let stiff = run_trial(&request(Physics {
            pgs_iterations: 40,
            ..d
        }))
        .unwrap();
        assert_ne!(coarse.x_m.to_bits(), stiff.x_m.to_bits());
    }
}
