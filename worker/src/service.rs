//! The stateless worker service: it asks the runs it hears of for trials
//! (never more than its free slots), runs them on OS threads (never on the
//! async runtime), and puts each outcome on its run's key. It keeps nothing
//! between trials.
//!
//! Which run gets a free slot is [`crate::share`]'s choice (fair shares by
//! priority). The event loop never waits for a trial or a slot: requests,
//! grants, finished trials, heartbeats and the shutdown signal are all events.
//! A granted trial beyond the worker's limits (duration, physics, model) is
//! given back at once with the reason. While it runs a trial it names the
//! trial's dispatch in its heartbeat to the run, which renews the trial's
//! lease; a trial granted again while it runs is not started twice (its
//! answer carries the newest dispatch). On shutdown the worker stops
//! asking, asks its programs to stop (SIGTERM, then SIGKILL after the
//! grace), gives back every trial it holds (the coordinators offer them to
//! other workers at once, without waiting for a lease), removes its scratch
//! space, drops its liveliness token and returns; threads still computing
//! NAO trials are abandoned with the process.

use std::{
    collections::{BTreeMap, BTreeSet},
    sync::Arc,
    time::{Duration, Instant},
};

use protocol::{
    keys::{self, FleetKeys},
    wire::{
        show_fingerprint, RunAdvert, TrialFailure, TrialOutcome, TrialRequest, WireMessage,
        WorkGrant, WorkRequest, WorkerPresence, WorkerStatus,
    },
    TrialModel,
};
use zenoh::Session;

use crate::share::Share;

/// How often a worker publishes its [`WorkerStatus`] for watchers.
pub const STATUS_EVERY: Duration = Duration::from_secs(1);

/// Settings of a worker.
#[derive(Debug, Clone)]
pub struct WorkerConfig {
    /// Key prefix (default `naofarm`).
    pub prefix: String,
    /// Trials run at once.
    pub slots: u32,
    /// Interval of the heartbeat to each run it holds trials of.
    pub heartbeat: Duration,
    /// Minimum wall time of one trial (paces cheap models to benchmark or test the farm).
    pub min_trial: Duration,
    /// Longest trial accepted, simulated seconds.
    pub max_duration_s: f64,
    /// Most physics steps per 20 ms cycle accepted.
    pub max_substeps: u32,
    /// Trial models served.
    pub models: Vec<TrialModel>,
    /// Trial programs served, by the name experiments use.
    pub programs: crate::program::Programs,
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
            max_duration_s: 3600.0,
            max_substeps: 50,
            models: vec![TrialModel::Nao, TrialModel::Synthetic],
            programs: crate::program::Programs::default(),
        }
    }
}

impl WorkerConfig {
    /// Why this worker will not run `req`, if it will not.
    #[must_use]
    pub fn beyond_limits(&self, req: &TrialRequest) -> Option<String> {
        if req.duration_s > self.max_duration_s {
            return Some(format!(
                "a trial of {} s is beyond this worker's limit of {} s",
                req.duration_s, self.max_duration_s
            ));
        }
        let most = req.physics.substeps;
        if most > self.max_substeps {
            return Some(format!(
                "{most} physics substeps are beyond this worker's limit of {}",
                self.max_substeps
            ));
        }
        if let Some(p) = &req.program {
            if self.programs.get(p).is_none() {
                return Some(format!(
                    "this worker has not registered a program named `{p}`"
                ));
            }
            return None;
        }
        if !self.models.contains(&req.model) {
            return Some(
                format!("this worker does not serve the {:?} model", req.model).to_lowercase(),
            );
        }
        None
    }
}

/// Worker failures.
#[derive(Debug, thiserror::Error)]
pub enum WorkerError {
    /// Zenoh failed.
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// The fingerprint's probe trials could not run.
    #[error("the fingerprint's probe: {0}")]
    Probe(String),
    /// The programs' scratch space could not be made.
    #[error("the programs' scratch space: {0}")]
    Scratch(String),
}

fn zerr(e: impl std::fmt::Display) -> WorkerError {
    WorkerError::Zenoh(e.to_string())
}

