//! A run on disk: the evolve state machine bound to its journal.
//!
//! [`Run::open`] creates a run directory or resumes one (replaying the journal,
//! never re-running initialisation over restored state); [`Run::on_outcome`]
//! journals a new outcome before applying it. Both return [`Effect`]s for the
//! transport: trials to dispatch, decisions to publish. Everything an effect
//! refers to is durable before the effect is returned.

use std::{
    collections::{BTreeMap, BTreeSet},
    path::Path,
};

use protocol::{experiment::text_hash, Experiment, TrialRequest};

use crate::{
    evolve::{
        Action, Counted, DecidedIteration, Evolve, HistoryPoint, Imported, Incumbent, Measurement,
        OpenedIteration, OutcomeError,
    },
    journal::{Control, Journal, JournalError, Record, Tail},
    lock::{LockError, RunLock},
};

mod read;
pub use read::{
    farm_trial, load_history, read_run, replay, salvage, FarmTrial, FromRun, RunView, Salvaged,
};

/// What the transport must do.
#[derive(Debug, Clone, PartialEq)]
pub enum Effect {
    /// Run these trials of this iteration.
    Dispatch(OpenedIteration, Vec<u32>),
    /// Publish this decision.
    Decided(DecidedIteration),
    /// The run is complete.
    Finished,
}

/// Why a run could not be opened or an outcome was not taken.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// Journal I/O or corruption.
    #[error(transparent)]
    Journal(#[from] JournalError),
    /// The directory holds a run of another experiment.
    #[error(
        "{dir}: the journal was written for another experiment ({why}); use a new --out directory"
    )]
    OtherExperiment {
        /// The run directory.
        dir: String,
        /// What differs.
        why: String,
    },
    /// `salvage`'s new run directory holds a journal already.
    #[error("{0} already holds a journal; salvage writes into a new --out directory")]
    SalvageOntoJournal(String),
    /// Replaying the journal disagrees with what this build computes.
    #[error("{dir}: journal replay diverges at iteration {iteration}: {why}")]
    Diverged {
        /// The run directory.
        dir: String,
        /// Iteration.
        iteration: u64,
        /// What differs.
        why: String,
    },
    /// An outcome was refused (unknown iteration, wrong seed, NaN…).
    #[error(transparent)]
    Refused(#[from] OutcomeError),
    /// Another coordinator holds the run directory.
    #[error(transparent)]
    Locked(#[from] LockError),
    /// `--from` names a run whose parameters are not this experiment's.
    #[error("--from {dir}: {why}")]
    FromMismatch {
        /// The earlier run's directory.
        dir: String,
        /// What differs.
        why: String,
    },
    /// A control action with bad numbers.
    #[error("control: {why}")]
    BadControl {
        /// What is wrong.
        why: String,
    },
    /// A run would begin in a directory that holds other files and no run.
    #[error("{dir} holds files but no run ({names}); a run begins in a new or empty directory")]
    NotARunDirectory {
        /// The directory.
        dir: String,
        /// The first few of its files, comma-separated.
        names: String,
    },
    /// A new run would begin inside another run's directory.
    #[error(
        "{dir} is inside the run directory {run}; a new run goes beside another run, never \
         inside it (removing that run would remove this one with it)"
    )]
    InsideARun {
        /// The directory asked for.
        dir: String,
        /// The run directory it is inside.
        run: String,
    },
    /// The journal's header holds an experiment this build cannot read.
    #[error("{dir}: the journal's experiment does not parse: {why}")]
    BadHeader {
        /// The run directory.
        dir: String,
        /// The parser's message.
        why: String,
    },
}

/// A run: the loop plus its journal, under the run directory's lock.
#[derive(Debug)]
pub struct Run {
    ev: Evolve,
    journal: Journal,
    journaled_open: BTreeSet<u64>,
    journaled_decided: BTreeSet<u64>,
    resumed: bool,
    extended_from: Option<u64>,
    failures: BTreeMap<(u64, u32), Vec<(String, String)>>,
    failure_limit: usize,
    id: String,
    priority: u32,
    paused: bool,
    /// The journaled fingerprint of the workers that serve the run.
    fingerprint: Option<u64>,
    _lock: RunLock,
}

