//! The one naofarm CLI: parses arguments and wires the crates together.
//!
//! Layout: [`args`] (every clap type), [`commands`] (one file per command),
//! and the leaves they share: [`common`] (exit-code failure, experiment
//! files, NAME=VALUE parameters), [`out`] (pipe-safe output), [`net`] (zenoh
//! configuration and session), [`serve`] (serving a run with its view),
//! [`crew`] (a bench's processes and scratch, taken down with it),
//! [`view`] (the progress view), [`render`] (a trial's animated replay). Leaves use no command; commands use no
//! other command. Library logic belongs in the crates, not here.

#[macro_use]
mod out;

mod args;
mod commands;
mod common;
mod crew;
mod net;
mod render;
mod serve;
mod view;

use std::process::ExitCode;

use args::{Cli, Command};
use clap::Parser;
use common::Failure;

fn main() -> ExitCode {
    let args = args::Cli::parse();
    if matches!(
        args.command,
        Command::Coordinator { .. } | Command::Worker { .. } | Command::Web(_)
    ) {
        compact_zenoh_runtime();
    }
    if matches!(
        args.command,
        Command::Coordinator { .. }
            | Command::Worker { .. }
            | Command::Router { .. }
            | Command::Web(_)
    ) {
        serve::watch_stdin();
    }
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| {
                tracing_subscriber::EnvFilter::new(
                    // zenoh warns when a peer's scouting delay passes; not ours to act on.
                    "warn,zenoh::net::runtime::orchestrator=error",
                )
            }),
        )
        .with_writer(std::io::stderr)
        .init();
    match dispatch(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure::Usage(e)) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
        Err(Failure::Job(e)) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}

/// A coordinator's and a worker's zenoh work (receive, route, send) on one
/// thread instead of five: their messages arrive one at a time, and every hop
/// between threads is a wake-up that costs more CPU than the message
/// (docs/fleet.md, measured). A worker's trials run on threads of their own.
/// A `ZENOH_RUNTIME` already set is left as it is. Called before any thread starts.
fn compact_zenoh_runtime() {
    if std::env::var_os("ZENOH_RUNTIME").is_none() {
        std::env::set_var(
            "ZENOH_RUNTIME",
            "(rx: (handover: app), tx: (handover: app), net: (handover: app), \
             acc: (handover: app), app: (worker_threads: 1))",
        );
    }
}

/// Runs the chosen subcommand.
fn dispatch(cli: Cli) -> Result<(), Failure> {
    match cli.command {
        Command::Check { experiment, json } => commands::check::check(&experiment, json),
        Command::Run {
            job,
            workers,
            json,
            listen,
            tls,
            programs,
        } => commands::run::run(&job, workers, json, listen.as_deref(), tls, &programs),
        Command::Coordinator { job, net, json } => {
            commands::coordinator::coordinator(&job, &net, json)
        }
        Command::Worker {
            net,
            slots,
            min_trial_ms,
            heartbeat_ms,
            limits,
            programs,
        } => commands::worker::worker(&net, slots, min_trial_ms, heartbeat_ms, &limits, &programs),
        Command::Router {
            listen,
            config,
            tls,
        } => commands::router::router(&listen, config.as_deref(), tls),
        Command::Fingerprint => commands::fingerprint::fingerprint(),
        Command::Certs {
            dir,
            names,
            hosts,
            days,
            force,
            expired,
        } => commands::certs::certs(&dir, &names, &hosts, days, force, expired),
        Command::Ctl {
            run,
            action,
            net,
            timeout_s,
        } => commands::ctl::ctl(&run, &action, &net, timeout_s),
        Command::Watch(a) => commands::watch::watch(&a),
        Command::Web(a) => commands::web::web(&a),
        Command::Clop(a) => commands::clop::clop(&a),
        Command::History { dir, json, csv } => commands::history::history(&dir, json, csv),
        Command::Report {
            dirs,
            out,
            trials,
            threads,
            programs,
        } => commands::report::report(
            &dirs,
            out.as_deref(),
            &programs,
            trials,
            threads.unwrap_or_else(|| {
                std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
            }),
        ),
        Command::Journal(j) => commands::journal::journal(j),
        Command::Bench(b) => commands::bench::bench(b),
        Command::Stand(a) => commands::stand::stand(&a),
        Command::Trial(a) => commands::trial::trial(&a),
        Command::Model {
            robot_type,
            params,
            json,
            simspark,
        } => {
            use commands::model::Format;
            let format = match (json, simspark) {
                (true, _) => Format::Json,
                (_, true) => Format::Simspark,
                _ => Format::Text,
            };
            commands::model::model(robot_type, &params, format)
        }
    }
}