/// What a worker did before it stopped.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct WorkerSummary {
    /// Trials run and reported.
    pub trials: u64,
    /// Trials that failed (reported as failures) or were given back (limits, shutdown).
    pub refused: u64,
    /// The most trials it held at once.
    pub most_held: u32,
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

/// Publishes this worker's status for watchers (JSON); one that cannot be
/// encoded or sent is logged.
async fn put_status(session: &Session, key: &str, st: &WorkerStatus) {
    match st.to_json() {
        Ok(text) => {
            let put = session
                .put(key, text)
                .encoding(zenoh::bytes::Encoding::APPLICATION_JSON);
            if let Err(e) = put.await {
                tracing::warn!(key, error = %e, "publishing the status failed");
            }
        }
        Err(e) => tracing::error!(key, error = %e, "status not published"),
    }
}

/// This machine's host name, as watchers see it.
fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| std::fs::read_to_string("/etc/hostname"))
        .map(|h| {
            h.trim()
                .chars()
                .filter(|c| !c.is_control())
                .take(253)
                .collect::<String>()
        })
        .ok()
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "unknown".into())
}

/// The text of a panic's payload.
fn panic_text(p: Box<dyn std::any::Any + Send>) -> String {
    p.downcast_ref::<&str>()
        .map(|s| (*s).to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "(no message)".into())
}

/// A trial's key in the worker: (run id, iteration, trial).
type Held = (String, u64, u32);

/// Tells `req`'s run that this worker failed it (`refused`: gave it back,
/// not the trial's fault), with why.
async fn give_back(
    session: &Session,
    prefix: &str,
    worker: &str,
    req: &TrialRequest,
    reason: &str,
    refused: bool,
) {
    let f = TrialFailure {
        run: req.run.clone(),
        iteration: req.iteration,
        trial: req.trial,
        seed: req.seed,
        dispatch: req.dispatch,
        worker: worker.to_string(),
        reason: protocol::wire::fit_reason(reason),
        refused,
    };
    put_message(session, &FleetKeys::new(prefix, &req.run).failures(), &f).await;
}

/// `program` as it is on disk now: registered anew when its file changed
/// (its new build replaces it in `programs`), with why the trial in hand
/// goes back then.
async fn fresh(
    programs: &mut crate::program::Programs,
    program: &crate::program::Program,
    fingerprint: u64,
) -> Result<crate::program::Program, String> {
    match program.refreshed().await {
        None => Ok(program.clone()),
        Some(Ok(new)) => {
            let why = format!(
                "program `{}` changed on disk since this worker registered it: this worker now serves its new build (fingerprint {}), and a run takes one build only",
                new.name,
                show_fingerprint(new.fingerprint(fingerprint))
            );
            programs.by_name.insert(new.name.clone(), new);
            Err(why)
        }
        Some(Err(e)) => Err(format!(
            "program `{}` is no longer runnable: {e}",
            program.name
        )),
    }
}

/// Runs one trial on a blocking thread: its measurement, or why it failed.
async fn run_one(
    req: TrialRequest,
    min_trial: Duration,
) -> (Result<crate::Measurement, String>, f64) {
    let started = Instant::now();
    let r = tokio::task::spawn_blocking(move || {
        let out = crate::fault::run_trial(&req);
        let rest = min_trial.saturating_sub(started.elapsed());
        if !rest.is_zero() {
            std::thread::sleep(rest);
        }
        out
    })
    .await;
    let result = match r {
        Ok(Ok(t)) => t.check().map(|()| t),
        Ok(Err(e)) => Err(e.to_string()),
        Err(e) if e.is_panic() => Err(format!("panic: {}", panic_text(e.into_panic()))),
        Err(e) => Err(format!("the trial's thread ended: {e}")),
    };
    (result, started.elapsed().as_secs_f64())
}

