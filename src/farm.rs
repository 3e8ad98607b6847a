//! Wiring of `run`, `coordinator` and `worker`: parse, open sessions, call
//! the services, turn signals into the shutdown channel.

use std::time::Duration;

use anyhow::anyhow;
use coordinator::{
    run::{load_history, Run},
    service::{self, Ended, Event, ServiceConfig},
};
use protocol::{experiment::TrialModel, wire::RunStatus};

use crate::{
    cli::{load_experiment, Failure, JobArgs},
    net::{free_loopback_port, open_session, NetArgs},
    view::View,
};

fn runtime() -> Result<tokio::runtime::Runtime, Failure> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| Failure::Job(e.into()))
}

/// A shutdown channel that turns true on SIGINT or SIGTERM.
fn signals() -> tokio::sync::watch::Receiver<bool> {
    let (tx, rx) = tokio::sync::watch::channel(false);
    tokio::spawn(async move {
        let ctrl_c = tokio::signal::ctrl_c();
        #[cfg(unix)]
        {
            let mut term =
                match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
                    Ok(t) => t,
                    Err(_) => {
                        let _ = ctrl_c.await;
                        let _ = tx.send(true);
                        return;
                    }
                };
            tokio::select! {
                _ = ctrl_c => {}
                _ = term.recv() => {}
            }
        }
        #[cfg(not(unix))]
        let _ = ctrl_c.await;
        let _ = tx.send(true);
    });
    rx
}

fn open_run(job: &JobArgs) -> Result<(Run, Vec<coordinator::run::Effect>), Failure> {
    let (mut exp, text) = load_experiment(&job.experiment)?;
    if let Some(n) = job.iterations {
        exp.iterations = n;
    }
    if let Some(s) = job.seed {
        exp.seed = s;
    }
    if let Some(m) = &job.model {
        exp.model = TrialModel::parse(m).map_err(|e| Failure::Usage(anyhow!("--model: {e}")))?;
    }
    exp.validate().map_err(|e| Failure::Usage(e.into()))?;
    if !(job.lease_s.is_finite() && (1.0..=86_400.0).contains(&job.lease_s)) {
        return Err(Failure::Usage(anyhow!(
            "--lease-s {}: must be in [1, 86400] seconds",
            job.lease_s
        )));
    }
    let imported = match &job.from {
        Some(dir) => {
            let from = load_history(dir, &exp).map_err(|e| match e {
                coordinator::run::RunError::FromMismatch { .. } => Failure::Usage(e.into()),
                e => Failure::Job(anyhow!("--from {}: {e}", dir.display())),
            })?;
            eprintln!(
                "starting from {}: {} of its {} points lie inside this experiment's bounds{}",
                dir.display(),
                from.imported.history.len(),
                from.total,
                if from.best_kept {
                    ""
                } else {
                    "; its best set does not, so ν′ starts undefined"
                }
            );
            Some(from.imported)
        }
        None => None,
    };
    if !(1..=100).contains(&job.max_trial_failures) {
        return Err(Failure::Usage(anyhow!(
            "--max-trial-failures {}: must be in 1..=100",
            job.max_trial_failures
        )));
    }
    let mut opened = Run::open(&job.out, exp, &text, imported).map_err(|e| match e {
        coordinator::run::RunError::OtherExperiment { .. }
        | coordinator::run::RunError::Locked(_)
        | coordinator::run::RunError::Diverged { .. } => Failure::Usage(e.into()),
        e => Failure::Job(e.into()),
    })?;
    opened.0.set_failure_limit(job.max_trial_failures as usize);
    if let Some(before) = opened.0.extended_from() {
        eprintln!(
            "extending {} from {before} to {} iterations",
            job.out.display(),
            opened.0.evolve().experiment().iterations
        );
    }
    Ok(opened)
}

fn service_config(job: &JobArgs, prefix: &str) -> ServiceConfig {
    ServiceConfig {
        prefix: prefix.to_string(),
        lease: Duration::from_secs_f64(job.lease_s),
        ..ServiceConfig::default()
    }
}