/// By default a trial stops the run when it has failed on this many distinct
/// workers (or twice as many times in all: a small fleet retrying it on the
/// same workers). [`Run::set_failure_limit`] changes it.
pub const DISTINCT_FAILURES: usize = 3;

/// What a trial's failure means for the run.
#[derive(Debug, Clone, PartialEq)]
pub enum FailureVerdict {
    /// Journaled: give the trial to another worker.
    Retry,
    /// Not about a pending trial (late, or already decided): nothing journaled.
    Ignored,
    /// The trial failed too often: the run must stop with this report.
    GiveUp(GaveUp),
}

/// A trial that cannot be run: the run stops with this.
#[derive(Debug, Clone, PartialEq)]
pub struct GaveUp {
    /// Iteration.
    pub iteration: u64,
    /// Trial index.
    pub trial: u32,
    /// The trial's full parameter set.
    pub params: Vec<(String, f64)>,
    /// Each failure: worker and reason.
    pub reasons: Vec<(String, String)>,
}

impl std::fmt::Display for GaveUp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let workers: BTreeSet<&str> = self.reasons.iter().map(|(w, _)| w.as_str()).collect();
        write!(
            f,
            "trial {} of iteration {} failed {} times on {} distinct workers; the run stops. Parameters: {}. Reasons: {}",
            self.trial,
            self.iteration,
            self.reasons.len(),
            workers.len(),
            self.params
                .iter()
                .map(|(n, v)| format!("{n}={v}"))
                .collect::<Vec<_>>()
                .join(", "),
            self.reasons
                .iter()
                .map(|(w, r)| format!("worker {w}: {r}"))
                .collect::<Vec<_>>()
                .join("; ")
        )
    }
}

fn effective_json(exp: &Experiment) -> Result<String, RunError> {
    serde_json::to_string(exp).map_err(|e| RunError::BadHeader {
        dir: String::new(),
        why: format!("the experiment does not encode as JSON: {e}"),
    })
}

/// The fields (dotted paths) in which two experiments differ.
#[must_use]
pub fn differing_fields(a: &Experiment, b: &Experiment) -> Vec<String> {
    fn walk(prefix: &str, a: &serde_json::Value, b: &serde_json::Value, out: &mut Vec<String>) {
        match (a, b) {
            (serde_json::Value::Object(x), serde_json::Value::Object(y)) => {
                let keys: BTreeSet<&String> = x.keys().chain(y.keys()).collect();
                for k in keys {
                    let path = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    match (x.get(k), y.get(k)) {
                        (Some(p), Some(q)) => walk(&path, p, q, out),
                        _ => out.push(path),
                    }
                }
            }
            _ if a != b => out.push(prefix.to_string()),
            _ => {}
        }
    }
    let (Ok(a), Ok(b)) = (serde_json::to_value(a), serde_json::to_value(b)) else {
        return vec!["(unencodable experiment)".into()];
    };
    let mut out = Vec::new();
    walk("", &a, &b, &mut out);
    out
}

/// A journal's header experiment with its extensions applied, and the
/// imported history: what the run is.
fn journaled_experiment(
    dir: &Path,
    records: &[Record],
) -> Result<(Experiment, Imported), RunError> {
    let Some(Record::Header {
        experiment_json,
        imported,
        ..
    }) = records.first()
    else {
        return Err(JournalError::NoHeader {
            path: Journal::path_in(dir),
        }
        .into());
    };
    let mut exp =
        serde_json::from_str::<Experiment>(experiment_json).map_err(|e| RunError::BadHeader {
            dir: dir.display().to_string(),
            why: e.to_string(),
        })?;
    for r in records {
        if let Record::Extended { iterations, .. } = r {
            exp.iterations = exp.iterations.max(*iterations);
        }
    }
    Ok((exp, imported.clone()))
}

