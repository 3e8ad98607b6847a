//! The coordinator service: drives a [`Run`] over zenoh, as one of many runs
//! sharing a fleet of workers.
//!
//! Workers pull: a worker asks the run's `work` queryable for trials (at most
//! its free slots) and gets them in the reply, each under an unguessable
//! dispatch id; the run advertises its priority and how many trials it has
//! ready on its `ad` key, and workers share their slots among the runs by
//! priority (see `docs/fleet.md`). Every fleet key carries the run id, so a
//! coordinator hears only its own run's outcomes. A trial goes back to the
//! queue when its worker's liveliness token disappears, when the worker stops
//! sending heartbeats, or when its lease passes; only the answer to the
//! dispatch in flight counts, once (the [`Run`] decides). Watched topics
//! (trials, results, status) carry JSON. Bad messages are logged once per
//! source, counted per reason and dropped; nothing reaches the journal unless
//! the run accepts it.

use std::{
    collections::{BTreeMap, HashMap},
    time::Duration,
};

use tokio::time::Instant;

use protocol::{
    keys::{self, FleetKeys, RunKeys},
    wire::{
        show_fingerprint, Control, ControlRequest, IterationResult, RunAdvert, RunState, RunStatus,
        TrialFailure, TrialOutcome, WireMessage, WorkGrant, WorkRequest, WorkerPresence,
    },
};
use zenoh::{bytes::Encoding, sample::SampleKind, Session};

use crate::{
    decider::{self, Cmd, Decider, Facts, Fx, Reply, Snapshot},
    evolve::{Counted, OpenedIteration},
    run::{Effect, FailureVerdict, Run, RunError},
    schedule::{Answer, Scheduler},
};

mod handlers;
pub use handlers::PLAUSIBLE_DISTANCE_M;
use handlers::{
    no_worker_fits, on_ctl, on_failure, on_outcome, on_reply, on_work, publish, put_json,
    reply_history, reply_json,
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
#[derive(Debug, Clone, Default, PartialEq)]
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
    /// Trials failed or given back by workers, per reason (at most 64
    /// reasons; further ones are counted under "other reasons").
    pub failure_reasons: BTreeMap<String, u64>,
    /// Ready → handed to a worker, ms, per trial (the first 100,000).
    pub dispatch_ms: Vec<f32>,
    /// Seconds spent applying outcomes to the run (journal, pickOut, CLOP's fit and draw).
    pub decide_s: f64,
    /// CPU seconds of the run's thread (journal, pickOut, CLOP), when known.
    pub run_cpu_s: Option<f64>,
    /// Work requests answered (each a query and its reply).
    pub work_requests: u64,
    /// Adverts published.
    pub adverts: u64,
    /// Work requests answered with no trial (another worker was first, or the run is not running).
    pub empty_grants: u64,
}

impl Counters {
    /// The `q`-quantile (0..=1) of the dispatch latencies, ms.
    #[must_use]
    pub fn dispatch_quantile(&self, q: f64) -> Option<f64> {
        let mut v = self.dispatch_ms.clone();
        if v.is_empty() {
            return None;
        }
        v.sort_by(f32::total_cmp);
        #[allow(
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss,
            clippy::cast_precision_loss
        )]
        let i = ((v.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize;
        v.get(i).map(|x| f64::from(*x))
    }
}

/// A worker that failed this many trials which others then ran is set aside.
pub const SET_ASIDE_AFTER: u32 = 3;

