//! `naofarm clop`: arguments and output of the local tuning command
//! ([`tools::tune`] plays the games).

use std::{path::PathBuf, time::Duration};

use anyhow::anyhow;
use clap::Args;
use coordinator::clop::Clop;
use tools::tune::{parse_param, tune, Games, TuneError, Tuning};

use crate::cli::Failure;

/// Arguments of `naofarm clop`.
#[derive(Args, Debug)]
pub struct ClopArgs {
    /// A parameter, NAME:KIND:LO:HI (KIND: linear, integer, gamma, integer_gamma); repeatable, in order.
    #[arg(long = "param", value_name = "NAME:KIND:LO:HI", required = true)]
    params: Vec<String>,
    /// Games to play in all (a resumed log's games count).
    #[arg(long)]
    budget: u64,
    /// Seed of CLOP's sampler and of the games' seeds.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// A command started once: reads `<game> <seed> <v1> <v2> …`, answers `W`, `D` or `L` per line.
    #[arg(long, conflicts_with = "script", required_unless_present = "script")]
    evaluator: Option<String>,
    /// A command run once per game with `<processor> <seed> <name1> <value1> …`; its last line is W, L or D.
    #[arg(long)]
    script: Option<String>,
    /// Append every game here (JSON lines); an existing log is replayed and continued.
    #[arg(long)]
    log: Option<PathBuf>,
    /// Seconds one game may take before the evaluator is declared hung.
    #[arg(long, default_value_t = 600.0)]
    timeout_s: f64,
    /// CLOP's DrawElo (draws are likelier with a larger value).
    #[arg(long, default_value_t = 0.0)]
    draw_elo: f64,
    /// Machine-readable output.
    #[arg(long)]
    json: bool,
}

/// `naofarm clop`.
pub fn clop(a: &ClopArgs) -> Result<(), Failure> {
    let params = a
        .params
        .iter()
        .map(|s| parse_param(s))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| Failure::Usage(anyhow!("{e}")))?;
    if !(a.timeout_s.is_finite() && a.timeout_s > 0.0 && a.timeout_s < 1e9) {
        return Err(Failure::Usage(anyhow!(
            "--timeout-s must be a positive number of seconds"
        )));
    }
    let games = match (&a.evaluator, &a.script) {
        (Some(cmd), None) => Games::Lines(cmd.clone()),
        (None, Some(cmd)) => Games::Script(cmd.clone()),
        _ => {
            return Err(Failure::Usage(anyhow!(
                "give one of --evaluator and --script"
            )))
        }
    };
    let job = Tuning {
        params,
        budget: a.budget,
        seed: a.seed,
        games,
        log: a.log.clone(),
        timeout: Duration::from_secs_f64(a.timeout_s),
        draw_elo: a.draw_elo,
    };
    let names: Vec<String> = job.params.iter().map(|p| p.name.clone()).collect();
    let clop = tune(&job).map_err(|e| match e {
        TuneError::Bad(e) => Failure::Usage(anyhow!("{e}")),
        TuneError::Failed(e) => Failure::Job(anyhow!("{e}")),
    })?;
    report(&clop, &names, a.json)
}

fn report(clop: &Clop, names: &[String], json: bool) -> Result<(), Failure> {
    let (w, d, l) = clop.counts();
    let mean = clop.to_external(&clop.mean());
    let max = clop.to_external(&clop.max());
    let named = |v: &[f64]| -> serde_json::Map<String, serde_json::Value> {
        names
            .iter()
            .zip(v)
            .map(|(n, x)| (n.clone(), serde_json::Value::from(*x)))
            .collect()
    };
    if json {
        let out = serde_json::json!({
            "mean": named(&mean),
            "max": named(&max),
            "wins": w,
            "draws": d,
            "losses": l,
        });
        return crate::cli::emit(&format!("{out}\n"));
    }
    let show = |v: &[f64]| {
        names
            .iter()
            .zip(v)
            .map(|(n, x)| format!("{n} = {x}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    crate::cli::emit(&format!(
        "{} games: W {w} D {d} L {l}\nmean: {}\nmax:  {}\n",
        w + d + l,
        show(&mean),
        show(&max)
    ))
}
