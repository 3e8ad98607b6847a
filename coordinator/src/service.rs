//! The coordinator service: drives a [`Run`] over zenoh.
//!
//! It hands each trial to one live worker (addressed by id, never by
//! best-matching), keeps at most `slots` trials on a worker, re-queues a
//! trial when its worker's liveliness token disappears, when the worker stops
//! sending heartbeats, or when the trial's lease deadline passes, and counts a
//! late or duplicate outcome once (the [`Run`] decides). Watched topics
//! (trials, results, status) carry JSON. Bad messages are logged, counted and
//! dropped; nothing reaches the journal unless the run accepts it.

use std::{
    collections::{BTreeMap, BTreeSet, HashMap},
    time::{Duration, Instant},
};

use protocol::{
    keys,
    wire::{IterationResult, RunStatus, TrialFailure, TrialOutcome, WireMessage, WorkerPresence},
};
use zenoh::{bytes::Encoding, sample::SampleKind, Session};

use crate::{
    evolve::{DecidedIteration, OpenedIteration},
    run::{Effect, FailureVerdict, Run, RunError},
};

/// Settings of the coordinator service.
#[derive(Debug, Clone)]
pub struct ServiceConfig {
    /// Key prefix (default `naofarm`).
    pub prefix: String,
    /// A trial not answered within this time is given to another worker.
    pub lease: Duration,
    /// A worker not heard from (heartbeat or outcome) for this long gets no new work.
    pub silence: Duration,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        Self {
            prefix: keys::DEFAULT_PREFIX.to_string(),
            lease: Duration::from_secs(120),
            silence: Duration::from_secs(3),
        }
    }
}

/// Counters of what the service saw.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Counters {
    /// Outcomes journaled.
    pub accepted: u64,
    /// Outcomes that were duplicates (late or re-dispatched).
    pub duplicates: u64,
    /// Messages refused (undecodable, unknown run/iteration/trial, NaN, wrong seed).
    pub refused: u64,
    /// Trials re-dispatched (lost worker or lease).
    pub redispatched: u64,
    /// Trial failures journaled (a worker's report, or its loss while holding the trial).
    pub failures: u64,
    /// Workers set aside for failing trials that others ran.
    pub set_aside: Vec<String>,
}

/// A worker that failed this many trials which others then ran is set aside.
pub const SET_ASIDE_AFTER: u32 = 3;

/// How the service ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Ended {
    /// Every iteration decided.
    Finished(Counters),
    /// Stopped by the shutdown signal.
    Interrupted(Counters),
}

/// Progress events for views (the run's own terminal, tests).
#[derive(Debug, Clone)]
pub enum Event {
    /// The state when the service starts (a resumed run's history included).
    Started(Vec<IterationResult>, Box<RunStatus>),
    /// An iteration was decided: what the results topic carries, and the status after it.
    Decided(Box<IterationResult>, Box<RunStatus>),
}

/// Service failures.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// The run (journal) failed.
    #[error(transparent)]
    Run(#[from] RunError),
    /// Zenoh failed.
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// A trial could not be run on any worker.
    #[error("{0}")]
    GaveUp(crate::run::GaveUp),
}

fn zerr(e: impl std::fmt::Display) -> ServiceError {
    ServiceError::Zenoh(e.to_string())
}

#[derive(Debug)]
struct WorkerInfo {
    slots: u32,
    assigned: BTreeSet<(u64, u32)>,
    last_seen: Instant,
}

impl WorkerInfo {
    fn new(slots: u32) -> Self {
        Self {
            slots,
            assigned: BTreeSet::new(),
            last_seen: Instant::now(),
        }
    }
}

#[derive(Debug)]
struct Inflight {
    worker: String,
    deadline: Instant,
}

struct State {
    run: Run,
    cfg: ServiceConfig,
    opened: BTreeMap<u64, OpenedIteration>,
    queue: BTreeSet<(u64, u32)>,
    inflight: HashMap<(u64, u32), Inflight>,
    workers: BTreeMap<String, WorkerInfo>,
    dispatch: u64,
    counters: Counters,
    finished: bool,
    history: Vec<IterationResult>,
    started: Instant,
    trials_done: u64,
    /// Per worker: trials it failed that another worker then ran.
    bad: HashMap<String, u32>,
}

