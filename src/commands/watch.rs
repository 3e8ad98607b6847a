//! `naofarm watch [RUN]`: lists the runs a zenoh session can see, or follows
//! one run from any machine: its status and history by query first, then
//! its result, trial and status topics. It only subscribes and queries; it
//! never publishes, so it cannot disturb the run.

use std::time::{Duration, Instant};

use anyhow::anyhow;
use coordinator::follow::{Ending, Verdict};
use protocol::{
    keys,
    wire::{IterationResult, RunStatus, TrialOutcome, WireMessage},
};
use zenoh::{query::ConsolidationMode, sample::SampleKind, Session};

use crate::{
    args::{NetArgs, WatchArgs},
    common::Failure,
    view::View,
};

fn zerr(e: impl std::fmt::Display) -> Failure {
    Failure::Job(anyhow!("zenoh: {e}"))
}

/// Asks `key` until some answer comes or `deadline` passes (the session may
/// still be connecting when the first query leaves: it then gets no reply).
async fn query_until(
    session: &Session,
    key: &str,
    deadline: Instant,
) -> Result<Vec<String>, Failure> {
    loop {
        let replies = session
            .get(key)
            .consolidation(ConsolidationMode::None)
            .timeout(Duration::from_secs(2))
            .await
            .map_err(zerr)?;
        let mut out = Vec::new();
        while let Ok(reply) = replies.recv_async().await {
            match reply.result() {
                Ok(sample) => {
                    out.push(String::from_utf8_lossy(&sample.payload().to_bytes()).into_owned());
                }
                Err(e) => tracing::warn!(key, error = ?e.payload(), "error reply"),
            }
        }
        if !out.is_empty() || Instant::now() >= deadline {
            return Ok(out);
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// `naofarm watch`.
pub fn watch(a: &WatchArgs) -> Result<(), Failure> {
    if !(a.timeout_s.is_finite() && a.timeout_s > 0.0 && a.timeout_s <= 86_400.0) {
        return Err(Failure::Usage(anyhow!(
            "--timeout-s must be in (0, 86400] seconds"
        )));
    }
    if let Some(run) = &a.run {
        keys::check_chunk("run", run).map_err(|e| Failure::Usage(anyhow!(e)))?;
    }
    let mut net = a.net.clone();
    if net.connect.is_empty() && net.config.is_none() {
        net.connect
            .push(crate::net::default_connect(net.tls.is_some()));
    }
    let cfg = net
        .zenoh_config_within("watcher", a.timeout_s)
        .map_err(Failure::Usage)?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .map_err(|e| Failure::Job(e.into()))?;
    rt.block_on(async {
        let session = crate::net::open_asking(cfg, &net.connect).await?;
        let deadline = Instant::now() + Duration::from_secs_f64(a.timeout_s);
        let r = match &a.run {
            None => list(&session, &net, deadline, a.json).await,
            Some(run) => follow(&session, &net, run, deadline, a.json).await,
        };
        let _ = session.close().await;
        r
    })
}

async fn list(
    session: &Session,
    net: &NetArgs,
    deadline: Instant,
    json: bool,
) -> Result<(), Failure> {
    let runs = statuses(session, &net.prefix, deadline).await?;
    if runs.is_empty() {
        eprintln!("no runs answer at {}", net.connect.join(", "));
        return Ok(());
    }
    for (s, claims) in &runs {
        if *claims > 1 {
            eprintln!("{}", claimed_warning(s, *claims));
        }
        if json {
            let mut v = serde_json::to_value(s).map_err(|e| Failure::Job(e.into()))?;
            v["claims"] = serde_json::json!(claims);
            outln!("{v}");
        } else {
            let mark = if *claims > 1 {
                format!("  CLAIMED BY {claims}")
            } else {
                String::new()
            };
            outln!(
                "{:<24} {}  {:>5}/{:<5} decided  A {} E {} R {}  priority {}  {} workers  {:.1} trials/s  {}{mark}",
                s.run,
                s.id,
                s.decided,
                s.planned,
                s.accepts,
                s.equivalents,
                s.rejects,
                s.priority,
                s.workers,
                s.trials_per_s,
                format!("{:?}", s.state).to_lowercase()
            );
        }
    }
    Ok(())
}

/// What `watch` says when more than one session answers for one run id.
fn claimed_warning(s: &RunStatus, claims: usize) -> String {
    format!(
        "warning: run {} ({}) is claimed by {claims} sessions: another coordinator serves a copy of \
         its directory, or someone forges its status; what is shown is the first answer. \
         Over `--tls`, only sessions with a coordinator certificate can answer",
        s.id, s.run
    )
}

/// Every run that answers a status query, by name then id, each with how
/// many answers claimed it (more than one: two coordinators, or a forger).
async fn statuses(
    session: &Session,
    prefix: &str,
    deadline: Instant,
) -> Result<Vec<(RunStatus, usize)>, Failure> {
    let answers = query_until(session, &keys::status_all(prefix), deadline).await?;
    let mut runs: Vec<RunStatus> = answers
        .iter()
        .filter_map(|t| match RunStatus::from_json(t) {
            Ok(s) => Some(s),
            Err(e) => {
                tracing::warn!(error = %e, "ignored a status answer");
                None
            }
        })
        .collect();
    runs.sort_by(|a, b| a.id.cmp(&b.id));
    let mut claimed: Vec<(RunStatus, usize)> = Vec::new();
    for s in runs {
        match claimed.last_mut() {
            Some((first, n)) if first.id == s.id => *n += 1,
            _ => claimed.push((s, 1)),
        }
    }
    claimed.sort_by(|a, b| (&a.0.run, &a.0.id).cmp(&(&b.0.run, &b.0.id)));
    Ok(claimed)
}

/// The one run that `run` names: its id, the start of its id, or its name
/// when only one live run has that name.
pub async fn resolve(
    session: &Session,
    prefix: &str,
    run: &str,
    deadline: Instant,
    connect: &str,
) -> Result<RunStatus, Failure> {
    let runs = statuses(session, prefix, deadline).await?;
    let by_id: Vec<&(RunStatus, usize)> = runs.iter().filter(|s| s.0.id.starts_with(run)).collect();
    let by_name: Vec<&(RunStatus, usize)> = runs.iter().filter(|s| s.0.run == run).collect();
    let found = if by_id.len() == 1 { by_id } else { by_name };
    match found.as_slice() {
        [(one, claims)] => {
            if *claims > 1 {
                eprintln!("{}", claimed_warning(one, *claims));
            }
            Ok(one.clone())
        }
        [] => Err(Failure::Job(anyhow!(
            "no coordinator answers for run `{run}` at {connect}: the run is finished or unknown \
             (`naofarm watch` without a run lists the runs that answer)"
        ))),
        many => Err(Failure::Usage(anyhow!(
            "`{run}` names {} runs; give one of their ids: {}",
            many.len(),
            many.iter()
                .map(|s| s.0.id.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ))),
    }
}

async fn follow(
    session: &Session,
    net: &NetArgs,
    run: &str,
    deadline: Instant,
    json: bool,
) -> Result<(), Failure> {
    let prefix = &net.prefix;
    let status = resolve(session, prefix, run, deadline, &net.connect.join(", ")).await?;
    let run = status.run.clone();
    let id = status.id.clone();
    let rkeys = keys::RunKeys::new(prefix, &run, &id);
    // Subscribe first, then ask again: whatever is decided in between comes
    // twice and is reported once.
    let results = session
        .declare_subscriber(rkeys.results_all())
        .await
        .map_err(zerr)?;
    let trials = session
        .declare_subscriber(rkeys.trials_all())
        .await
        .map_err(zerr)?;
    let statuses = session
        .declare_subscriber(rkeys.status())
        .await
        .map_err(zerr)?;
    let coordinator = session
        .liveliness()
        .declare_subscriber(keys::coordinator(prefix, &id))
        .await
        .map_err(zerr)?;
    let answers = query_until(session, &rkeys.status(), deadline).await?;
    let status = answers
        .iter()
        .find_map(|t| RunStatus::from_json(t).ok())
        .unwrap_or(status);
    if status.finished {
        return Err(Failure::Job(anyhow!(
            "run `{run}` is finished ({} of {} iterations decided); see `naofarm history DIR`",
            status.decided,
            status.planned
        )));
    }
    let parts = query_until(session, &rkeys.history(), deadline).await?;
    let history = protocol::wire::history_from_parts(&parts)
        .map_err(|e| Failure::Job(anyhow!("the history answer does not parse: {e}")))?;
    let mut view = View::new(json);
    view.history(&history);
    view.status(&status);
    let mut last = status;
    let shutdown = tokio::signal::ctrl_c();
    tokio::pin!(shutdown);
    // When the run has ended, and whether every result arrived.
    let mut ending = Ending::new(last.planned, Duration::from_secs(3));
    let far = tokio::time::Instant::now() + Duration::from_secs(86_400 * 365);
    loop {
        let reported = view.reported() as u64;
        match ending.verdict(reported, tokio::time::Instant::now()) {
            Verdict::Going => {}
            Verdict::Complete { finished } => {
                if !finished {
                    last.decided = last.planned;
                    last.finished = true;
                    view.status(&last);
                }
                view.finish(&last, serde_json::json!({}));
                return Ok(());
            }
            Verdict::Incomplete { finished } => {
                view.abandon();
                return Err(Failure::Job(if finished {
                    anyhow!(
                        "run `{run}` finished, but only {reported} of its {} results reached this watcher",
                        ending.planned()
                    )
                } else {
                    anyhow!(
                        "the coordinator of run `{run}` stopped after {reported} of {} iterations",
                        ending.planned()
                    )
                }));
            }
        }
        tokio::select! {
            // Results before statuses: a finished status must not overtake
            // the last result in this loop.
            biased;
            s = results.recv_async() => {
                let s = s.map_err(zerr)?;
                match IterationResult::from_json(&String::from_utf8_lossy(&s.payload().to_bytes())) {
                    Ok(r) if r.run == run => {
                        view.decided(&r);
                    }
                    Ok(r) => tracing::warn!(run = %r.run, "ignored a result of another run"),
                    Err(e) => tracing::warn!(error = %e, "ignored a malformed result"),
                }
            }
            s = trials.recv_async() => {
                let s = s.map_err(zerr)?;
                match TrialOutcome::from_json(&String::from_utf8_lossy(&s.payload().to_bytes())) {
                    Ok(o) => view.trial(&o),
                    Err(e) => tracing::warn!(error = %e, "ignored a malformed trial outcome"),
                }
            }
            s = statuses.recv_async() => {
                let s = s.map_err(zerr)?;
                match RunStatus::from_json(&String::from_utf8_lossy(&s.payload().to_bytes())) {
                    Ok(st) if st.id == id => {
                        view.status(&st);
                        ending.status(st.planned, st.finished, tokio::time::Instant::now());
                        last = st;
                    }
                    Ok(_) => {}
                    Err(e) => tracing::warn!(error = %e, "ignored a malformed status"),
                }
            }
            s = coordinator.recv_async() => {
                let s = s.map_err(zerr)?;
                if s.kind() == SampleKind::Delete {
                    ending.coordinator_gone(tokio::time::Instant::now());
                }
            }
            // Past the grace period: the verdict at the top of the loop says so.
            () = tokio::time::sleep_until(ending.deadline().unwrap_or(far)) => {}
            _ = &mut shutdown => {
                view.abandon();
                return Ok(());
            }
        }
    }
}
