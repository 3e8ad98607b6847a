//! The coordinator: CLOP, pickOut and the evolving loop as pure state
//! machines, the durable journal, and the zenoh dispatch that drives them.
//!
//! Modules: [`clop`] (the optimiser, ask/tell), [`problems`] (CLOP's artificial
//! test problems), [`bench`] (the CLOP benchmark harness), [`cmaes`] (its
//! CMA-ES baseline), [`tune`] (local tuning of any noisy program with CLOP:
//! evaluator processes and a replayable log).
//!
//! The optimiser and the loop must not do I/O, read a clock or draw from an
//! unseeded random stream; side effects (journal, publishing, progress) hang
//! off them as sinks.
#![warn(missing_docs)]

pub mod bench;
pub mod clop;
pub mod cmaes;
pub mod evolve;
pub mod journal;
pub mod lock;
pub mod problems;
pub mod run;
pub mod schedule;
pub mod service;
pub mod tune;
