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
    collections::{BTreeMap, HashMap},
    time::Duration,
};

use tokio::time::Instant;

use protocol::{
    keys,
    wire::{IterationResult, RunStatus, TrialFailure, TrialOutcome, WireMessage, WorkerPresence},
};
use zenoh::{bytes::Encoding, sample::SampleKind, Session};

use crate::{
    evolve::{DecidedIteration, OpenedIteration},
    run::{Effect, FailureVerdict, Run, RunError},
    schedule::{Answer, Scheduler},
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
    /// Refused messages per reason.
    pub refused_reasons: BTreeMap<String, u64>,
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

struct State {
    run: Run,
    cfg: ServiceConfig,
    opened: BTreeMap<u64, OpenedIteration>,
    sched: Scheduler,
    dispatch: u64,
    counters: Counters,
    finished: bool,
    history: Vec<IterationResult>,
    started: Instant,
    trials_done: u64,
    /// Per worker: trials it failed that another worker then ran.
    bad: HashMap<String, u32>,
    /// (source, reason) pairs already logged.
    logged: std::collections::HashSet<(String, String)>,
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
            workers: u32::try_from(self.sched.workers()).unwrap_or(u32::MAX),
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
        let held = self.sched.worker_gone(id);
        if !held.is_empty() {
            tracing::info!(
                worker = id,
                trials = held.len(),
                "worker gone; its trials go back to the queue"
            );
        }
        for t in held {
            self.failed(t, id, "the worker went away while holding the trial")?;
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
                self.sched.failed(t, Instant::now());
            }
            FailureVerdict::GiveUp(g) => {
                self.counters.failures += 1;
                return Err(ServiceError::GaveUp(g));
            }
        }
        Ok(())
    }

    /// Refuses a message from `source` for `reason`: counted per reason, logged once per source and reason.
    fn refuse(&mut self, source: &str, reason: &str) {
        self.counters.refused += 1;
        *self
            .counters
            .refused_reasons
            .entry(reason.to_string())
            .or_default() += 1;
        if self.logged.insert((source.to_string(), reason.to_string())) {
            tracing::warn!(
                source,
                reason,
                "refused (further ones from this source for this reason are only counted)"
            );
        }
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
                self.sched.set_aside(&w);
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
        sched: Scheduler::new(cfg.lease, cfg.silence),
        cfg,
        opened: BTreeMap::new(),
        dispatch: 0,
        counters: Counters::default(),
        finished: false,
        history: Vec::new(),
        started: Instant::now(),
        trials_done: 0,
        bad: HashMap::new(),
        logged: std::collections::HashSet::new(),
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
            publish(&session, &keys::status(&prefix, &name), &st.status()).await;
            return Ok(Ended::Finished(st.counters));
        }
        tokio::select! {
            s = outcomes.recv_async() => {
                let s = s.map_err(zerr)?;
                let bytes = s.payload().to_bytes();
                match TrialOutcome::decode(&bytes) {
                    Err(e) => st.refuse("an undecodable message", &format!("outcome: {e}")),
                    Ok(o) if o.run != name => st.refuse(&o.worker, "outcome for another run"),
                    Ok(o) => on_outcome(&session, &mut st, o, events.as_ref()).await?,
                }
            }
            s = failures.recv_async() => {
                let s = s.map_err(zerr)?;
                match TrialFailure::decode(&s.payload().to_bytes()) {
                    Ok(f) if f.run == name => {
                        let t = (f.iteration, f.trial);
                        match st.sched.answered(t, &f.worker, f.dispatch, Instant::now()) {
                            Answer::Held => {
                                tracing::warn!(worker = %f.worker, iteration = f.iteration, trial = f.trial, reason = %f.reason, "a worker could not run a trial");
                                st.failed(t, &f.worker, &f.reason)?;
                                dispatch(&session, &mut st).await;
                            }
                            other => st.refuse(&f.worker, &format!("failure report: {}", other.reason())),
                        }
                    }
                    Ok(f) => st.refuse(&f.worker, "failure report for another run"),
                    Err(e) => st.refuse("an undecodable message", &format!("failure report: {e}")),
                }
            }
            s = presence.recv_async() => {
                let s = s.map_err(zerr)?;
                match WorkerPresence::decode(&s.payload().to_bytes()) {
                    Ok(p) => st.sched.worker_seen(&p.worker, Some(p.slots), Instant::now()),
                    Err(e) => st.refuse("an undecodable message", &format!("presence: {e}")),
                }
            }
            s = live.recv_async() => {
                let s = s.map_err(zerr)?;
                let id = keys::last_chunk(s.key_expr().as_str()).to_string();
                if s.kind() == SampleKind::Delete {
                    st.requeue_worker(&id)?;
                } else {
                    // Slots arrive with the first heartbeat; until then one.
                    st.sched.worker_seen(&id, None, Instant::now());
                }
            }
            q = status_q.recv_async() => {
                let q = q.map_err(zerr)?;
                reply_json(&q, st.status().to_json().map_err(|e| e.to_string())).await;
            }
            q = history_q.recv_async() => {
                let q = q.map_err(zerr)?;
                reply_json(&q, serde_json::to_string(&st.history).map_err(|e| e.to_string())).await;
            }
            _ = tick.tick() => {
                let t = st.sched.tick(Instant::now());
                for (trial, worker) in t.expired {
                    if st.run.is_pending(trial.0, trial.1) {
                        tracing::info!(iteration = trial.0, trial = trial.1, %worker, "lease expired; re-dispatching");
                        st.sched.enqueue(trial);
                        st.counters.redispatched += 1;
                    }
                }
                for id in t.silent {
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

/// Answers a query with a JSON body; a body that could not be encoded is
/// logged and not answered (the querier sees no reply, never an empty one).
async fn reply_json(q: &zenoh::query::Query, body: Result<String, String>) {
    match body {
        Ok(body) => {
            if let Err(e) = q
                .reply(q.key_expr().clone(), body)
                .encoding(Encoding::APPLICATION_JSON)
                .await
            {
                tracing::warn!(error = %e, "a query reply failed");
            }
        }
        Err(e) => tracing::error!(error = %e, "a query was not answered"),
    }
}

/// Publishes a watched message in its JSON form (one that cannot be encoded is logged, not sent).
async fn publish<M: WireMessage>(session: &Session, key: &str, message: &M) {
    match message.to_json() {
        Ok(body) => put_json(session, key, body).await,
        Err(e) => tracing::error!(key, error = %e, "not published"),
    }
}

async fn put_json(session: &Session, key: &str, body: String) {
    // Block, not drop, under congestion: watchers count on every result.
    if let Err(e) = session
        .put(key, body)
        .encoding(Encoding::APPLICATION_JSON)
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .await
    {
        tracing::warn!(key, error = %e, "publish failed");
    }
}

/// The most a trial's torso can travel, m.
pub const PLAUSIBLE_DISTANCE_M: f64 = 100.0;

/// Whether an outcome could be a real trial of `duration_s`.
fn plausible(o: &TrialOutcome, duration_s: f64) -> Result<(), String> {
    if o.x_m.abs() > PLAUSIBLE_DISTANCE_M || o.y_m.abs() > PLAUSIBLE_DISTANCE_M {
        return Err(format!(
            "x {} m, y {} m (beyond {PLAUSIBLE_DISTANCE_M} m)",
            o.x_m, o.y_m
        ));
    }
    if !(0.0..=duration_s + 1e-6).contains(&o.sim_time_s) {
        return Err(format!(
            "simulated time {} s outside [0, {duration_s}] s",
            o.sim_time_s
        ));
    }
    if o.fall_time_s
        .is_some_and(|t| t > o.sim_time_s + 1e-9 || t < 0.0)
    {
        return Err("fall time after the simulated time".into());
    }
    Ok(())
}

async fn on_outcome(
    session: &Session,
    st: &mut State,
    o: TrialOutcome,
    events: Option<&tokio::sync::mpsc::UnboundedSender<Event>>,
) -> Result<(), ServiceError> {
    let t = (o.iteration, o.trial);
    let answer = st.sched.answered(t, &o.worker, o.dispatch, Instant::now());
    if answer == Answer::WrongDispatch {
        // The holder answered under another id: it misbehaves; the trial fails on it.
        st.refuse(&o.worker, answer.reason());
        st.failed(t, &o.worker, "answered under a wrong dispatch id")?;
        return Ok(());
    }
    if answer != Answer::Held {
        // Never journaled: only the answer to a dispatch in flight counts
        // (a late answer after the lease passed included).
        st.refuse(&o.worker, answer.reason());
        return Ok(());
    }
    let duration = st.run.evolve().experiment().trial_duration_s;
    if let Err(why) = plausible(&o, duration) {
        tracing::warn!(worker = %o.worker, iteration = o.iteration, trial = o.trial, %why, "an implausible outcome counts as a failure");
        st.failed(t, &o.worker, &format!("implausible outcome: {why}"))?;
        return Ok(());
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
            st.sched.forget(t);
            let prefix = st.cfg.prefix.clone();
            publish(
                session,
                &keys::trial(&prefix, &o.run, o.iteration, o.trial),
                &o,
            )
            .await;
            handle_effects(session, st, effects, events).await?;
        }
        Err(RunError::Refused(e)) => {
            let reason = match e {
                crate::evolve::OutcomeError::WrongSeed { .. } => "wrong seed",
                crate::evolve::OutcomeError::Invalid { .. } => "invalid numbers",
                _ => "trial not open",
            };
            st.refuse(&o.worker, reason);
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
                    st.sched.enqueue((o.iteration, k));
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
                    json.to_string(),
                )
                .await;
                st.opened.insert(o.iteration, o);
            }
            Effect::Decided(d) => {
                st.opened.remove(&d.iteration);
                let r = st.result_of(&d);
                publish(session, &keys::results(&prefix, &name, d.iteration), &r).await;
                let status = st.status();
                publish(session, &keys::status(&prefix, &name), &status).await;
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
    let run = &st.run;
    // Dispatch ids are unguessable: an answer must echo the one it was sent.
    let mut rng = rand::rng();
    let sends = st.sched.dispatch(
        Instant::now(),
        &|t| run.failed_workers(t.0, t.1),
        &mut || rand::Rng::random::<u64>(&mut rng),
    );
    for (t, id, dispatch_id) in sends {
        let Some(opened) = st.opened.get(&t.0) else {
            st.sched.forget(t);
            continue;
        };
        st.dispatch += 1;
        let req = match st.run.request(opened, t.1, dispatch_id) {
            Ok(r) => r,
            Err(e) => {
                tracing::error!(error = %e, "a queued trial has no request; dropped");
                st.sched.forget(t);
                continue;
            }
        };
        let bytes = match req.encode() {
            Ok(b) => b,
            Err(e) => {
                tracing::error!(error = %e, "a trial request cannot be encoded; dropped");
                st.sched.forget(t);
                continue;
            }
        };
        if let Err(e) = session.put(keys::work(&st.cfg.prefix, &id), bytes).await {
            tracing::warn!(worker = %id, error = %e, "dispatch failed");
        }
    }
}

/// CPU time (user + system) this process has used, from `/proc/self/stat`
/// (Linux; clock ticks of 1/100 s, the kernel's USER_HZ). `None` elsewhere.
#[must_use]
pub fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which may hold spaces) closed by ')'.
    let rest = stat.rsplit_once(')')?.1;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of stat(5); `rest` starts at field 3.
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}