/// Shows the service's events in a [`View`] until the channel closes.
fn spawn_view(
    json: bool,
    mut rx: tokio::sync::mpsc::UnboundedReceiver<Event>,
) -> tokio::task::JoinHandle<(View, Option<RunStatus>)> {
    tokio::spawn(async move {
        let mut view = View::new(json);
        let mut last = None;
        while let Some(e) = rx.recv().await {
            match e {
                Event::Started(history, status) => {
                    view.history(&history);
                    view.status(&status);
                    last = Some(*status);
                }
                Event::Decided(result, status) => {
                    view.decided(&result);
                    view.status(&status);
                    last = Some(*status);
                }
            }
        }
        (view, last)
    })
}

/// CPU time (user + system) this process has used, from `/proc/self/stat`
/// (Linux; clock ticks of 1/100 s, the kernel's USER_HZ). `None` elsewhere.
fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may hold spaces) closed by ')'.
    let rest = stat.rsplit_once(')')?.1;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of stat(5); `rest` starts at field 3.
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

fn summary(
    run_dir: &std::path::Path,
    ended: &Ended,
    view: Option<(View, Option<RunStatus>)>,
) -> Result<(), Failure> {
    if let Some((mut view, last)) = view {
        match (last, ended) {
            (Some(status), Ended::Finished(c)) => view.finish(
                &status,
                serde_json::json!({
                    "accepted": c.accepted,
                    "duplicates": c.duplicates,
                    "refused": c.refused,
                    "redispatched": c.redispatched,
                    "failures": c.failures,
                    "set_aside": c.set_aside,
                    "cpu_s": process_cpu_seconds(),
                }),
            ),
            _ => view.abandon(),
        }
    }
    match ended {
        Ended::Finished(c) => {
            eprintln!(
                "run complete: {} outcomes journaled, {} duplicates ignored, {} refused, {} re-dispatched, {} trial failures{}; journal in {}",
                c.accepted,
                c.duplicates,
                c.refused,
                c.redispatched,
                c.failures,
                if c.set_aside.is_empty() {
                    String::new()
                } else {
                    format!(" (set aside: {})", c.set_aside.join(", "))
                },
                run_dir.display()
            );
            Ok(())
        }
        Ended::Interrupted(_) => Err(Failure::Job(anyhow!(
            "interrupted; resume with the same command (journal in {})",
            run_dir.display()
        ))),
    }
}

/// `naofarm coordinator`.
pub fn coordinator(job: &JobArgs, net: &NetArgs, json: bool) -> Result<(), Failure> {
    let cfg = net
        .zenoh_config(&["tcp/127.0.0.1:7447"])
        .map_err(Failure::Usage)?;
    let (run, effects) = open_run(job)?;
    let rt = runtime()?;
    rt.block_on(async {
        let session = open_session(cfg).await?;
        let shutdown = signals();
        let served =
            serve_with_view(&session, (run, effects), job, &net.prefix, shutdown, json).await;
        let _ = session.close().await;
        let (ended, view) = served;
        summary(&job.out, &ended.map_err(|e| Failure::Job(e.into()))?, view)
    })
}

/// Serves the run on `session`, its events shown in a [`View`]; returns how it
/// ended and the view with the last status.
async fn serve_with_view(
    session: &zenoh::Session,
    (run, effects): (Run, Vec<coordinator::run::Effect>),
    job: &JobArgs,
    prefix: &str,
    shutdown: tokio::sync::watch::Receiver<bool>,
    json: bool,
) -> (
    Result<Ended, service::ServiceError>,
    Option<(View, Option<RunStatus>)>,
) {
    let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
    let printer = spawn_view(json, rx);
    let ended = service::serve(
        session.clone(),
        run,
        effects,
        service_config(job, prefix),
        shutdown,
        Some(tx),
    )
    .await;
    (ended, printer.await.ok())
}