/// Runs one trial of a registered program in a slot of the host's: its
/// measurement, or why it failed.
async fn run_program(
    program: crate::program::Program,
    req: TrialRequest,
    run_dir: std::path::PathBuf,
    settings: crate::program::Settings,
    stop: tokio_util::sync::CancellationToken,
    pool: Arc<crate::served::Pool>,
) -> (Result<crate::Measurement, String>, f64) {
    let started = Instant::now();
    // The slots this worker keeps the run's program in, first: another
    // slot would start another process and leave those idle.
    let kept = pool.kept_slots(&req.run, &program.name);
    let r = match crate::job::Slot::claim_preferring(&kept) {
        Ok(slot) => {
            let dir = run_dir.join(format!("slot-{}", slot.n));
            let r =
                crate::program::run(&program, &req, slot.n, &dir, &settings, &stop, &pool).await;
            // The slot's scratch is kept for the run's next trial in it.
            drop(slot);
            r
        }
        Err(e) => Err(format!("no slot for program `{}`: {e}", program.name)),
    };
    (r, started.elapsed().as_secs_f64())
}

/// A grant as this worker reads it.
struct Grant {
    /// The grant, with the trials it can read.
    grant: WorkGrant,
    /// Trials of the grant that fail their checks (a build with another
    /// parameter registry sent them), each with why: given back at once.
    unreadable: Vec<(TrialRequest, String)>,
}

/// Reads a grant's bytes: a grant whose only fault is trials that fail their
/// checks keeps the rest, and names those to give back.
fn read_grant(bytes: &[u8]) -> Result<Grant, protocol::DecodeError> {
    let e = match WorkGrant::decode(bytes) {
        Ok(grant) => {
            return Ok(Grant {
                grant,
                unreadable: Vec::new(),
            })
        }
        Err(e @ protocol::DecodeError::Field { .. }) => e,
        Err(e) => return Err(e),
    };
    let mut grant = WorkGrant::decode_unchecked(bytes)?;
    let mut unreadable = Vec::new();
    for t in std::mem::take(&mut grant.trials) {
        match t.validate() {
            Ok(()) => grant.trials.push(t),
            Err((field, problem)) => {
                unreadable.push((t, format!("cannot read the trial: `{field}`: {problem}")));
            }
        }
    }
    if grant.validate().is_err() {
        return Err(e);
    }
    Ok(Grant { grant, unreadable })
}

/// Asks run `run` for `want` trials; the grant, or why there is none.
async fn ask(session: Session, work_key: String, req: WorkRequest) -> Result<Grant, String> {
    let bytes = req.encode().map_err(|e| e.to_string())?;
    let replies = session
        .get(work_key)
        .payload(bytes)
        .timeout(Duration::from_secs(2))
        .await
        .map_err(|e| e.to_string())?;
    match replies.recv_async().await {
        Ok(reply) => match reply.result() {
            Ok(sample) => {
                let bytes = crate::fault::grant_bytes(sample.payload().to_bytes().into_owned());
                read_grant(&bytes).map_err(|e| {
                    // Not a quiet "no grant": the run has leased trials to
                    // this worker that it cannot name to give back, and they
                    // wait out their lease.
                    tracing::warn!(key = %sample.key_expr(), error = %e,
                        "a grant this worker cannot read: its trials go back to the run when their lease ends");
                    e.to_string()
                })
            }
            Err(e) => Err(format!(
                "the run refused: {}",
                String::from_utf8_lossy(&e.payload().to_bytes())
            )),
        },
        Err(_) => Err("no answer".into()),
    }
}

enum Done {
    /// A grant (or its failure) for (run, asked).
    Grant(String, u32, Result<Grant, String>),
    /// A trial ended: (run, iteration, trial), what it gave, its wall time.
    Trial(Held, Result<crate::Measurement, String>, f64),
}