impl State {
    fn status(&self) -> RunStatus {
        let ev = self.run.evolve();
        let (a, e, r) = ev.counts();
        let exp = ev.experiment();
        let secs = self.started.elapsed().as_secs_f64();
        #[allow(clippy::cast_precision_loss)]
        let rate = if secs > 0.0 {
            self.trials_done as f64 / secs
        } else {
            0.0
        };
        RunStatus {
            run: exp.name.clone(),
            planned: exp.iterations,
            opened: ev.opened(),
            decided: ev.decided(),
            accepts: a,
            equivalents: e,
            rejects: r,
            best: ev.best_wire(),
            optim2: ev.named(&ev.optim2()),
            workers: u32::try_from(self.workers.len()).unwrap_or(u32::MAX),
            trials_per_s: rate,
            finished: ev.finished(),
        }
    }

    fn result_of(&self, d: &DecidedIteration) -> IterationResult {
        let ev = self.run.evolve();
        IterationResult {
            run: ev.experiment().name.clone(),
            iteration: d.iteration,
            params: ev.named(&d.params),
            stats: d.stats.clone(),
            decision: d.decision,
            best: d.best.as_ref().map(|b| ev.wire_best(b)),
        }
    }

    /// A worker is gone (token dropped, or silent): its trials count as failed
    /// by it and go back to the queue.
    fn requeue_worker(&mut self, id: &str) -> Result<(), ServiceError> {
        if let Some(w) = self.workers.remove(id) {
            tracing::info!(worker = id, "worker gone; its trials go back to the queue");
            for t in w.assigned {
                if self.inflight.remove(&t).is_some() {
                    self.failed(t, id, "the worker went away while holding the trial")?;
                }
            }
        }
        Ok(())
    }

    /// Journals a failure of trial `t` on worker `id` and re-queues the trial,
    /// or stops the run when it has failed too often.
    fn failed(&mut self, t: (u64, u32), id: &str, reason: &str) -> Result<(), ServiceError> {
        match self.run.on_failure(t.0, t.1, id, reason)? {
            FailureVerdict::Ignored => {}
            FailureVerdict::Retry => {
                self.counters.failures += 1;
                self.counters.redispatched += 1;
                self.queue.insert(t);
            }
            FailureVerdict::GiveUp(g) => {
                self.counters.failures += 1;
                return Err(ServiceError::GaveUp(g));
            }
        }
        Ok(())
    }

    /// A trial was run: every other worker that failed it gets a mark.
    fn ran_elsewhere(&mut self, t: (u64, u32), by: &str) {
        for w in self.run.failed_workers(t.0, t.1) {
            if w == by {
                continue;
            }
            let n = self.bad.entry(w.clone()).or_default();
            *n += 1;
            if *n == SET_ASIDE_AFTER && !self.counters.set_aside.contains(&w) {
                tracing::warn!(worker = %w, "set aside: it failed {SET_ASIDE_AFTER} trials that other workers ran");
                self.counters.set_aside.push(w);
            }
        }
    }
}

