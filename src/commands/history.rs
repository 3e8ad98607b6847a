//! `naofarm history DIR`: the decided history H of a run, for plotting elsewhere.

use std::path::Path;

use anyhow::anyhow;
use coordinator::evolve::DecidedIteration;

use crate::common::{emit, Failure};

fn opt(v: Option<f64>) -> serde_json::Value {
    v.map_or(serde_json::Value::Null, serde_json::Value::from)
}

/// Prints H of the run in `dir` as a table, JSON (`--json`) or CSV (`--csv`).
pub fn history(dir: &Path, json: bool, csv: bool) -> Result<(), Failure> {
    if json && csv {
        return Err(Failure::Usage(anyhow!("choose one of --json and --csv")));
    }
    let view = crate::common::read_run(dir)?;
    crate::common::note_tail(dir, &view);
    let (exp, decided) = (view.experiment, view.decided);
    let names: Vec<&str> = exp.parameter.iter().map(|p| p.name.as_str()).collect();
    // ν′ at the end of the history: the row flagged `best`.
    let best = decided
        .iter()
        .rev()
        .find_map(|d| d.best.as_ref().map(|b| b.iteration));
    let is_best = |d: &DecidedIteration| best == Some(d.iteration);
    if json {
        let rows: Vec<serde_json::Value> = decided
            .iter()
            .map(|d| {
                let params: serde_json::Map<String, serde_json::Value> = names
                    .iter()
                    .zip(&d.params)
                    .map(|(n, v)| ((*n).to_string(), serde_json::Value::from(*v)))
                    .collect();
                serde_json::json!({
                    "iteration": d.iteration,
                    "params": params,
                    "s": d.stats.s,
                    "mx": opt(d.stats.mx),
                    "my": opt(d.stats.my),
                    "ex": opt(d.stats.ex),
                    "ey": opt(d.stats.ey),
                    "decision": d.decision.as_str(),
                    "best": is_best(d),
                })
            })
            .collect();
        let text = serde_json::to_string_pretty(&rows).map_err(|e| Failure::Job(e.into()))?;
        return emit(&format!("{text}\n"));
    }
    let cell = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
    let sep = if csv { "," } else { "\t" };
    let mut header = vec!["iteration".to_string()];
    header.extend(names.iter().map(|n| (*n).to_string()));
    header.extend(
        ["s", "mx", "my", "ex", "ey", "decision", "best"]
            .iter()
            .map(|s| (*s).to_string()),
    );
    let mut out = header.join(sep) + "\n";
    for d in &decided {
        let mut row = vec![d.iteration.to_string()];
        row.extend(d.params.iter().map(f64::to_string));
        row.push(d.stats.s.to_string());
        row.extend([d.stats.mx, d.stats.my, d.stats.ex, d.stats.ey].map(cell));
        row.push(d.decision.as_str().to_string());
        row.push(is_best(d).to_string());
        out += &(row.join(sep) + "\n");
    }
    emit(&out)
}
