//! `naofarm clop`: arguments and output of the local tuning command
//! ([`tools::tune`] plays the games).

use std::time::Duration;

use anyhow::anyhow;
use coordinator::clop::Clop;
use tools::tune::{parse_param, tune, Games, TuneError, Tuning};

use crate::{args::ClopArgs, common::Failure};

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
        return crate::common::emit(&format!("{out}\n"));
    }
    let show = |v: &[f64]| {
        names
            .iter()
            .zip(v)
            .map(|(n, x)| format!("{n} = {x}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    crate::common::emit(&format!(
        "{} games: W {w} D {d} L {l}\nmean: {}\nmax:  {}\n",
        w + d + l,
        show(&mean),
        show(&max)
    ))
}