/// Runs the coordinator until the run finishes or `shutdown` turns true.
pub async fn serve(
    session: Session,
    run: Run,
    effects: Vec<Effect>,
    cfg: ServiceConfig,
    mut shutdown: tokio::sync::watch::Receiver<bool>,
    events: Option<tokio::sync::mpsc::UnboundedSender<Event>>,
) -> Result<Ended, ServiceError> {
    let prefix = cfg.prefix.clone();
    let name = run.evolve().experiment().name.clone();
    let outcomes = session
        .declare_subscriber(keys::outcomes(&prefix))
        .await
        .map_err(zerr)?;
    let failures = session
        .declare_subscriber(keys::failures(&prefix))
        .await
        .map_err(zerr)?;
    let presence = session
        .declare_subscriber(keys::presence(&prefix))
        .await
        .map_err(zerr)?;
    let live = session
        .liveliness()
        .declare_subscriber(keys::workers_all(&prefix))
        .history(true)
        .await
        .map_err(zerr)?;
    let status_q = session
        .declare_queryable(keys::status(&prefix, &name))
        .await
        .map_err(zerr)?;
    let history_q = session
        .declare_queryable(keys::history(&prefix, &name))
        .await
        .map_err(zerr)?;
    let _token = session
        .liveliness()
        .declare_token(keys::coordinator(&prefix, &name))
        .await
        .map_err(zerr)?;
    let mut st = State {
        run,
        cfg,
        opened: BTreeMap::new(),
        queue: BTreeSet::new(),
        inflight: HashMap::new(),
        workers: BTreeMap::new(),
        dispatch: 0,
        counters: Counters::default(),
        finished: false,
        history: Vec::new(),
        started: Instant::now(),
        trials_done: 0,
        bad: HashMap::new(),
    };
    if let Some(g) = st.run.exhausted() {
        return Err(ServiceError::GaveUp(g));
    }
    // A resumed run answers history queries with what it decided before.
    st.history = st
        .run
        .evolve()
        .history()
        .iter()
        .map(|d| st.result_of(d))
        .collect();
    if let Some(tx) = &events {
        let _ = tx.send(Event::Started(st.history.clone(), Box::new(st.status())));
    }
    handle_effects(&session, &mut st, effects, events.as_ref()).await?;
    let mut tick = tokio::time::interval(Duration::from_millis(50));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        if st.finished {
            put_json(
                &session,
                &keys::status(&prefix, &name),
                &st.status().to_json(),
            )
            .await;
            return Ok(Ended::Finished(st.counters));
        }
        tokio::select! {
            s = outcomes.recv_async() => {
                let s = s.map_err(zerr)?;
                let bytes = s.payload().to_bytes();
                match TrialOutcome::decode(&bytes) {
                    Err(e) => {
                        st.counters.refused += 1;
                        tracing::warn!(error = %e, "refused a message on the outcomes topic");
                    }
                    Ok(o) if o.run != name => {
                        st.counters.refused += 1;
                        tracing::warn!(run = %o.run, "refused an outcome for an unknown run");
                    }
                    Ok(o) => on_outcome(&session, &mut st, o, events.as_ref()).await?,
                }
            }
            s = failures.recv_async() => {
                let s = s.map_err(zerr)?;
                match TrialFailure::decode(&s.payload().to_bytes()) {
                    Ok(f) if f.run == name => {
                        let t = (f.iteration, f.trial);
                        if st.inflight.get(&t).is_some_and(|x| x.worker == f.worker) {
                            tracing::warn!(worker = %f.worker, iteration = f.iteration, trial = f.trial, reason = %f.reason, "a worker could not run a trial");
                            st.inflight.remove(&t);
                            if let Some(w) = st.workers.get_mut(&f.worker) {
                                w.assigned.remove(&t);
                                w.last_seen = Instant::now();
                            }
                            st.failed(t, &f.worker, &f.reason)?;
                            dispatch(&session, &mut st).await;
                        } else {
                            st.counters.refused += 1;
                            tracing::warn!(worker = %f.worker, "refused a failure report for a trial that worker does not hold");
                        }
                    }
                    Ok(_) => st.counters.refused += 1,
                    Err(e) => {
                        st.counters.refused += 1;
                        tracing::warn!(error = %e, "refused a message on the failures topic");
                    }
                }
            }
            s = presence.recv_async() => {
                let s = s.map_err(zerr)?;
                match WorkerPresence::decode(&s.payload().to_bytes()) {
                    Ok(p) => {
                        let w = st.workers.entry(p.worker.clone()).or_insert_with(|| WorkerInfo::new(p.slots));
                        w.slots = p.slots;
                        w.last_seen = Instant::now();
                    }
                    Err(e) => {
                        st.counters.refused += 1;
                        tracing::warn!(error = %e, "refused a presence message");
                    }
                }
            }
            s = live.recv_async() => {
                let s = s.map_err(zerr)?;
                let id = keys::last_chunk(s.key_expr().as_str()).to_string();
                if s.kind() == SampleKind::Delete {
                    st.requeue_worker(&id)?;
                } else {
                    // Slots arrive with the first heartbeat; until then one.
                    st.workers.entry(id).or_insert_with(|| WorkerInfo::new(1));
                }
            }
            q = status_q.recv_async() => {
                let q = q.map_err(zerr)?;
                let body = st.status().to_json();
                if let Err(e) = q.reply(q.key_expr().clone(), body).encoding(Encoding::APPLICATION_JSON).await {
                    tracing::warn!(error = %e, "status reply failed");
                }
            }
            q = history_q.recv_async() => {
                let q = q.map_err(zerr)?;
                let body = serde_json::to_string(&st.history).unwrap_or_default();
                if let Err(e) = q.reply(q.key_expr().clone(), body).encoding(Encoding::APPLICATION_JSON).await {
                    tracing::warn!(error = %e, "history reply failed");
                }
            }
            _ = tick.tick() => {
                let now = Instant::now();
                let expired: Vec<(u64, u32)> = st.inflight.iter().filter(|(_, f)| f.deadline <= now).map(|(k, _)| *k).collect();
                for t in expired {
                    if let Some(f) = st.inflight.remove(&t) {
                        if let Some(w) = st.workers.get_mut(&f.worker) {
                            w.assigned.remove(&t);
                        }
                        if st.run.is_pending(t.0, t.1) {
                            tracing::info!(iteration = t.0, trial = t.1, worker = %f.worker, "lease expired; re-dispatching");
                            st.queue.insert(t);
                            st.counters.redispatched += 1;
                        }
                    }
                }
                let silence = st.cfg.silence;
                let silent: Vec<String> = st.workers.iter().filter(|(_, w)| now.duration_since(w.last_seen) > silence * 4).map(|(k, _)| k.clone()).collect();
                for id in silent {
                    // Far past its heartbeat: treat as gone even if its token lingers.
                    st.requeue_worker(&id)?;
                }
                dispatch(&session, &mut st).await;
            }
            _ = shutdown.changed() => {
                if *shutdown.borrow() {
                    return Ok(Ended::Interrupted(st.counters));
                }
            }
        }
    }
}