/// Serves trials until `shutdown` turns true, then gives back what it holds,
/// drops its liveliness token and returns.
pub async fn serve(
    session: Session,
    cfg: WorkerConfig,
    mut shutdown: tokio::sync::watch::Receiver<bool>,
) -> Result<WorkerSummary, WorkerError> {
    let uuid = uuid::Uuid::new_v4();
    let id = uuid.to_string();
    let prefix = cfg.prefix.clone();
    // The probe trials run before the worker says it exists.
    let fingerprint = tokio::task::spawn_blocking(crate::fingerprint::of_this_worker)
        .await
        .map_err(|e| WorkerError::Probe(e.to_string()))?;
    let adverts = session
        .declare_subscriber(keys::adverts_all(&prefix))
        .await
        .map_err(zerr)?;
    let token = session
        .liveliness()
        .declare_token(keys::worker(&prefix, &id))
        .await
        .map_err(zerr)?;
    // The trial programs' scratch space: this worker's own, removed when it
    // stops (or by the next worker on this host, if this one is killed); a
    // worker without programs makes none, and only sweeps dead ones'.
    let scratch = if cfg.programs.by_name.is_empty() {
        crate::job::Scratch::sweep(&std::env::temp_dir(), "worker");
        None
    } else {
        Some(
            crate::job::Scratch::create("worker", &id)
                .map_err(|e| WorkerError::Scratch(e.to_string()))?,
        )
    };
    let containment = if cfg.programs.by_name.is_empty() {
        String::new()
    } else {
        crate::job::Host::get().describe()
    };
    tracing::info!(worker = %id, slots = cfg.slots, fingerprint = %protocol::wire::show_fingerprint(fingerprint), "worker ready");
    if !containment.is_empty() {
        tracing::info!(worker = %id, containment, "trial programs run as jobs");
        if !crate::job::Host::get().contains_daemons() {
            tracing::warn!("neither a cgroup nor a PID namespace is available here: a process a program detaches (setsid) outlives its trial if this worker is killed");
        }
    }
    let mut programs = cfg.programs.clone();
    let stop_programs = tokio_util::sync::CancellationToken::new();
    let mut share = Share::new(uuid.as_u64_pair().0);
    let mut held: BTreeMap<Held, TrialRequest> = BTreeMap::new();
    let mut asking: u32 = 0;
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<Done>();
    let mut summary = WorkerSummary::default();
    let mut beat = tokio::time::interval(cfg.heartbeat);
    beat.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let mut tell = tokio::time::interval(STATUS_EVERY);
    tell.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let status_key = keys::worker_status(&prefix, &id);
    // Each run's program (from its adverts), and the task of each program trial.
    let mut run_program_of: BTreeMap<String, String> = BTreeMap::new();
    let mut program_tasks: BTreeMap<Held, tokio::task::JoinHandle<()>> = BTreeMap::new();
    // Programs that serve, kept running between their run's trials.
    let kept = Arc::new(crate::served::Pool::default());
    // The fingerprint this worker asks and answers `run` with.
    let fingerprint_for = |programs: &crate::program::Programs, program: Option<&String>| {
        program
            .and_then(|p| programs.get(p))
            .map_or(fingerprint, |p| p.fingerprint(fingerprint))
    };
    let host = host_name();
    let version = env!("CARGO_PKG_VERSION").to_string();
    loop {
        tokio::select! {
            s = adverts.recv_async() => {
                let Ok(s) = s else { break };
                match RunAdvert::decode(&s.payload().to_bytes()) {
                    Ok(ad) => {
                        share.advert(&ad, tokio::time::Instant::now());
                        if let Some(p) = &ad.program {
                            if programs.get(p).is_none() {
                                let why = format!("this worker has not registered a program named `{p}`");
                                if share.unservable(&ad.id, &why) {
                                    tracing::info!(run = %ad.id, %why, "this worker will not serve the run");
                                }
                            }
                            run_program_of.insert(ad.id.clone(), p.clone());
                        }
                    }
                    Err(e) => tracing::debug!(error = %e, "ignored an advert"),
                }
            }
            Some(done) = rx.recv() => match done {
                Done::Grant(run, asked, grant) => {
                    asking -= asked;
                    let (trials, unreadable, ready) = match grant {
                        Ok(Grant { grant: g, unreadable }) => {
                            match &g.note {
                                // The run's fingerprint is journaled and this
                                // worker's fixed: it is never asked again.
                                Some(note) if note.starts_with("fingerprint") && share.unservable(&run, note) => {
                                    tracing::warn!(run, note, "this worker will not serve the run");
                                }
                                Some(note) if note.starts_with("fingerprint") => {}
                                Some(note) => tracing::debug!(run, note, "short grant"),
                                None => {}
                            }
                            (g.trials, unreadable, Some((g.ready, g.running, g.seq)))
                        }
                        Err(e) => {
                            tracing::debug!(run, error = %e, "no grant");
                            (Vec::new(), Vec::new(), None)
                        }
                    };
                    let got = u32::try_from(trials.len() + unreadable.len()).unwrap_or(u32::MAX);
                    share.granted(&run, asked, got, ready);
                    // Trials this build cannot read (another parameter
                    // registry) come first, each with why: like a trial
                    // beyond this worker's limits, each is given back at
                    // once, refused with the reason, so that the run offers
                    // it to other workers instead of waiting out its lease.
                    let unreadable = unreadable.into_iter().map(|(req, why)| (req, Some(why)));
                    for (req, unread) in unreadable.chain(trials.into_iter().map(|req| (req, None))) {
                        if req.run != run {
                            tracing::warn!(run, other = %req.run, "a grant held another run's trial; ignored");
                            share.done(&run, None);
                            continue;
                        }
                        if let Some(why) = &unread {
                            tracing::warn!(run, iteration = req.iteration, trial = req.trial, %why, "giving back a trial this worker cannot read");
                        }
                        if let Some(why) = unread.or_else(|| cfg.beyond_limits(&req)) {
                            if share.unservable(&run, &why) {
                                tracing::warn!(run, %why, "this worker will not serve the run");
                            }
                            share.done(&run, None);
                            summary.refused += 1;
                            give_back(&session, &prefix, &id, &req, &why, true).await;
                            continue;
                        }
                        let key = (req.run.clone(), req.iteration, req.trial);
                        if let Some(running) = held.get_mut(&key) {
                            // Granted again while it runs here (its lease
                            // passed while this worker was not heard): not
                            // run twice; its answer carries the newest dispatch.
                            tracing::info!(run, iteration = req.iteration, trial = req.trial, "a trial running here was granted again");
                            running.dispatch = req.dispatch;
                            share.done(&run, None);
                            continue;
                        }
                        let program = match req.program.as_ref().and_then(|p| programs.get(p)).cloned() {
                            Some(p) => match fresh(&mut programs, &p, fingerprint).await {
                                Ok(p) => Some(p),
                                Err(why) => {
                                    tracing::warn!(run, %why, "giving the trial back");
                                    share.done(&run, None);
                                    summary.refused += 1;
                                    give_back(&session, &prefix, &id, &req, &why, true).await;
                                    continue;
                                }
                            },
                            None => None,
                        };
                        tracing::debug!(run, iteration = req.iteration, trial = req.trial, "trial started");
                        held.insert(key.clone(), req.clone());
                        let tx = tx.clone();
                        let min_trial = cfg.min_trial;
                        if let (Some(program), Some(scratch)) = (program, &scratch) {
                            let run_dir = scratch.path().join(&req.run);
                            let settings = programs.settings.clone();
                            let stop = stop_programs.clone();
                            let k = key.clone();
                            let pool = kept.clone();
                            let task = tokio::spawn(async move {
                                let (r, wall) = run_program(program, req, run_dir, settings, stop, pool).await;
                                let _ = tx.send(Done::Trial(k, r, wall));
                            });
                            program_tasks.insert(key, task);
                            continue;
                        }
                        tokio::spawn(async move {
                            let (r, wall) = run_one(req, min_trial).await;
                            let _ = tx.send(Done::Trial(key, r, wall));
                        });
                    }
                    summary.most_held = summary.most_held.max(u32::try_from(held.len()).unwrap_or(u32::MAX));
                }
                Done::Trial(key, result, wall) => {
                    program_tasks.remove(&key);
                    let Some(req) = held.remove(&key) else {
                        continue; // given back already (shutdown)
                    };
                    share.done(&req.run, Some(wall));
                    let fkeys = FleetKeys::new(&prefix, &req.run);
                    match result {
                        Ok(m) => {
                            let fp = fingerprint_for(&programs, req.program.as_ref());
                            let mut o = TrialOutcome::answer(&req, id.clone(), fp, m, wall);
                            crate::fault::tamper(&mut o);
                            put_message(&session, &fkeys.outcomes(), &o).await;
                            summary.trials += 1;
                        }
                        Err(reason) => {
                            tracing::error!(%reason, iteration = req.iteration, trial = req.trial, "trial could not run; reporting it");
                            give_back(&session, &prefix, &id, &req, &reason, false).await;
                            summary.refused += 1;
                        }
                    }
                }
            },
            _ = beat.tick() => {
                share.expire(tokio::time::Instant::now());
                // Every run this worker runs trials of hears which, by
                // dispatch id: their leases follow the work.
                let runs: BTreeSet<&String> = held.keys().map(|(r, _, _)| r).collect();
                for run in runs {
                    let running: Vec<u64> = held
                        .iter()
                        .filter(|((r, _, _), _)| r == run)
                        .map(|(_, req)| req.dispatch)
                        .take(cfg.slots as usize)
                        .collect();
                    let p = WorkerPresence {
                        worker: id.clone(),
                        slots: cfg.slots,
                        busy: u32::try_from(held.len()).unwrap_or(u32::MAX).min(cfg.slots),
                        version: version.clone(),
                        running,
                    };
                    put_message(&session, &FleetKeys::new(&prefix, run).presence(), &p).await;
                }
                // A run that ended (no longer advertised) leaves no scratch here.
                let ended: Vec<String> = run_program_of
                    .keys()
                    .filter(|r| !share.knows(r) && !held.keys().any(|(h, _, _)| h == *r))
                    .cloned()
                    .collect();
                for r in ended {
                    run_program_of.remove(&r);
                    kept.end_run(&r).await;
                    let Some(dir) = scratch.as_ref().map(|s| s.path().join(&r)) else {
                        continue;
                    };
                    if let Err(e) = std::fs::remove_dir_all(&dir) {
                        if e.kind() != std::io::ErrorKind::NotFound {
                            tracing::warn!(dir = %dir.display(), error = %e, "a run's scratch space was not removed");
                        }
                    }
                }
            }
            _ = tell.tick() => {
                let mut runs: BTreeMap<String, u32> = BTreeMap::new();
                for (r, _, _) in held.keys() {
                    *runs.entry(r.clone()).or_default() += 1;
                }
                let st = WorkerStatus {
                    worker: id.clone(),
                    host: host.clone(),
                    slots: cfg.slots,
                    busy: u32::try_from(held.len()).unwrap_or(u32::MAX).min(cfg.slots),
                    fingerprint: show_fingerprint(fingerprint),
                    version: version.clone(),
                    runs: runs.into_iter().collect(),
                    trials: summary.trials,
                    refused: summary.refused,
                    programs: programs.by_name.keys().cloned().collect(),
                    containment: containment.clone(),
                };
                put_status(&session, &status_key, &st).await;
            }
            _ = shutdown.changed() => {
                if *shutdown.borrow() {
                    break;
                }
            }
        }
        // Fill free slots: never more than free, one request per run at a time.
        let busy = u32::try_from(held.len()).unwrap_or(u32::MAX);
        let free = cfg.slots.saturating_sub(busy + asking);
        if free > 0 {
            for (run, want) in share.pick(free, cfg.max_duration_s) {
                asking += want;
                let program = run_program_of
                    .get(&run)
                    .filter(|p| programs.get(p).is_some());
                let req = WorkRequest {
                    worker: id.clone(),
                    want,
                    slots: cfg.slots,
                    busy,
                    max_duration_s: cfg.max_duration_s,
                    version: version.clone(),
                    fingerprint: fingerprint_for(&programs, program),
                    program: program.cloned(),
                };
                let key = FleetKeys::new(&prefix, &run).work();
                let session = session.clone();
                let tx = tx.clone();
                tokio::spawn(async move {
                    let g = ask(session, key, req).await;
                    let _ = tx.send(Done::Grant(run, want, g));
                });
            }
        }
    }
    // Stop asking; ask the programs to stop (SIGTERM, SIGKILL after the
    // grace); give back what we hold, so it is run elsewhere at once (grants
    // still on their way included: each ask times out within 2 s).
    drop(adverts);
    stop_programs.cancel();
    let late = tokio::time::Instant::now() + Duration::from_secs(3);
    while asking > 0 {
        match tokio::time::timeout_at(late, rx.recv()).await {
            Ok(Some(Done::Grant(_, asked, grant))) => {
                asking -= asked;
                if let Ok(g) = grant {
                    let unreadable = g.unreadable.into_iter().map(|(req, _)| req);
                    for req in g.grant.trials.into_iter().chain(unreadable) {
                        held.insert((req.run.clone(), req.iteration, req.trial), req);
                    }
                }
            }
            Ok(Some(Done::Trial(..))) => {}
            Ok(None) | Err(_) => break,
        }
    }
    for req in std::mem::take(&mut held).into_values() {
        summary.refused += 1;
        give_back(&session, &prefix, &id, &req, "the worker is stopping", true).await;
    }
    if let Err(e) = token.undeclare().await {
        tracing::warn!(error = %e, "undeclaring the liveliness token failed");
    }
    // Programs asked to stop end within their grace (then they are killed
    // whole), before their scratch space goes.
    let bound = programs.settings.grace + Duration::from_secs(5);
    for (_, task) in std::mem::take(&mut program_tasks) {
        if tokio::time::timeout(bound, task).await.is_err() {
            tracing::warn!("a program trial did not end within its grace");
        }
    }
    kept.stop_all(programs.settings.grace).await;
    // Only this worker ever wrote there (its id is in the name).
    drop(scratch);
    tracing::info!(worker = %id, trials = summary.trials, "worker stopped");
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::{wire::RunState, Physics};

    fn trial(k: u32, params: Vec<(String, f64)>) -> TrialRequest {
        TrialRequest {
            run: "r".into(),
            iteration: 2,
            trial: k,
            seed: 7,
            model: TrialModel::Synthetic,
            program: None,
            robot_type: 0,
            duration_s: 1.0,
            params,
            dispatch: 9,
            physics: Physics::default(),
        }
    }

    fn grant(trials: Vec<TrialRequest>, note: Option<String>) -> Vec<u8> {
        WorkGrant {
            trials,
            ready: 0,
            running: 2,
            seq: 1,
            state: RunState::Running,
            note,
        }
        .encode()
        .unwrap()
    }

    /// A grant whose only fault is a trial that fails its checks keeps the
    /// others and names that one, with the field, to give back; a fault of
    /// the grant itself leaves nothing to name.
    #[test]
    fn a_grant_keeps_the_trials_it_can_read_and_names_the_others() {
        let bad = trial(1, vec![("no_such_parameter".into(), 1.0)]);
        let g = read_grant(&grant(vec![trial(0, vec![]), bad.clone()], None)).unwrap();
        assert_eq!(g.grant.trials, vec![trial(0, vec![])]);
        assert_eq!(g.unreadable.len(), 1);
        assert_eq!(g.unreadable[0].0, bad);
        assert!(
            g.unreadable[0].1.contains("`params`")
                && g.unreadable[0].1.contains("no_such_parameter"),
            "{}",
            g.unreadable[0].1
        );
        let whole = read_grant(&grant(vec![trial(0, vec![])], None)).unwrap();
        assert_eq!((whole.grant.trials.len(), whole.unreadable.len()), (1, 0));
        let long_note = Some("n".repeat(5000));
        assert!(read_grant(&grant(vec![bad], long_note)).is_err());
        assert!(read_grant(b"not a grant").is_err());
    }

    /// A worker limited to 20 physics steps per cycle refuses a trial that
    /// asks for more, naming the count, and takes one within it.
    #[test]
    fn steps_beyond_the_workers_limit_are_refused() {
        let cfg = WorkerConfig {
            max_substeps: 20,
            ..WorkerConfig::default()
        };
        let steps = |n| TrialRequest {
            physics: Physics {
                substeps: n,
                ..Physics::default()
            },
            ..trial(0, vec![])
        };
        let why = cfg.beyond_limits(&steps(30)).unwrap();
        assert!(why.starts_with("30 physics substeps"), "{why}");
        assert_eq!(cfg.beyond_limits(&steps(20)), None);
    }
}