/// Refuses to begin a new run in `dir` (it holds no journal) when it holds
/// files other than a coordinator's lock (a start that failed before its
/// journal leaves one): they are someone else's, and a run there would write
/// among them, its lock over a file of theirs named `lock`. A missing `dir`
/// is fine: the lock makes it.
fn refuse_foreign_files(dir: &Path) -> Result<(), RunError> {
    if !dir.is_dir() {
        return Ok(());
    }
    let io = |cause| {
        RunError::Journal(JournalError::Io {
            path: dir.to_path_buf(),
            cause,
        })
    };
    let mut names = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let entry = entry.map_err(io)?;
        let name = entry.file_name();
        let ours = name == crate::lock::LOCK_FILE
            && entry.file_type().is_ok_and(|t| t.is_file())
            && entry.metadata().is_ok_and(|m| m.len() <= 4096)
            && std::fs::read(entry.path()).is_ok_and(|t| crate::lock::is_lock_text(&t));
        if !ours {
            let mut shown = name.to_string_lossy().into_owned();
            if name == crate::lock::LOCK_FILE {
                shown += ", not a coordinator's";
            }
            names.push(shown);
        }
    }
    if names.is_empty() {
        return Ok(());
    }
    names.sort();
    Err(RunError::NotARunDirectory {
        dir: dir.display().to_string(),
        names: first_names(&names),
    })
}

/// Refuses to begin a new run in `dir` (it holds no journal) when a
/// directory above it holds a run's journal: removing that run (say once
/// `journal salvage` has copied it) would remove the new one with it. A run
/// already in `dir` is resumed wherever it is: [`Run::open`] asks only for
/// a new one.
fn refuse_inside_a_run(dir: &Path) -> Result<(), RunError> {
    // The nearest part of the path that exists, resolved (`..`, links).
    let Some(real) = dir
        .ancestors()
        .filter(|a| !a.as_os_str().is_empty())
        .find_map(|a| a.canonicalize().ok())
        .or_else(|| std::env::current_dir().ok())
    else {
        return Ok(());
    };
    match real.ancestors().find(|a| Journal::path_in(a).is_file()) {
        Some(run) => Err(RunError::InsideARun {
            dir: dir.display().to_string(),
            run: run.display().to_string(),
        }),
        None => Ok(()),
    }
}

/// Refuses to begin a new run in `dir` where it would harm something of
/// anyone's: among someone else's files, or inside another run's directory.
/// [`Run::open`] asks it for every new run; a start may ask it earlier, before
/// it touches the network, so that the refusal comes first. Writes nothing.
pub fn refuse_new_run_at(dir: &Path) -> Result<(), RunError> {
    refuse_foreign_files(dir)?;
    refuse_inside_a_run(dir)
}

/// The first three of `names` (sorted by the caller), comma-separated, with
/// ", …" when there are more: how a refusal names the files it found.
#[must_use]
pub fn first_names<S: AsRef<str>>(names: &[S]) -> String {
    let shown: Vec<&str> = names.iter().take(3).map(AsRef::as_ref).collect();
    shown.join(", ") + if names.len() > 3 { ", …" } else { "" }
}

