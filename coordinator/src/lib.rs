//! The coordinator of a run, in three layers that only depend downwards:
//!
//! - **core** (pure: no I/O, no clock, no unseeded randomness): [`clop`] (the
//!   optimiser, ask/tell) and [`evolve`] (Algorithm 1 as a state machine over
//!   `protocol::pickout`);
//! - **durable state**: [`journal`] (the append-only, checksummed journal and
//!   its damage rules), [`lock`] (one coordinator per run directory), [`run`]
//!   (a run on disk: create, resume, extend, salvage, replay a farm trial),
//!   [`decider`] (the run on its own thread, so its journal and CLOP's fits
//!   never hold up the transport), [`cpu`] (the CPU time it costs);
//! - **transport**: [`schedule`] (who runs which trial, leases and liveness, a
//!   pure part under the caller's clock) and [`service`] (the zenoh loop that
//!   moves messages between workers, watchers and the run), and for watchers
//!   [`follow`] (when a followed run has ended, a pure state machine).
//!
//! Tooling around CLOP (benchmarks, baselines, local tuning) lives in
//! `naofarm-tools`, not here. This crate must not print, exit or parse
//! command lines, and its core must not read a clock or do I/O.
#![warn(missing_docs)]

pub mod clop;
pub mod cpu;
pub mod decider;
pub mod evolve;
pub mod follow;
pub mod journal;
pub mod lock;
pub mod run;
pub mod schedule;
pub mod service;
#[cfg(test)]
mod test_dir;