/// How the service ended.
#[derive(Debug, Clone, PartialEq)]
pub enum Ended {
    /// Every iteration decided.
    Finished(Counters),
    /// Stopped by the shutdown signal.
    Interrupted(Counters),
    /// Stopped by `naofarm ctl RUN stop` (journaled; the run can be resumed).
    Stopped(Counters, String),
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
    /// The run's thread ended without saying why (it always says why first).
    #[error("the run's thread ended")]
    RunEnded,
    /// A trial could not be run on any worker.
    #[error("{0}")]
    GaveUp(crate::run::GaveUp),
    /// Another coordinator already serves this run id (a copied run directory?).
    #[error("run id {id} is already served by another coordinator on this network (a copy of the run directory?); refusing to serve it twice")]
    AlreadyServed {
        /// The run id.
        id: String,
    },
    /// A resumed run met workers, and none has the fingerprint its history was made with.
    #[error("run {id}: its history was made by workers of fingerprint {ours}, and every worker here has another ({theirs}): their trials might not give the same bits (another naofarm build, or another CPU's maths); start workers of this build on such hosts, or start the run afresh")]
    NoMatchingWorker {
        /// The run id.
        id: String,
        /// The run's journaled fingerprint.
        ours: String,
        /// The workers' fingerprints, with their ids.
        theirs: String,
    },
}

fn zerr(e: impl std::fmt::Display) -> ServiceError {
    ServiceError::Zenoh(e.to_string())
}

struct State {
    /// Commands to the run's thread (journal, pickOut, CLOP).
    run: std::sync::mpsc::Sender<Cmd>,
    /// The run as of its thread's last reply.
    snap: Snapshot,
    /// Fixed facts, pending trials and who failed them (kept here as the
    /// service takes outcomes and failures; the run's thread agrees).
    facts: Facts,
    /// Control queries waiting for the run's thread, by tag.
    ctl_waiting: HashMap<u64, zenoh::query::Query>,
    next_tag: u64,
    rkeys: RunKeys,
    fkeys: FleetKeys,
    /// Sequence number of the last advert; whether it said trials were ready;
    /// whether a worker got fewer trials than it wanted since (it waits for
    /// the next advert before asking again).
    advert: (u64, bool, bool),
    /// Trials in flight as of the last advert, and when it went.
    advertised_running: (usize, Instant),
    stopped: Option<String>,
    /// Workers whose token went, and when: their trials go back to the queue
    /// after [`GONE_GRACE`] (what they gave back on their way out counts first).
    gone: Vec<(String, Instant)>,
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
    /// Whether the run's worker fingerprint (`facts.fingerprint`) came from
    /// the journal (a resumed run) rather than from this session's first asker.
    journaled_fingerprint: bool,
    /// Whether a worker of the run's fingerprint asked in this session.
    matched: bool,
    /// Workers that asked with another fingerprint: id → fingerprint.
    mismatched: BTreeMap<String, u64>,
    /// Workers whose liveliness tokens are up.
    live: std::collections::BTreeSet<String>,
}

impl State {
    fn status(&self) -> RunStatus {
        let (a, e, r) = self.snap.counts;
        let exp = &self.facts.experiment;
        let secs = self.started.elapsed().as_secs_f64();
        #[allow(clippy::cast_precision_loss)]
        let rate = if secs > 0.0 {
            self.trials_done as f64 / secs
        } else {
            0.0
        };
        RunStatus {
            run: exp.name.clone(),
            id: self.facts.id.clone(),
            priority: self.snap.priority,
            state: self.state(),
            planned: exp.iterations,
            opened: self.snap.opened,
            decided: self.snap.decided,
            accepts: a,
            equivalents: e,
            rejects: r,
            best: self.snap.best.clone(),
            optim2: self.snap.optim2.clone(),
            optim2_decided: self.snap.optim2_decided,
            workers: u32::try_from(self.sched.workers()).unwrap_or(u32::MAX),
            trials_per_s: rate,
            finished: self.snap.finished,
            failures: protocol::wire::reason_counts(&self.counters.failure_reasons),
            refused: protocol::wire::reason_counts(&self.counters.refused_reasons),
        }
    }

    /// Counts a trial that a worker failed or gave back, by reason.
    fn count_failure(&mut self, reason: String) {
        let map = &mut self.counters.failure_reasons;
        let key = if map.len() < 64 || map.contains_key(&reason) {
            reason
        } else {
            "other reasons".to_string()
        };
        *map.entry(key).or_default() += 1;
    }