impl Run {
    /// Creates a run in `dir`, or resumes (or extends) the one there. Takes the
    /// directory's lock first; every check happens before any write.
    ///
    /// `imported` (a history from `--from`) is used only when creating.
    pub fn open(
        dir: &Path,
        exp: Experiment,
        exp_text: &str,
        imported: Option<Imported>,
    ) -> Result<(Self, Vec<Effect>), RunError> {
        if !Journal::path_in(dir).exists() {
            refuse_new_run_at(dir)?;
        }
        let lock = RunLock::acquire(dir)?;
        if Journal::path_in(dir).exists() {
            return Self::resume(dir, exp, lock);
        }
        let imported = imported.unwrap_or_default();
        let header = Record::Header {
            experiment_text: exp_text.to_string(),
            experiment_hash: text_hash(exp_text),
            experiment_json: effective_json(&exp)?,
            version: env!("CARGO_PKG_VERSION").to_string(),
            imported: imported.clone(),
        };
        let mut journal = Journal::create(dir, &header)?;
        let id = uuid::Uuid::new_v4().to_string();
        journal.append_all(&[
            &Record::Identity { id: id.clone() },
            &Record::clock_now(true),
        ])?;
        let (ev, actions) = Evolve::start(exp, &imported);
        let mut run = Self {
            ev,
            journal,
            journaled_open: BTreeSet::new(),
            journaled_decided: BTreeSet::new(),
            resumed: false,
            extended_from: None,
            failures: BTreeMap::new(),
            failure_limit: DISTINCT_FAILURES,
            id,
            priority: 1,
            paused: false,
            fingerprint: None,
            _lock: lock,
        };
        let effects = run.act(actions)?;
        Ok((run, effects))
    }

    fn resume(dir: &Path, exp: Experiment, lock: RunLock) -> Result<(Self, Vec<Effect>), RunError> {
        let dirs = dir.display().to_string();
        let scan = Journal::read(dir)?;
        if let Some(e) = scan.damage(&Journal::path_in(dir)) {
            return Err(e.into());
        }
        let records = scan.records();
        let (theirs, imported) = journaled_experiment(dir, &records)?;
        let mut differ = differing_fields(&theirs, &exp);
        let extend = differ == ["iterations"] && exp.iterations > theirs.iterations;
        if extend {
            differ.clear();
        }
        if !differ.is_empty() {
            let detail = differ
                .iter()
                .map(|f| match f.as_str() {
                    "iterations" => format!(
                        "iterations (the run plans {}, this asks {}; a run can be extended, not shortened)",
                        theirs.iterations, exp.iterations
                    ),
                    "name" => format!("name (`{}`, not `{}`)", theirs.name, exp.name),
                    "seed" => format!("seed ({}, not {})", theirs.seed, exp.seed),
                    f => f.to_string(),
                })
                .collect::<Vec<_>>()
                .join(", ");
            return Err(RunError::OtherExperiment {
                dir: dirs,
                why: format!("differs in {detail}"),
            });
        }
        // Every check is done: now the journal may be repaired and appended to.
        let mut journal = Journal::open_for_append(dir, &scan)?;
        if extend {
            journal.append(&Record::Extended {
                iterations: exp.iterations,
                version: env!("CARGO_PKG_VERSION").to_string(),
            })?;
        }
        let (mut ev, mut actions) = Evolve::start(exp, &imported);
        let mut opened_records = Vec::new();
        let mut decided_records = Vec::new();
        let mut failures: BTreeMap<(u64, u32), Vec<(String, String)>> = BTreeMap::new();
        let mut id = None;
        let (mut priority, mut paused) = (1, false);
        let mut fingerprint = None;
        for rec in records.into_iter().skip(1) {
            match rec {
                Record::Header { .. } => {
                    return Err(RunError::Diverged {
                        dir: dirs,
                        iteration: 0,
                        why: "a second header".into(),
                    })
                }
                Record::Extended { .. } | Record::Clock { .. } => {}
                Record::Fingerprint { fingerprint: f, .. } => {
                    fingerprint = fingerprint.or(Some(f));
                }
                Record::Identity { id: i } => id = id.or(Some(i)),
                Record::Control { action, .. } => match action {
                    Control::Pause => paused = true,
                    Control::Resume => paused = false,
                    Control::Priority(p) => priority = p,
                    // A stopped run that is served again runs.
                    Control::Stop => {}
                },
                Record::Failed {
                    iteration,
                    trial,
                    worker,
                    reason,
                } => failures
                    .entry((iteration, trial))
                    .or_default()
                    .push((worker, reason)),
                Record::Opened(o) => opened_records.push(o),
                Record::Decided(d) => decided_records.push(d),
                Record::Outcome {
                    iteration,
                    trial,
                    seed,
                    measurement,
                    ..
                } => {
                    let more = ev.apply(iteration, trial, seed, measurement).map_err(|e| {
                        RunError::Diverged {
                            dir: dirs.clone(),
                            iteration,
                            why: e.to_string(),
                        }
                    })?;
                    actions.extend(more);
                }
            }
        }
        let mut run = Self {
            ev,
            journal,
            journaled_open: BTreeSet::new(),
            journaled_decided: BTreeSet::new(),
            resumed: true,
            extended_from: extend.then_some(theirs.iterations),
            failures,
            failure_limit: DISTINCT_FAILURES,
            id: String::new(),
            priority,
            paused,
            fingerprint,
            _lock: lock,
        };
        // A journal older than run ids gets one now, kept from then on.
        run.id = match id {
            Some(i) => i,
            None => {
                let i = uuid::Uuid::new_v4().to_string();
                run.journal.append(&Record::Identity { id: i.clone() })?;
                i
            }
        };
        run.journal.append(&Record::clock_now(true))?;
        let diverged = |iteration: u64, what: &str| RunError::Diverged {
            dir: dirs.clone(),
            iteration,
            why: format!("the journaled {what} differs from the replayed one"),
        };
        let opened = opened_records
            .iter()
            .map(|o| (o.iteration, true, Action::Open(o.clone())));
        let decided = decided_records
            .iter()
            .map(|d| (d.iteration, false, Action::Decided(d.clone())));
        for (iteration, open, record) in opened.chain(decided) {
            if !actions.contains(&record) {
                let what = if open { "parameter set" } else { "decision" };
                return Err(diverged(iteration, what));
            }
            if open {
                run.journaled_open.insert(iteration);
            } else {
                run.journaled_decided.insert(iteration);
            }
        }
        let mut effects = run.act(actions)?;
        // Re-issue every trial still pending (act() issued only new iterations).
        effects.retain(|e| !matches!(e, Effect::Dispatch(..)));
        for (opened, missing) in run.ev.missing() {
            if !missing.is_empty() {
                effects.push(Effect::Dispatch(opened, missing));
            }
        }
        if run.ev.finished() && !effects.contains(&Effect::Finished) {
            effects.push(Effect::Finished);
        }
        Ok((run, effects))
    }

