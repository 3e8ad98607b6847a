//! One module per command; each parses nothing (see `crate::args`) and calls
//! the crates.

pub mod bench;
pub mod bench_fleet;
pub mod certs;
pub mod check;
pub mod clop;
pub mod coordinator;
pub mod ctl;
pub mod fingerprint;
pub mod history;
pub mod journal;
pub mod model;
pub mod report;
pub mod router;
pub mod run;
pub mod stand;
pub mod trial;
pub mod watch;
pub mod web;
pub mod worker;