async fn put_json(session: &Session, key: &str, body: &str) {
    // Block, not drop, under congestion: watchers count on every result.
    if let Err(e) = session
        .put(key, body.to_string())
        .encoding(Encoding::APPLICATION_JSON)
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .await
    {
        tracing::warn!(key, error = %e, "publish failed");
    }
}

async fn on_outcome(
    session: &Session,
    st: &mut State,
    o: TrialOutcome,
    events: Option<&tokio::sync::mpsc::UnboundedSender<Event>>,
) -> Result<(), ServiceError> {
    let t = (o.iteration, o.trial);
    if let Some(w) = st.workers.get_mut(&o.worker) {
        w.assigned.remove(&t);
        w.last_seen = Instant::now();
    }
    if st.inflight.get(&t).is_some_and(|f| f.worker == o.worker) {
        st.inflight.remove(&t);
    }

    match st
        .run
        .on_outcome(o.iteration, o.trial, o.seed, o.measurement(), &o.worker)
    {
        Ok((crate::evolve::Counted::Duplicate, _)) => {
            st.counters.duplicates += 1;
            tracing::debug!(
                iteration = o.iteration,
                trial = o.trial,
                "duplicate outcome ignored"
            );
        }
        Ok((crate::evolve::Counted::New, effects)) => {
            st.ran_elsewhere(t, &o.worker);
            st.counters.accepted += 1;
            st.trials_done += 1;
            st.queue.remove(&t);
            st.inflight.remove(&t);
            let prefix = st.cfg.prefix.clone();
            put_json(
                session,
                &keys::trial(&prefix, &o.run, o.iteration, o.trial),
                &o.to_json(),
            )
            .await;
            handle_effects(session, st, effects, events).await?;
        }
        Err(RunError::Refused(e)) => {
            st.counters.refused += 1;
            tracing::warn!(error = %e, worker = %o.worker, "refused an outcome");
        }
        Err(e) => return Err(e.into()),
    }
    Ok(())
}

