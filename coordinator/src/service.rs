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
        }
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
                    Ok(p) => st.sched.worker_seen(&p.worker, Some(p.slots), Instant::now()),
                    Err(e) => st.refuse("an undecodable message", &format!("presence: {e}")),
                }
            }
            s = subs.live.recv_async() => {
                let s = s.map_err(zerr)?;
                let wid = keys::last_chunk(s.key_expr().as_str()).to_string();
                if s.kind() == SampleKind::Delete {
                    st.live.remove(&wid);
                    st.gone.push((wid, Instant::now()));
                    no_worker_fits(st)?;
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
                reply_json(&q, serde_json::to_string(&st.history).map_err(|e| e.to_string())).await;
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

/// A worker reported a trial it could not (or would not) run.
fn on_failure(st: &mut State, f: &TrialFailure) -> Result<(), ServiceError> {
    let t = (f.iteration, f.trial);
    match st.sched.answered(t, &f.worker, f.dispatch, Instant::now()) {
        Answer::Held if f.refused => {
            // Beyond its limits, or it is stopping: not the trial's failure.
            tracing::info!(worker = %f.worker, iteration = f.iteration, trial = f.trial, reason = %f.reason, "a worker gave a trial back");
            st.counters.redispatched += 1;
            st.sched.enqueue(t, Instant::now());
        }
        Answer::Held => {
            tracing::warn!(worker = %f.worker, iteration = f.iteration, trial = f.trial, reason = %f.reason, "a worker could not run a trial");
            st.failed(t, &f.worker, &f.reason)?;
        }
        other => st.refuse(&f.worker, &format!("failure report: {}", other.reason())),
    }
    Ok(())
}

/// Whether `req`'s worker may run this run's trials: the run's fingerprint
/// is pinned by the first worker that asks (journaled before any of its
/// outcomes), and from then on only workers of that fingerprint get trials.
/// A resumed run that meets only workers of other fingerprints ends.
fn fingerprint_fits(st: &mut State, req: &WorkRequest) -> Result<Option<String>, ServiceError> {
    let ours = match st.facts.fingerprint {
        Some(f) => f,
        None => {
            st.facts.fingerprint = Some(req.fingerprint);
            tracing::info!(worker = %req.worker, fingerprint = %show_fingerprint(req.fingerprint), version = %req.version, "the run's worker fingerprint is pinned");
            st.send(Cmd::Fingerprint {
                fingerprint: req.fingerprint,
                version: req.version.clone(),
                worker: req.worker.clone(),
            })?;
            req.fingerprint
        }
    };
    if req.fingerprint == ours {
        st.matched = true;
        return Ok(None);
    }
    let why = format!(
        "fingerprint: this run's trials are run by workers of fingerprint {}; this worker's is {} (naofarm {}): its bits might differ",
        show_fingerprint(ours),
        show_fingerprint(req.fingerprint),
        req.version
    );
    st.refuse(&req.worker, "work request of another worker fingerprint");
    if st
        .mismatched
        .insert(req.worker.clone(), req.fingerprint)
        .is_none()
    {
        tracing::warn!(worker = %req.worker, "{why}");
    }
    no_worker_fits(st)?;
    Ok(Some(why))
}

/// A resumed run whose every live worker asked with another fingerprint
/// than the journaled one (and none with it) ends at once: its history
/// could not go on with the same bits.
fn no_worker_fits(st: &State) -> Result<(), ServiceError> {
    let Some(ours) = st.facts.fingerprint else {
        return Ok(());
    };
    if st.journaled_fingerprint
        && !st.matched
        && !st.mismatched.is_empty()
        && st.live.iter().all(|w| st.mismatched.contains_key(w))
    {
        let theirs = st
            .mismatched
            .iter()
            .map(|(w, f)| format!("{} on worker {w}", show_fingerprint(*f)))
            .collect::<Vec<_>>()
            .join(", ");
        return Err(ServiceError::NoMatchingWorker {
            id: st.facts.id.clone(),
            ours: show_fingerprint(ours),
            theirs,
        });
    }
    Ok(())
}

/// A worker asks for trials: grant up to its free slots, in one reply that only it receives.
async fn on_work(st: &mut State, q: &zenoh::query::Query) -> Result<(), ServiceError> {
    st.counters.work_requests += 1;
    let Some(payload) = q.payload() else {
        st.refuse("a query without payload", "work request: empty");
        reply_err(q, "a work request needs a WorkRequest payload").await;
        return Ok(());
    };
    let req = match WorkRequest::decode(&payload.to_bytes()) {
        Ok(r) => r,
        Err(e) => {
            st.refuse("an undecodable message", &format!("work request: {e}"));
            reply_err(q, &e.to_string()).await;
            return Ok(());
        }
    };
    let state = st.state();
    let mut note = None;
    let mut trials = Vec::new();
    let misfit = if state == RunState::Running {
        fingerprint_fits(st, &req)?
    } else {
        None
    };
    let exp = &st.facts.experiment;
    let refused = misfit.is_some();
    if let Some(why) = misfit {
        note = Some(why);
    } else if state != RunState::Running {
        note = Some(format!("the run is {state:?}").to_lowercase());
    } else if exp.trial_duration_s > req.max_duration_s {
        note = Some(format!(
            "this run's trials last {} s, beyond the worker's limit of {} s",
            exp.trial_duration_s, req.max_duration_s
        ));
        st.sched
            .worker_seen(&req.worker, Some(req.slots), Instant::now());
    } else {
        let failed = &st.facts.failed;
        let mut rng = rand::rng();
        let taken = st.sched.take(
            &req.worker,
            req.slots,
            req.want,
            Instant::now(),
            &|t| failed.get(&t).cloned().unwrap_or_default(),
            &mut || rand::Rng::random::<u64>(&mut rng),
        );
        for (t, dispatch_id) in taken {
            let built = st
                .opened
                .get(&t.0)
                .ok_or_else(|| "its iteration is not open".to_string())
                .and_then(|o| {
                    crate::run::request(&st.facts.experiment, &st.facts.id, o, t.1, dispatch_id)
                        .map_err(|e| e.to_string())
                });
            match built {
                Ok(r) => {
                    st.dispatch += 1;
                    trials.push(r);
                }
                Err(e) => {
                    tracing::error!(iteration = t.0, trial = t.1, error = %e, "a queued trial has no request; dropped");
                    st.sched.forget(t);
                }
            }
        }
    }
    for d in st.sched.drain_latencies() {
        if st.counters.dispatch_ms.len() < 100_000 {
            #[allow(clippy::cast_possible_truncation)]
            st.counters
                .dispatch_ms
                .push((d.as_secs_f64() * 1000.0) as f32);
        }
    }
    if trials.is_empty() {
        st.counters.empty_grants += 1;
    }
    if !refused && (trials.len() < req.want as usize || st.sched.ready() == 0) {
        // The worker now believes nothing is ready here: tell it when
        // something is. Not for a worker of another fingerprint: nothing
        // changed here, and an advert would only bring its next request
        // (a worker of an older build asks again after every advert).
        st.advert.2 = true;
    }
    let grant = WorkGrant {
        trials,
        ready: u32::try_from(st.sched.ready()).unwrap_or(u32::MAX),
        running: u32::try_from(st.sched.in_flight()).unwrap_or(u32::MAX),
        seq: st.advert.0,
        state,
        note,
    };
    match grant.encode() {
        Ok(bytes) => {
            if let Err(e) = q.reply(q.key_expr().clone(), bytes).await {
                // The worker does not get them: their leases bring them back.
                tracing::warn!(worker = %req.worker, error = %e, "a work grant was not sent");
            }
        }
        Err(e) => tracing::error!(error = %e, "a work grant cannot be encoded"),
    }
    Ok(())
}

/// `naofarm ctl`: pause, resume, stop, priority; the run's thread journals
/// it, and the query is answered with the status once it has.
async fn on_ctl(st: &mut State, q: zenoh::query::Query) -> Result<(), ServiceError> {
    let Some(payload) = q.payload() else {
        reply_err(&q, "a control request needs a ControlRequest payload").await;
        return Ok(());
    };
    let req = match ControlRequest::decode(&payload.to_bytes()) {
        Ok(r) => r,
        Err(e) => {
            st.refuse("an undecodable message", &format!("control: {e}"));
            reply_err(&q, &e.to_string()).await;
            return Ok(());
        }
    };
    let tag = st.tag();
    st.ctl_waiting.insert(tag, q);
    st.send(Cmd::Control {
        action: req.action,
        by: req.by,
        tag,
    })
}

/// The run's thread answered.
async fn on_reply(
    session: &Session,
    st: &mut State,
    reply: Reply,
    events: Option<&tokio::sync::mpsc::UnboundedSender<Event>>,
) -> Result<(), ServiceError> {
    match reply {
        Reply::Applied {
            outcome: o,
            counted,
            effects,
            snapshot,
            took_s,
        } => {
            if let Some(snapshot) = snapshot {
                st.snap = *snapshot;
            }
            st.counters.decide_s += took_s;
            match counted {
                Counted::New => {
                    publish(session, &st.rkeys.trial(o.iteration, o.trial), o.as_ref()).await;
                }
                Counted::Duplicate => {
                    st.counters.duplicates += 1;
                    st.counters.accepted = st.counters.accepted.saturating_sub(1);
                }
            }
            handle_effects(session, st, effects, events).await?;
        }
        Reply::Failed {
            iteration,
            trial,
            verdict,
        } => match verdict {
            FailureVerdict::Retry => {}
            FailureVerdict::Ignored => {
                if !st.facts.pending.contains(&(iteration, trial)) {
                    st.sched.forget((iteration, trial));
                }
            }
            FailureVerdict::GiveUp(g) => return Err(ServiceError::GaveUp(g)),
        },
        Reply::Controlled {
            tag,
            action,
            by,
            result,
            snapshot,
        } => {
            st.snap = *snapshot;
            let q = st.ctl_waiting.remove(&tag);
            match result {
                Ok(()) => {
                    tracing::info!(?action, %by, "control");
                    if action == Control::Stop {
                        st.stopped = Some(by);
                    }
                    if let Some(q) = q {
                        reply_json(&q, st.status().to_json().map_err(|e| e.to_string())).await;
                    }
                }
                Err(why) => {
                    if let Some(q) = q {
                        reply_err(&q, &why).await;
                    }
                }
            }
        }
        Reply::Fatal(e) => return Err(e.into()),
    }
    Ok(())
}

async fn reply_err(q: &zenoh::query::Query, why: &str) {
    if let Err(e) = q.reply_err(why.to_string()).await {
        tracing::warn!(error = %e, "an error reply failed");
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

fn on_outcome(st: &mut State, o: TrialOutcome) -> Result<(), ServiceError> {
    let t = (o.iteration, o.trial);
    if st.facts.fingerprint.is_some_and(|f| f != o.fingerprint) {
        // Never journaled: the run's bits come from workers of one fingerprint.
        st.refuse(&o.worker, "outcome of another worker fingerprint");
        if st.sched.holder(t) == Some(o.worker.as_str()) {
            st.failed(t, &o.worker, "answered with another worker fingerprint")?;
        }
        return Ok(());
    }
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
    let duration = st.facts.experiment.trial_duration_s;
    if let Err(why) = plausible(&o, duration) {
        tracing::warn!(worker = %o.worker, iteration = o.iteration, trial = o.trial, %why, "an implausible outcome counts as a failure");
        st.failed(t, &o.worker, &format!("implausible outcome: {why}"))?;
        return Ok(());
    }
    let checked = st
        .opened
        .get(&t.0)
        .filter(|_| st.facts.pending.contains(&t))
        .ok_or_else(|| "trial not open".to_string())
        .and_then(|opened| decider::check(opened, o.trial, o.seed, &o.measurement()));
    if let Err(why) = checked {
        // Its worker answered the dispatch with something the run would refuse.
        st.refuse(&o.worker, &why);
        st.failed(t, &o.worker, &format!("refused outcome: {why}"))?;
        return Ok(());
    }
    st.facts.pending.remove(&t);
    st.sched.forget(t);
    st.ran_elsewhere(t, &o.worker);
    st.counters.accepted += 1;
    st.trials_done += 1;
    st.send(Cmd::Outcome(Box::new(o)))
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

/// CPU time (user + system) this process has used, from `/proc/self/stat`
/// (Linux; clock ticks of 1/100 s, the kernel's USER_HZ). `None` elsewhere.
#[must_use]
pub fn process_cpu_seconds() -> Option<f64> {
    cpu_seconds_of("/proc/self/stat")
}

/// CPU time (user + system) from a `stat` file of proc(5) (a process's or a thread's).
#[must_use]
pub fn cpu_seconds_of(path: &str) -> Option<f64> {
    let stat = std::fs::read_to_string(path).ok()?;
    // Fields after the command name (which may hold spaces) closed by ')'.
    let rest = stat.rsplit_once(')')?.1;
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of stat(5); `rest` starts at field 3.
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}