    /// The run's id (a UUID, journaled when the directory was created).
    #[must_use]
    pub fn id(&self) -> &str {
        &self.id
    }

    /// The run's priority (journaled; 1 unless changed).
    #[must_use]
    pub fn priority(&self) -> u32 {
        self.priority
    }

    /// Whether the run is paused (journaled).
    #[must_use]
    pub fn paused(&self) -> bool {
        self.paused
    }

    /// The fingerprint of the workers that serve the run, once pinned (journaled).
    #[must_use]
    pub fn fingerprint(&self) -> Option<u64> {
        self.fingerprint
    }

    /// Pins the run's worker fingerprint (journaled, one fsync) if none is yet.
    pub fn pin_fingerprint(
        &mut self,
        fingerprint: u64,
        version: &str,
        worker: &str,
    ) -> Result<(), RunError> {
        if self.fingerprint.is_some() {
            return Ok(());
        }
        self.journal.append(&Record::Fingerprint {
            fingerprint,
            version: version.to_string(),
            worker: worker.to_string(),
        })?;
        self.fingerprint = Some(fingerprint);
        Ok(())
    }

    /// Journals a control action and applies it (a no-op change is not journaled).
    pub fn control(&mut self, action: Control, by: &str) -> Result<(), RunError> {
        action.check().map_err(|why| RunError::BadControl { why })?;
        let changes = match action {
            Control::Pause => !self.paused,
            Control::Resume => self.paused,
            Control::Priority(p) => p != self.priority,
            Control::Stop => true,
        };
        if !changes {
            return Ok(());
        }
        self.journal.append(&Record::Control {
            action,
            by: by.to_string(),
        })?;
        match action {
            Control::Pause => self.paused = true,
            Control::Resume => self.paused = false,
            Control::Priority(p) => self.priority = p,
            Control::Stop => {}
        }
        Ok(())
    }

