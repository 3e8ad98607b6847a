//! The one naofarm CLI: parses arguments and wires the crates together.

#[macro_use]
mod out;

mod benches;
mod cli;
mod farm;
mod history;
mod journal;
mod net;
mod robot;
mod tune;
mod view;
mod watch;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let args = cli::Cli::parse();
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
    match cli::dispatch(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(cli::Failure::Usage(e)) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
        Err(cli::Failure::Job(e)) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}
