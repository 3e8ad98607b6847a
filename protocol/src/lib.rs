//! naofarm's shared language: the experiment file format, the parameter
//! registry, the wire messages exchanged by coordinator, workers and watchers,
//! and the zenoh key expressions they travel on.
//!
//! Modules: [`experiment`] (TOML experiment files and their validation),
//! [`params`] (the one parameter registry: names, roles, units, admissible
//! ranges, expert values; named values decoded once), [`seed`] (every random
//! stream from the run seed, iteration and trial), [`measurement`] (what one
//! trial measured), [`pickout`] (iteration statistics, pickOut, ν′ and H),
//! [`wire`] (versioned bincode envelope, one encode/decode per message),
//! [`keys`] (every key expression naofarm uses).
//!
//! This crate must not do I/O, open zenoh sessions, read clocks or draw
//! random numbers: it only describes and checks data.
#![warn(missing_docs)]

pub mod experiment;
pub mod keys;
pub mod measurement;
pub mod params;
pub mod pickout;
pub mod seed;
pub mod wire;

pub use experiment::{Experiment, ExperimentError, ParamKind, ParamSpec, Physics, TrialModel};
pub use wire::{
    Decision, DecodeError, IterationResult, RunStatus, Stats, TrialOutcome, TrialRequest,
    WireMessage, WorkerPresence, WIRE_VERSION,
};