    /// Journals what the actions need (one fsync), then returns the effects.
    fn act(&mut self, actions: Vec<Action>) -> Result<Vec<Effect>, RunError> {
        let mut recs = Vec::new();
        let mut effects = Vec::new();
        for a in actions {
            match a {
                Action::Open(o) => {
                    if self.journaled_open.insert(o.iteration) {
                        recs.push(Record::Opened(o.clone()));
                    }
                    let all = (0..self.ev.experiment().trials_per_iteration).collect();
                    effects.push(Effect::Dispatch(o, all));
                }
                Action::Decided(d) => {
                    if self.journaled_decided.insert(d.iteration) {
                        recs.push(Record::Decided(d.clone()));
                        effects.push(Effect::Decided(d));
                    }
                }
                Action::Finished => effects.push(Effect::Finished),
            }
        }
        if recs.iter().any(|r| matches!(r, Record::Decided(_))) {
            recs.push(Record::clock_now(false));
        }
        if !recs.is_empty() {
            self.journal.append_all(&recs.iter().collect::<Vec<_>>())?;
        }
        Ok(effects)
    }

    /// Takes one trial outcome: refused, ignored as a duplicate, or journaled and applied.
    pub fn on_outcome(
        &mut self,
        iteration: u64,
        trial: u32,
        seed: u64,
        measurement: Measurement,
        worker: &str,
    ) -> Result<(Counted, Vec<Effect>), RunError> {
        match self.ev.classify(iteration, trial, seed, &measurement)? {
            Counted::Duplicate => Ok((Counted::Duplicate, Vec::new())),
            Counted::New => {
                self.journal.append(&Record::Outcome {
                    iteration,
                    trial,
                    seed,
                    measurement,
                    worker: worker.to_string(),
                })?;
                let actions = self.ev.apply(iteration, trial, seed, measurement)?;
                Ok((Counted::New, self.act(actions)?))
            }
        }
    }

    /// Takes a worker's report that it could not run a pending trial: journals
    /// it and says whether to retry elsewhere or stop the run.
    pub fn on_failure(
        &mut self,
        iteration: u64,
        trial: u32,
        worker: &str,
        reason: &str,
    ) -> Result<FailureVerdict, RunError> {
        if !self.is_pending(iteration, trial) {
            return Ok(FailureVerdict::Ignored);
        }
        self.journal.append(&Record::Failed {
            iteration,
            trial,
            worker: worker.to_string(),
            reason: reason.to_string(),
        })?;
        self.failures
            .entry((iteration, trial))
            .or_default()
            .push((worker.to_string(), reason.to_string()));
        Ok(self.verdict(iteration, trial))
    }

    fn verdict(&self, iteration: u64, trial: u32) -> FailureVerdict {
        let Some(reasons) = self.failures.get(&(iteration, trial)) else {
            return FailureVerdict::Retry;
        };
        let distinct: BTreeSet<&str> = reasons.iter().map(|(w, _)| w.as_str()).collect();
        if distinct.len() < self.failure_limit && reasons.len() < 2 * self.failure_limit {
            return FailureVerdict::Retry;
        }
        let params = self
            .ev
            .open_params(iteration)
            .map(|p| self.ev.experiment().full_params(p))
            .unwrap_or_default();
        FailureVerdict::GiveUp(GaveUp {
            iteration,
            trial,
            params,
            reasons: reasons.clone(),
        })
    }