/// `naofarm worker`.
pub fn worker(net: &NetArgs, slots: Option<u32>, min_trial_ms: u64) -> Result<(), Failure> {
    if min_trial_ms > 3_600_000 {
        return Err(Failure::Usage(anyhow!(
            "--min-trial-ms {min_trial_ms}: must be at most 3600000"
        )));
    }
    let cfg = net.zenoh_config(&[]).map_err(Failure::Usage)?;
    let mut wcfg = worker::service::WorkerConfig {
        prefix: net.prefix.clone(),
        min_trial: Duration::from_millis(min_trial_ms),
        ..worker::service::WorkerConfig::default()
    };
    if let Some(s) = slots {
        if s == 0 || s > 4096 {
            return Err(Failure::Usage(anyhow!("--slots must be in 1..=4096")));
        }
        wcfg.slots = s;
    }
    let rt = runtime()?;
    rt.block_on(async {
        let session = open_session(cfg).await?;
        let shutdown = signals();
        let s = worker::service::serve(session.clone(), wcfg, shutdown)
            .await
            .map_err(|e| Failure::Job(e.into()))?;
        let _ = session.close().await;
        eprintln!(
            "worker stopped: {} trials run, {} refused",
            s.trials, s.refused
        );
        Ok(())
    })
}

/// `naofarm run`: coordinator and local workers in one process, over zenoh on loopback.
pub fn run(
    job: &JobArgs,
    workers: Option<u32>,
    json: bool,
    listen: Option<&str>,
) -> Result<(), Failure> {
    let n = workers.unwrap_or_else(|| {
        std::thread::available_parallelism()
            .ok()
            .and_then(|n| u32::try_from(n.get()).ok())
            .unwrap_or(1)
    });
    if n == 0 || n > 1024 {
        return Err(Failure::Usage(anyhow!(
            "--workers {n}: must be in 1..=1024"
        )));
    }
    let endpoint = match listen {
        Some(e) if e.starts_with("tcp/127.") || e.starts_with("tcp/[::1]") => e.to_string(),
        Some(e) => {
            return Err(Failure::Usage(anyhow!(
                "--listen `{e}`: `run` serves on loopback only (tcp/127.0.0.1:PORT); use `coordinator` and `worker` for a cluster"
            )))
        }
        None => format!(
            "tcp/127.0.0.1:{}",
            free_loopback_port().map_err(Failure::Job)?
        ),
    };
    eprintln!("zenoh on {endpoint}; watch from another terminal with `naofarm watch RUN --connect {endpoint}`");
    let coord_net = NetArgs {
        listen: vec![endpoint.clone()],
        prefix: protocol::keys::DEFAULT_PREFIX.to_string(),
        ..NetArgs::default()
    };
    let worker_net = NetArgs {
        connect: vec![endpoint],
        listen: vec![],
        prefix: protocol::keys::DEFAULT_PREFIX.to_string(),
        config: None,
    };
    let ccfg = coord_net.zenoh_config(&[]).map_err(Failure::Job)?;
    let (run, effects) = open_run(job)?;
    let rt = runtime()?;
    rt.block_on(async {
        let session = open_session(ccfg).await?;
        let shutdown = signals();
        let mut handles = Vec::new();
        let mut worker_sessions = Vec::new();
        for _ in 0..n {
            let wcfg = worker_net.zenoh_config(&[]).map_err(Failure::Job)?;
            let ws = open_session(wcfg).await?;
            worker_sessions.push(ws.clone());
            let cfg = worker::service::WorkerConfig {
                slots: 1,
                ..worker::service::WorkerConfig::default()
            };
            handles.push(tokio::spawn(worker::service::serve(
                ws,
                cfg,
                shutdown.clone(),
            )));
        }
        let (ended, view) = serve_with_view(
            &session,
            (run, effects),
            job,
            protocol::keys::DEFAULT_PREFIX,
            shutdown,
            json,
        )
        .await;
        for ws in &worker_sessions {
            let _ = ws.close().await;
        }
        for h in handles {
            h.abort();
        }
        let _ = session.close().await;
        let ended = ended.map_err(|e| Failure::Job(e.into()))?;
        summary(&job.out, &ended, view)
    })
}