async fn handle_effects(
    session: &Session,
    st: &mut State,
    effects: Vec<Effect>,
    events: Option<&tokio::sync::mpsc::UnboundedSender<Event>>,
) -> Result<(), ServiceError> {
    let prefix = st.cfg.prefix.clone();
    let name = st.run.evolve().experiment().name.clone();
    for e in effects {
        match e {
            Effect::Dispatch(o, ks) => {
                for k in ks {
                    st.queue.insert((o.iteration, k));
                }
                let ev = st.run.evolve();
                let json = serde_json::json!({
                    "run": name,
                    "iteration": o.iteration,
                    "params": ev.named(&o.params),
                    "trials": o.seeds.len(),
                    "expert": o.expert,
                });
                put_json(
                    session,
                    &keys::params(&prefix, &name, o.iteration),
                    &json.to_string(),
                )
                .await;
                st.opened.insert(o.iteration, o);
            }
            Effect::Decided(d) => {
                st.opened.remove(&d.iteration);
                let r = st.result_of(&d);
                put_json(
                    session,
                    &keys::results(&prefix, &name, d.iteration),
                    &r.to_json(),
                )
                .await;
                let status = st.status();
                put_json(session, &keys::status(&prefix, &name), &status.to_json()).await;
                st.history.push(r.clone());
                if let Some(tx) = events {
                    let _ = tx.send(Event::Decided(Box::new(r), Box::new(status)));
                }
            }
            Effect::Finished => st.finished = true,
        }
    }
    dispatch(session, st).await;
    Ok(())
}

async fn dispatch(session: &Session, st: &mut State) {
    let now = Instant::now();
    let silence = st.cfg.silence;
    let usable = |st: &State, id: &String, w: &WorkerInfo| {
        now.duration_since(w.last_seen) <= silence && !st.counters.set_aside.contains(id)
    };
    let queued: Vec<(u64, u32)> = st.queue.iter().copied().collect();
    for t in queued {
        let free = st
            .workers
            .iter()
            .any(|(id, w)| usable(st, id, w) && (w.assigned.len() as u64) < u64::from(w.slots));
        if !free {
            break;
        }
        let Some(opened) = st.opened.get(&t.0) else {
            st.queue.remove(&t);
            continue;
        };
        // A trial that failed somewhere waits for a live worker that has not
        // failed it, when there is one; among the candidates, the one with the
        // most free slots (ties: smallest id).
        let failed = st.run.failed_workers(t.0, t.1);
        let fresh_exists = st
            .workers
            .iter()
            .any(|(id, w)| usable(st, id, w) && !failed.contains(id));
        let pick = st
            .workers
            .iter()
            .filter(|(id, w)| usable(st, id, w))
            .filter(|(_, w)| (w.assigned.len() as u64) < u64::from(w.slots))
            .filter(|(id, _)| !(fresh_exists && failed.contains(*id)))
            .max_by_key(|(id, w)| {
                (
                    u64::from(w.slots) - w.assigned.len() as u64,
                    std::cmp::Reverse((*id).clone()),
                )
            })
            .map(|(id, _)| id.clone());
        let Some(id) = pick else { continue };
        st.dispatch += 1;
        let req = match st.run.request(opened, t.1, st.dispatch) {
            Ok(r) => r,
            Err(e) => {
                tracing::error!(error = %e, "a queued trial has no request; dropped");
                st.queue.remove(&t);
                continue;
            }
        };
        st.queue.remove(&t);
        if let Some(w) = st.workers.get_mut(&id) {
            w.assigned.insert(t);
        }
        st.inflight.insert(
            t,
            Inflight {
                worker: id.clone(),
                deadline: now + st.cfg.lease,
            },
        );
        if let Err(e) = session
            .put(keys::work(&st.cfg.prefix, &id), req.encode())
            .await
        {
            tracing::warn!(worker = %id, error = %e, "dispatch failed");
        }
    }
}
