//! `naofarm check EXPERIMENT.toml`: validate an experiment file and print it.

use std::path::Path;

use anyhow::Context;

use crate::common::{load_experiment, Failure};

/// Prints the parsed experiment (`--json`: as JSON), or names its problem (exit 2).
pub fn check(path: &Path, json: bool) -> Result<(), Failure> {
    let (e, _) = load_experiment(path)?;
    if json {
        let text = serde_json::to_string_pretty(&e)
            .context("encode JSON")
            .map_err(Failure::Job)?;
        outln!("{text}");
        return Ok(());
    }
    let model = match &e.program {
        Some(p) => format!("the program `{p}`"),
        None => format!("model {:?}", e.model),
    };
    outln!(
        "experiment `{}` (seed {}, {model}, robot type {}, start {:?})",
        e.name,
        e.seed,
        e.robot_type,
        e.start
    );
    outln!(
        "  {} iterations x {} trials of {} s, pipeline depth {}",
        e.iterations,
        e.trials_per_iteration,
        e.trial_duration_s,
        e.pipeline_depth
    );
    outln!("  parameters (L):");
    for p in &e.parameter {
        outln!(
            "    {:<36} {:<8} [{}, {}]  expert {}",
            p.name,
            format!("{:?}", p.kind).to_lowercase(),
            p.lower,
            p.upper,
            p.expert_value()
        );
    }
    if !e.fixed.is_empty() {
        outln!("  fixed:");
        for (k, v) in &e.fixed {
            outln!("    {k:<36} {v}");
        }
    }
    if e.model == protocol::experiment::TrialModel::Nao {
        outln!("  physics: {}", e.physics);
        for (_, note) in crate::common::type_overrides(&e, e.robot_type) {
            outln!("  note: {note}");
        }
    }
    let k = &e.pickout;
    outln!(
        "  pickOut: SUCCESS_RATE {} XY_RATIO {} alpha {} beta {} gamma {}",
        k.success_rate,
        k.xy_ratio,
        k.alpha,
        k.beta,
        k.gamma
    );
    let c = &e.clop;
    outln!(
        "  CLOP: H {} DrawElo {} correlations {} prior {} refresh {} max weight iterations {} nMCMC {}",
        c.h,
        c.draw_elo,
        if c.correlations { "all" } else { "none" },
        c.prior_strength,
        c.refresh_rate,
        c.max_weight_iterations,
        c.n_mcmc
    );
    Ok(())
}