    fn state(&self) -> RunState {
        if self.snap.finished {
            RunState::Finished
        } else if self.stopped.is_some() {
            RunState::Stopped
        } else if self.snap.paused {
            RunState::Paused
        } else {
            RunState::Running
        }
    }

    fn advert(&mut self) -> RunAdvert {
        self.advert.0 += 1;
        let ready = if self.state() == RunState::Running {
            u32::try_from(self.sched.ready()).unwrap_or(u32::MAX)
        } else {
            0
        };
        self.advert.1 = ready > 0;
        self.advert.2 = false;
        let running = self.sched.in_flight();
        self.advertised_running = (running, Instant::now());
        RunAdvert {
            id: self.facts.id.clone(),
            name: self.facts.experiment.name.clone(),
            priority: self.snap.priority,
            ready,
            running: u32::try_from(running).unwrap_or(u32::MAX),
            state: self.state(),
            duration_s: self.facts.experiment.trial_duration_s,
            program: self.facts.experiment.program.clone(),
            seq: self.advert.0,
        }
    }

    /// Whether workers must hear of a change now: trials became ready, ran
    /// out, or are ready while a worker that got a short grant waits; or,
    /// while trials are ready, the trials in flight moved by a sixteenth of
    /// the last advert's count (at least 2), at most every
    /// [`ADVERT_MOVED_EVERY`]. Workers share the slots by that count: a
    /// stale one keeps a run that fell behind waiting
    /// (measured in docs/fleet.md: a run with 73 trials ready went unasked
    /// for 450 ms while workers believed it had its window in flight).
    fn advert_due(&self) -> bool {
        let ready = self.state() == RunState::Running && self.sched.ready() > 0;
        let running = self.sched.in_flight();
        let moved = ready
            && running.abs_diff(self.advertised_running.0)
                >= (self.advertised_running.0 / 16).max(2)
            && self.advertised_running.1.elapsed() >= ADVERT_MOVED_EVERY;
        ready != self.advert.1 || (ready && self.advert.2) || moved
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
            // A worker whose link dropped (or that fell silent under load)
            // did not fail the trial: it must not be set aside for it when
            // another worker runs it (a healed worker would be idle for good,
            // and a run whose every worker had a cut link would stall).
            if let Some(w) = self.facts.failed.get_mut(&t) {
                w.remove(id);
            }
        }
        Ok(())
    }

    /// Trial `t` failed on worker `id`: it goes back to the queue at once
    /// (offered to others first) and the run's thread journals the failure;
    /// its verdict may stop the run. A trial no longer pending is ignored.
    fn failed(&mut self, t: (u64, u32), id: &str, reason: &str) -> Result<(), ServiceError> {
        if !self.facts.pending.contains(&t) {
            return Ok(());
        }
        self.facts
            .failed
            .entry(t)
            .or_default()
            .insert(id.to_string());
        self.counters.failures += 1;
        self.count_failure(reason.to_string());
        self.counters.redispatched += 1;
        self.sched.failed(t, Instant::now());
        self.send(Cmd::Failure {
            iteration: t.0,
            trial: t.1,
            worker: id.to_string(),
            reason: reason.to_string(),
        })
    }

    fn send(&self, cmd: Cmd) -> Result<(), ServiceError> {
        self.run.send(cmd).map_err(|_| ServiceError::RunEnded)
    }

    fn tag(&mut self) -> u64 {
        self.next_tag += 1;
        self.next_tag
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
        for w in self.facts.failed.remove(&t).unwrap_or_default() {
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

/// Runs the coordinator until the run finishes, `shutdown` turns true, or
/// `naofarm ctl` stops it.
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
    let id = run.id().to_string();
    let rkeys = RunKeys::new(&prefix, &name, &id);
    let fkeys = FleetKeys::new(&prefix, &id);
    // A copied run directory must not be served twice: ask for the run's token first.
    let claimed = session
        .liveliness()
        .get(keys::coordinator(&prefix, &id))
        .timeout(Duration::from_millis(500))
        .await
        .map_err(zerr)?;
    while let Ok(reply) = claimed.recv_async().await {
        if reply.result().is_ok() {
            return Err(ServiceError::AlreadyServed { id });
        }
    }
    let sub = |key: String| async { session.declare_subscriber(key).await.map_err(zerr) };
    let queryable = |key: String| async { session.declare_queryable(key).await.map_err(zerr) };
    let subs = Subscriptions {
        outcomes: sub(fkeys.outcomes()).await?,
        failures: sub(fkeys.failures()).await?,
        presence: sub(fkeys.presence()).await?,
        live: session
            .liveliness()
            .declare_subscriber(keys::workers_all(&prefix))
            .history(true)
            .await
            .map_err(zerr)?,
        work_q: queryable(fkeys.work()).await?,
        ctl_q: queryable(fkeys.ctl()).await?,
        status_q: queryable(rkeys.status()).await?,
        history_q: queryable(rkeys.history()).await?,
        experiment_q: queryable(rkeys.experiment()).await?,
    };
    let _token = session
        .liveliness()
        .declare_token(keys::coordinator(&prefix, &id))
        .await
        .map_err(zerr)?;
    if let Some(g) = run.exhausted() {
        return Err(ServiceError::GaveUp(g));
    }
    // A resumed run answers history queries with what it decided before.
    let history: Vec<IterationResult> = run
        .evolve()
        .history()
        .iter()
        .map(|d| decider::result_of(&run, d))
        .collect();
    let effects = decider::effects(&run, effects);
    let facts = Facts::of(&run);
    let journaled_fingerprint = facts.fingerprint.is_some();
    let snap = Snapshot::of(&run);
    let Decider {
        tx,
        rx: mut replies,
        handle,
    } = Decider::start(run).map_err(|e| ServiceError::Zenoh(format!("the run's thread: {e}")))?;
    let mut st = State {
        run: tx,
        snap,
        facts,
        ctl_waiting: HashMap::new(),
        next_tag: 0,
        sched: Scheduler::new(cfg.lease, cfg.silence),
        rkeys,
        fkeys,
        advert: (0, false, false),
        advertised_running: (0, Instant::now()),
        stopped: None,
        gone: Vec::new(),
        opened: BTreeMap::new(),
        dispatch: 0,
        counters: Counters::default(),
        finished: false,
        history,
        started: Instant::now(),
        trials_done: 0,
        bad: HashMap::new(),
        logged: std::collections::HashSet::new(),
        journaled_fingerprint,
        matched: false,
        mismatched: BTreeMap::new(),
        live: std::collections::BTreeSet::new(),
    };
    if let Some(tx) = &events {
        let _ = tx.send(Event::Started(st.history.clone(), Box::new(st.status())));
    }
    let ended = serve_loop(
        &session,
        &mut st,
        effects,
        &mut replies,
        &subs,
        &mut shutdown,
        events.as_ref(),
    )
    .await;
    // The run's thread ends only after sending why (a journal that failed):
    // that reason, not the closed channel a later command met, is the error.
    let ended = match ended {
        Err(ServiceError::RunEnded) => {
            let mut why = Err(ServiceError::RunEnded);
            while let Ok(r) = replies.try_recv() {
                if let Reply::Fatal(e) = r {
                    why = Err(e.into());
                }
            }
            why
        }
        other => other,
    };
    // Everything sent is applied and the run closed before this returns.
    let State { run, .. } = st;
    drop(run);
    let run_cpu = tokio::task::spawn_blocking(move || {
        handle.join().unwrap_or_else(|_| {
            tracing::error!("the run's thread panicked");
            None
        })
    })
    .await
    .ok()
    .flatten();
    drop(replies);
    ended.map(|mut e| {
        match &mut e {
            Ended::Finished(c) | Ended::Interrupted(c) | Ended::Stopped(c, _) => {
                c.run_cpu_s = run_cpu
            }
        }
        e
    })
}

/// What the service listens to.
struct Subscriptions {
    outcomes: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    failures: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    presence: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    live: zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    work_q: zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<zenoh::query::Query>>,
    ctl_q: zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<zenoh::query::Query>>,
    status_q: zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<zenoh::query::Query>>,
    history_q: zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<zenoh::query::Query>>,
    experiment_q: zenoh::query::Queryable<zenoh::handlers::FifoChannelHandler<zenoh::query::Query>>,
}

#[allow(clippy::too_many_lines)]
async fn serve_loop(
    session: &Session,
    st: &mut State,
    effects: Vec<Fx>,
    replies: &mut tokio::sync::mpsc::UnboundedReceiver<Reply>,
    subs: &Subscriptions,
    shutdown: &mut tokio::sync::watch::Receiver<bool>,
    events: Option<&tokio::sync::mpsc::UnboundedSender<Event>>,
) -> Result<Ended, ServiceError> {
    let id = st.facts.id.clone();
    handle_effects(session, st, effects, events).await?;
    advertise(session, st).await;
    // Leases, silences and the grace after a worker's token goes are
    // seconds long; a tick of 200 ms keeps them, with few wake-ups.
    let mut tick = tokio::time::interval(Duration::from_millis(200));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut ad_tick = tokio::time::interval(ADVERT_EVERY);
    ad_tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        if st.finished {
            advertise(session, st).await;
            publish(session, &st.rkeys.status(), &st.status()).await;
            return Ok(Ended::Finished(st.counters.clone()));
        }
        if let Some(by) = st.stopped.clone() {
            advertise(session, st).await;
            publish(session, &st.rkeys.status(), &st.status()).await;
            return Ok(Ended::Stopped(st.counters.clone(), by));
        }
        if st.advert_due() {
            advertise(session, st).await;
        }
        tokio::select! {
            s = subs.outcomes.recv_async() => {
                let s = s.map_err(zerr)?;
                let bytes = s.payload().to_bytes();
                match TrialOutcome::decode(&bytes) {
                    Err(e) => st.refuse("an undecodable message", &format!("outcome: {e}")),
                    Ok(o) if o.run != id => st.refuse(&o.worker, "outcome for another run"),
                    Ok(o) => on_outcome(st, o)?,
                }
            }
            s = subs.failures.recv_async() => {
                let s = s.map_err(zerr)?;
                match TrialFailure::decode(&s.payload().to_bytes()) {
                    Ok(f) if f.run == id => on_failure(st, &f)?,
                    Ok(f) => st.refuse(&f.worker, "failure report for another run"),
                    Err(e) => st.refuse("an undecodable message", &format!("failure report: {e}")),
                }
            }
            s = subs.presence.recv_async() => {
                let s = s.map_err(zerr)?;
                match WorkerPresence::decode(&s.payload().to_bytes()) {
                    Ok(p) => {
                        let now = Instant::now();
                        st.sched.worker_seen(&p.worker, Some(p.slots), now);
                        st.sched.renew(&p.worker, &p.running, now);
                    }
                    Err(e) => st.refuse("an undecodable message", &format!("presence: {e}")),
                }
            }
            s = subs.live.recv_async() => {
                let s = s.map_err(zerr)?;
                let wid = keys::last_chunk(s.key_expr().as_str()).to_string();
                if s.kind() == SampleKind::Delete {
                    st.live.remove(&wid);
                    st.gone.push((wid, Instant::now()));
                    no_worker_fits(st, false)?;
                } else {
                    st.live.insert(wid);
                }
            }
            q = subs.work_q.recv_async() => {
                let q = q.map_err(zerr)?;
                on_work(st, &q).await?;
            }
            q = subs.ctl_q.recv_async() => {
                let q = q.map_err(zerr)?;
                on_ctl(st, q).await?;
            }
            q = subs.status_q.recv_async() => {
                let q = q.map_err(zerr)?;
                reply_json(&q, st.status().to_json().map_err(|e| e.to_string())).await;
            }
            q = subs.history_q.recv_async() => {
                let q = q.map_err(zerr)?;
                reply_history(&q, &st.history).await;
            }
            q = subs.experiment_q.recv_async() => {
                let q = q.map_err(zerr)?;
                reply_json(&q, serde_json::to_string(&st.facts.experiment).map_err(|e| e.to_string())).await;
            }
            _ = tick.tick() => {
                let now = Instant::now();
                let (due, later): (Vec<_>, Vec<_>) = std::mem::take(&mut st.gone)
                    .into_iter()
                    .partition(|(_, at)| now.saturating_duration_since(*at) >= GONE_GRACE);
                st.gone = later;
                for (wid, _) in due {
                    st.requeue_worker(&wid)?;
                }
                let t = st.sched.tick(now);
                for (trial, worker) in t.expired {
                    if st.facts.pending.contains(&trial) {
                        tracing::info!(iteration = trial.0, trial = trial.1, %worker, "lease expired; the trial is offered again");
                        st.sched.enqueue(trial, now);
                        st.counters.redispatched += 1;
                    }
                }
                for wid in t.silent {
                    // Far past its heartbeat: treat as gone even if its token lingers.
                    st.requeue_worker(&wid)?;
                }
            }
            _ = ad_tick.tick() => advertise(session, st).await,
            Some(r) = replies.recv() => on_reply(session, st, r, events).await?,
            _ = shutdown.changed() => {
                if *shutdown.borrow() {
                    return Ok(Ended::Interrupted(st.counters.clone()));
                }
            }
        }
    }
}

