//! The stateless worker service: takes trial requests addressed to it, runs
//! them on at most `slots` OS threads (never on the async runtime), and
//! publishes each outcome. It keeps nothing between trials.

use std::{
    sync::{
        atomic::{AtomicU32, Ordering},
        Arc,
    },
    time::{Duration, Instant},
};

use protocol::{
    keys,
    wire::{TrialFailure, TrialOutcome, TrialRequest, WireMessage, WorkerPresence},
};
use zenoh::Session;

/// Settings of a worker.
#[derive(Debug, Clone)]
pub struct WorkerConfig {
    /// Key prefix (default `naofarm`).
    pub prefix: String,
    /// Trials run at once.
    pub slots: u32,
    /// Interval of the presence heartbeat.
    pub heartbeat: Duration,
    /// Minimum wall time of one trial (paces cheap models to benchmark or test the farm).
    pub min_trial: Duration,
}

impl Default for WorkerConfig {
    fn default() -> Self {
        Self {
            prefix: keys::DEFAULT_PREFIX.to_string(),
            slots: std::thread::available_parallelism()
                .ok()
                .and_then(|n| u32::try_from(n.get()).ok())
                .unwrap_or(1),
            heartbeat: Duration::from_millis(500),
            min_trial: Duration::ZERO,
        }
    }
}

/// Worker failures.
#[derive(Debug, thiserror::Error)]
pub enum WorkerError {
    /// Zenoh failed.
    #[error("zenoh: {0}")]
    Zenoh(String),
}

fn zerr(e: impl std::fmt::Display) -> WorkerError {
    WorkerError::Zenoh(e.to_string())
}

/// What a worker did before it stopped.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct WorkerSummary {
    /// Trials run and reported.
    pub trials: u64,
    /// Requests refused (undecodable) or trials that failed (reported as failures).
    pub refused: u64,
}

/// Sends a message; one that cannot be encoded or sent is logged.
async fn put_message<M: WireMessage>(session: &Session, key: &str, m: &M) {
    match m.encode() {
        Ok(bytes) => {
            if let Err(e) = session.put(key, bytes).await {
                tracing::warn!(key, error = %e, "publishing failed");
            }
        }
        Err(e) => tracing::error!(key, error = %e, "not published"),
    }
}

/// The text of a panic's payload.
fn panic_text(p: Box<dyn std::any::Any + Send>) -> String {
    p.downcast_ref::<&str>()
        .map(|s| (*s).to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(no message)".into())
}

/// Serves trials until `shutdown` turns true, then finishes what it holds,
/// drops its liveliness token and returns.
pub async fn serve(
    session: Session,
    cfg: WorkerConfig,
    mut shutdown: tokio::sync::watch::Receiver<bool>,
) -> Result<WorkerSummary, WorkerError> {
    let id = uuid::Uuid::new_v4().to_string();
    let prefix = cfg.prefix.clone();
    let work = session
        .declare_subscriber(keys::work(&prefix, &id))
        .await
        .map_err(zerr)?;
    let token = session
        .liveliness()
        .declare_token(keys::worker(&prefix, &id))
        .await
        .map_err(zerr)?;
    tracing::info!(worker = %id, slots = cfg.slots, "worker ready");
    let busy = Arc::new(AtomicU32::new(0));
    let slots = Arc::new(tokio::sync::Semaphore::new(cfg.slots as usize));
    let mut tasks = tokio::task::JoinSet::new();
    let mut summary = WorkerSummary::default();
    let mut beat = tokio::time::interval(cfg.heartbeat);
    let presence_key = keys::presence(&prefix);
    loop {
        tokio::select! {
            _ = beat.tick() => {
                let p = WorkerPresence {
                    worker: id.clone(),
                    slots: cfg.slots,
                    busy: busy.load(Ordering::Relaxed).min(cfg.slots),
                    version: env!("CARGO_PKG_VERSION").to_string(),
                };
                put_message(&session, &presence_key, &p).await;
            }
            s = work.recv_async() => {
                let Ok(s) = s else { break };
                let req = match TrialRequest::decode(&s.payload().to_bytes()) {
                    Ok(r) => r,
                    Err(e) => {
                        summary.refused += 1;
                        tracing::warn!(error = %e, "refused a trial request");
                        continue;
                    }
                };
                let Ok(permit) = slots.clone().acquire_owned().await else { break };
                let session = session.clone();
                let id = id.clone();
                let busy = busy.clone();
                let prefix = prefix.clone();
                let min_trial = cfg.min_trial;
                busy.fetch_add(1, Ordering::Relaxed);
                tasks.spawn(async move {
                    let started = Instant::now();
                    let asked = req.clone();
                    let r = tokio::task::spawn_blocking(move || {
                        let out = crate::fault::run_trial(&req);
                        let rest = min_trial.saturating_sub(started.elapsed());
                        if !rest.is_zero() {
                            std::thread::sleep(rest);
                        }
                        out
                    })
                    .await;
                    busy.fetch_sub(1, Ordering::Relaxed);
                    drop(permit);
                    let result = match r {
                        Ok(Ok(t)) => t.check().map(|()| t),
                        Ok(Err(e)) => Err(e.to_string()),
                        Err(e) if e.is_panic() => Err(format!("panic: {}", panic_text(e.into_panic()))),
                        Err(e) => Err(format!("the trial's thread ended: {e}")),
                    };
                    match result {
                        Ok(m) => {
                            let mut o = TrialOutcome::answer(&asked, id, m, started.elapsed().as_secs_f64());
                            crate::fault::tamper(&mut o);
                            put_message(&session, &keys::outcomes(&prefix), &o).await;
                            true
                        }
                        Err(reason) => {
                            tracing::error!(%reason, iteration = asked.iteration, trial = asked.trial, "trial could not run; reporting it");
                            let f = TrialFailure {
                                run: asked.run,
                                iteration: asked.iteration,
                                trial: asked.trial,
                                seed: asked.seed,
                                dispatch: asked.dispatch,
                                worker: id,
                                reason,
                            };
                            put_message(&session, &keys::failures(&prefix), &f).await;
                            false
                        }
                    }
                });
            }
            Some(done) = tasks.join_next(), if !tasks.is_empty() => {
                match done {
                    Ok(true) => summary.trials += 1,
                    _ => summary.refused += 1,
                }
            }
            _ = shutdown.changed() => {
                if *shutdown.borrow() {
                    break;
                }
            }
        }
    }
    // Stop taking work, finish what we hold, then leave.
    drop(work);
    while let Some(done) = tasks.join_next().await {
        match done {
            Ok(true) => summary.trials += 1,
            _ => summary.refused += 1,
        }
    }
    if let Err(e) = token.undeclare().await {
        tracing::warn!(error = %e, "undeclaring the liveliness token failed");
    }
    tracing::info!(worker = %id, trials = summary.trials, "worker stopped");
    Ok(summary)
}
