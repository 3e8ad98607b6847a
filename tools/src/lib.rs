//! naofarm's tooling around the optimiser, kept out of the coordinator's
//! core: CLOP's benchmark against baselines, the local tuning of any noisy
//! program, and what they need.
//!
//! Modules: [`problems`] (CLOP's artificial test problems), [`mod@bench`] (the
//! regret and cost benchmark harness), [`cmaes`] (the CMA-ES baseline),
//! [`tune`] (local tuning with evaluator processes and a replayable log).
//!
//! This crate may start processes and write files (tune); it must not touch
//! a run directory, zenoh, or the evolving loop's state.
#![warn(missing_docs)]

pub mod bench;
pub mod cmaes;
pub mod problems;
pub mod tune;