/// How long after a worker's token went its trials go back to the queue: a
/// worker that stops gives back what it holds just before, and those
/// messages may arrive after the token's end.
pub const GONE_GRACE: Duration = Duration::from_millis(500);

/// The shortest interval between two adverts sent because the trials in
/// flight moved (bounds them to 40 a second per run).
const ADVERT_MOVED_EVERY: Duration = Duration::from_millis(25);

/// How often a run repeats its advert (workers forget a run not heard for three of these).
pub const ADVERT_EVERY: Duration = Duration::from_secs(1);

/// Publishes the run's advert (workers choose runs by it).
async fn advertise(session: &Session, st: &mut State) {
    st.counters.adverts += 1;
    let ad = st.advert();
    match ad.encode() {
        Ok(bytes) => {
            if let Err(e) = session.put(st.fkeys.advert(), bytes).await {
                tracing::warn!(error = %e, "advert not published");
            }
        }
        Err(e) => tracing::error!(error = %e, "advert not encoded"),
    }
}

async fn handle_effects(
    session: &Session,
    st: &mut State,
    effects: Vec<Fx>,
    events: Option<&tokio::sync::mpsc::UnboundedSender<Event>>,
) -> Result<(), ServiceError> {
    for e in effects {
        match e {
            Fx::Open(o, ks, named) => {
                for k in ks {
                    st.facts.pending.insert((o.iteration, k));
                    st.sched.enqueue((o.iteration, k), Instant::now());
                }
                let json = serde_json::json!({
                    "run": st.facts.experiment.name,
                    "id": st.facts.id,
                    "iteration": o.iteration,
                    "params": named,
                    "trials": o.seeds.len(),
                    "expert": o.expert,
                });
                put_json(session, &st.rkeys.params(o.iteration), json.to_string()).await;
                st.opened.insert(o.iteration, o);
            }
            Fx::Decided(r) => {
                st.opened.remove(&r.iteration);
                publish(session, &st.rkeys.results(r.iteration), r.as_ref()).await;
                let status = st.status();
                publish(session, &st.rkeys.status(), &status).await;
                st.history.push((*r).clone());
                if let Some(tx) = events {
                    let _ = tx.send(Event::Decided(r, Box::new(status)));
                }
            }
            Fx::Finished => st.finished = true,
        }
    }
    Ok(())
}