    /// Sets how many distinct workers may fail one trial before the run stops
    /// (at least 1; a resumed run may raise it to retry a trial that stopped it).
    pub fn set_failure_limit(&mut self, distinct_workers: usize) {
        self.failure_limit = distinct_workers.max(1);
    }

    /// A pending trial that has already failed too often (a resumed run keeps the counts).
    #[must_use]
    pub fn exhausted(&self) -> Option<GaveUp> {
        self.failures.keys().find_map(
            |&(i, k)| match (self.is_pending(i, k), self.verdict(i, k)) {
                (true, FailureVerdict::GiveUp(g)) => Some(g),
                _ => None,
            },
        )
    }

    /// The distinct workers that failed (iteration, trial).
    #[must_use]
    pub fn failed_workers(&self, iteration: u64, trial: u32) -> BTreeSet<String> {
        self.failures
            .get(&(iteration, trial))
            .map(|v| v.iter().map(|(w, _)| w.clone()).collect())
            .unwrap_or_default()
    }

    /// Whether an outcome for (iteration, trial) would still be taken.
    #[must_use]
    pub fn is_pending(&self, iteration: u64, trial: u32) -> bool {
        self.ev.is_pending(iteration, trial)
    }

    /// The trial request for trial `k` of an opened iteration.
    pub fn request(
        &self,
        opened: &OpenedIteration,
        k: u32,
        dispatch: u64,
    ) -> Result<TrialRequest, OutcomeError> {
        request(self.ev.experiment(), &self.id, opened, k, dispatch)
    }

    /// The evolve state machine (read-only).
    #[must_use]
    pub fn evolve(&self) -> &Evolve {
        &self.ev
    }

    /// Whether this run was resumed from a journal.
    #[must_use]
    pub fn resumed(&self) -> bool {
        self.resumed
    }

    /// The planned total before this open extended the run, if it did.
    #[must_use]
    pub fn extended_from(&self) -> Option<u64> {
        self.extended_from
    }
}

/// The request for trial `k` of an opened iteration: exactly what a worker gets.
pub fn request(
    exp: &Experiment,
    run_id: &str,
    opened: &OpenedIteration,
    k: u32,
    dispatch: u64,
) -> Result<TrialRequest, OutcomeError> {
    let seed = opened
        .seeds
        .get(k as usize)
        .copied()
        .ok_or(OutcomeError::UnknownTrial {
            iteration: opened.iteration,
            trial: k,
        })?;
    Ok(TrialRequest {
        run: run_id.to_string(),
        iteration: opened.iteration,
        trial: k,
        seed,
        model: exp.model,
        program: exp.program.clone(),
        robot_type: exp.robot_type,
        duration_s: exp.trial_duration_s,
        params: exp.full_params(&opened.params),
        dispatch,
        physics: exp.physics,
    })
}

/// Runs every effect to completion in this thread with `trial` (tests, local tools).
///
/// `order` permutes each batch of pending trials (to show order does not matter).
pub fn drive_local(
    run: &mut Run,
    effects: Vec<Effect>,
    trial: &dyn Fn(&TrialRequest) -> Measurement,
    order: &mut dyn FnMut(&mut Vec<TrialRequest>),
) -> Result<(), RunError> {
    let mut queue: Vec<TrialRequest> = Vec::new();
    let push = |run: &Run, effects: Vec<Effect>, queue: &mut Vec<TrialRequest>| {
        for e in effects {
            if let Effect::Dispatch(o, ks) = e {
                for k in ks {
                    if let Ok(r) = run.request(&o, k, 0) {
                        queue.push(r);
                    }
                }
            }
        }
    };
    push(run, effects, &mut queue);
    while !queue.is_empty() {
        order(&mut queue);
        let req = queue.remove(0);
        let r = trial(&req);
        let (_, effects) = run.on_outcome(req.iteration, req.trial, req.seed, r, "local")?;
        push(run, effects, &mut queue);
    }
    Ok(())
}

#[cfg(test)]
mod tests;
