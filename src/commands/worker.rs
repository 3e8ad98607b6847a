//! `naofarm worker`: a stateless worker (cluster use).

use std::time::Duration;

use anyhow::anyhow;
use protocol::params::Shown;

use crate::{
    args::{NetArgs, ProgramArgs, WorkerLimits},
    common::Failure,
    net::open_session,
    serve::{runtime, signals},
};

/// `naofarm worker`.
pub fn worker(
    net: &NetArgs,
    slots: Option<u32>,
    min_trial_ms: u64,
    heartbeat_ms: u64,
    limits: &WorkerLimits,
    programs: &ProgramArgs,
) -> Result<(), Failure> {
    if !(10..=60_000).contains(&heartbeat_ms) {
        return Err(Failure::Usage(anyhow!(
            "--heartbeat-ms {heartbeat_ms}: must be in 10..=60000"
        )));
    }
    if !(limits.max_duration_s.is_finite() && limits.max_duration_s > 0.0) {
        return Err(Failure::Usage(anyhow!(
            "--max-duration-s {}: must be a positive number of seconds",
            Shown(limits.max_duration_s)
        )));
    }
    let models = limits
        .models
        .iter()
        .map(|m| protocol::TrialModel::parse(m))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| Failure::Usage(anyhow!("--models: {e}")))?;
    if models.contains(&protocol::TrialModel::Program) {
        return Err(Failure::Usage(anyhow!(
            "--models: programs are served by name, with --program NAME=PATH"
        )));
    }
    if min_trial_ms > 3_600_000 {
        return Err(Failure::Usage(anyhow!(
            "--min-trial-ms {min_trial_ms}: must be at most 3600000"
        )));
    }
    let cfg = net.zenoh_config("worker", &[]).map_err(Failure::Usage)?;
    let mut wcfg = worker::service::WorkerConfig {
        prefix: net.prefix.clone(),
        min_trial: Duration::from_millis(min_trial_ms),
        heartbeat: Duration::from_millis(heartbeat_ms),
        max_duration_s: limits.max_duration_s,
        max_substeps: limits.max_substeps,
        models,
        ..worker::service::WorkerConfig::default()
    };
    if let Some(s) = slots {
        if s == 0 || s > 4096 {
            return Err(Failure::Usage(anyhow!("--slots must be in 1..=4096")));
        }
        wcfg.slots = s;
    }
    let rt = runtime()?;
    let done = rt.block_on(async {
        wcfg.programs = crate::common::register_programs(programs, wcfg.slots).await?;
        if !wcfg.programs.by_name.is_empty() {
            eprintln!(
                "trial programs run as jobs contained by {}",
                worker::job::Host::get().describe()
            );
            for p in wcfg.programs.by_name.values() {
                let kept = if p.kept(&wcfg.programs.settings) {
                    "kept in its slot between a run's trials (it serves)"
                } else {
                    "started for each trial"
                };
                eprintln!("program `{}`: {kept}", p.name);
            }
        }
        let session = open_session(cfg, "worker", &net.connect).await?;
        let shutdown = signals();
        let s = worker::service::serve(session.clone(), wcfg, shutdown)
            .await
            .map_err(|e| Failure::Job(e.into()))?;
        let _ = session.close().await;
        eprintln!(
            "worker stopped: {} trials run, {} given back or failed, at most {} held",
            s.trials, s.refused, s.most_held
        );
        Ok(())
    });
    // Trials it gave back may still be computing on their threads: they are
    // abandoned, not waited for.
    rt.shutdown_background();
    done
}
