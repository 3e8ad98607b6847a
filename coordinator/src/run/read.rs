//! Reading a run without serving it: one farm trial as the journal tells it,
//! the run's view and history, its replay, the history of another run to
//! start from, and salvage of a damaged journal.

use super::*;

/// A farm trial as its run's journal tells it: the request a worker got, and
/// what was journaled for it (if it was run).
#[derive(Debug, Clone)]
pub struct FarmTrial {
    /// The request (dispatch 0).
    pub request: TrialRequest,
    /// The journaled measurement and the worker that made it.
    pub journaled: Option<(Measurement, String)>,
}

/// Reads trial `trial` of iteration `iteration` of the run in `dir` (only reads).
pub fn farm_trial(dir: &Path, iteration: u64, trial: u32) -> Result<FarmTrial, RunError> {
    let (view, records) = read_run_records(dir)?;
    let opened = records
        .iter()
        .find_map(|r| match r {
            Record::Opened(o) if o.iteration == iteration => Some(o.clone()),
            _ => None,
        })
        .ok_or(RunError::Refused(OutcomeError::UnknownIteration(iteration)))?;
    let request = request(
        &view.experiment,
        view.id.as_deref().unwrap_or("unnamed"),
        &opened,
        trial,
        0,
    )?;
    let journaled = records.into_iter().find_map(|r| match r {
        Record::Outcome {
            iteration: i,
            trial: k,
            measurement,
            worker,
            ..
        } if i == iteration && k == trial => Some((measurement, worker)),
        _ => None,
    });
    Ok(FarmTrial { request, journaled })
}

/// A run as its journal tells it, read without writing anything.
#[derive(Debug, Clone)]
pub struct RunView {
    /// The effective experiment (extensions applied).
    pub experiment: Experiment,
    /// The decided history.
    pub decided: Vec<DecidedIteration>,
    /// How the journal ends (never [`Tail::Damaged`]: that is an error).
    pub tail: Tail,
    /// Whether a coordinator holds the run now (a torn-looking tail is then in progress).
    pub live: bool,
    /// The journal's format.
    pub format: u32,
    /// The naofarm version that created the run.
    pub version: String,
    /// Records read.
    pub records: usize,
    /// The planned totals the run was extended to, in order.
    pub extensions: Vec<u64>,
    /// The run id (`None`: a journal older than run ids, never resumed since).
    pub id: Option<String>,
    /// Its wall time (`None`: a journal older than its clock marks).
    pub wall: Option<crate::journal::WallTime>,
}

/// Reads the run in `dir`: damage is an error naming its offset; a torn tail is
/// reported in [`RunView::tail`]. Reading never writes and takes no lock.
pub fn read_run(dir: &Path) -> Result<RunView, RunError> {
    read_run_records(dir).map(|(view, _)| view)
}

/// The run in `dir` replayed from its journal as a resume replays it (the
/// same CLOP state bit for bit, hence its Optim.2), without a lock and
/// without writing: for reports on a finished or a running run.
pub fn replay(dir: &Path) -> Result<Evolve, RunError> {
    let scan = Journal::read(dir)?;
    if let Some(e) = scan.damage(&Journal::path_in(dir)) {
        return Err(e.into());
    }
    let records = scan.records();
    let (exp, imported) = journaled_experiment(dir, &records)?;
    let (mut ev, _) = Evolve::start(exp, &imported);
    for rec in records {
        if let Record::Outcome {
            iteration,
            trial,
            seed,
            measurement,
            ..
        } = rec
        {
            ev.apply(iteration, trial, seed, measurement)
                .map_err(|e| RunError::Diverged {
                    dir: dir.display().to_string(),
                    iteration,
                    why: e.to_string(),
                })?;
        }
    }
    Ok(ev)
}

/// [`read_run`], with the journal's records (one read of the file).
pub(super) fn read_run_records(dir: &Path) -> Result<(RunView, Vec<Record>), RunError> {
    let scan = Journal::read(dir)?;
    if let Some(e) = scan.damage(&Journal::path_in(dir)) {
        return Err(e.into());
    }
    let records = scan.records();
    let (experiment, _) = journaled_experiment(dir, &records)?;
    let version = match records.first() {
        Some(Record::Header { version, .. }) => version.clone(),
        _ => String::new(),
    };
    let mut decided = Vec::new();
    let mut extensions = Vec::new();
    let mut id = None;
    for rec in &records {
        match rec {
            Record::Decided(d) => decided.push(d.clone()),
            Record::Extended { iterations, .. } => extensions.push(*iterations),
            Record::Identity { id: i } => id = id.or_else(|| Some(i.clone())),
            _ => {}
        }
    }
    let view = RunView {
        experiment,
        decided,
        tail: scan.tail,
        live: RunLock::is_held(dir),
        format: scan.format,
        version,
        records: records.len(),
        extensions,
        id,
        wall: crate::journal::WallTime::of(&records),
    };
    Ok((view, records))
}

/// An earlier run's H and ν′ for `--from RUN_DIR` (its own imports included),
/// matched to `exp`'s parameters by name.
#[derive(Debug, Clone)]
pub struct FromRun {
    /// The points that lie inside `exp`'s bounds, in `exp`'s parameter order.
    pub imported: Imported,
    /// Points in the earlier run.
    pub total: usize,
    /// Whether the earlier ν′ was kept (inside the new bounds).
    pub best_kept: bool,
}

/// Reads an earlier run for `--from`: a different parameter set is refused
/// (the names on each side); points outside `exp`'s bounds are left out.
pub fn load_history(dir: &Path, exp: &Experiment) -> Result<FromRun, RunError> {
    let (view, records) = read_run_records(dir)?;
    let mut all = Imported::default();
    for rec in records {
        match rec {
            Record::Header { imported, .. } => all = imported,
            Record::Decided(d) => {
                all.history.push(HistoryPoint {
                    params: d.params.clone(),
                    decision: d.decision,
                });
                if d.best.is_some() {
                    all.best = d.best;
                }
            }
            _ => {}
        }
    }
    let theirs: Vec<&str> = view
        .experiment
        .parameter
        .iter()
        .map(|p| p.name.as_str())
        .collect();
    let ours: Vec<&str> = exp.parameter.iter().map(|p| p.name.as_str()).collect();
    let mismatch = |why: String| RunError::FromMismatch {
        dir: dir.display().to_string(),
        why,
    };
    let (mut a, mut b) = (theirs.clone(), ours.clone());
    a.sort_unstable();
    b.sort_unstable();
    if a != b {
        return Err(mismatch(format!(
            "its parameters ({}) are not this experiment's ({})",
            theirs.join(", "),
            ours.join(", ")
        )));
    }
    // Position in the earlier run of each of ours.
    let index: Vec<usize> = ours
        .iter()
        .filter_map(|n| theirs.iter().position(|t| t == n))
        .collect();
    let remap = |p: &[f64]| -> Option<Vec<f64>> {
        let v: Vec<f64> = index
            .iter()
            .map(|&i| p.get(i).copied())
            .collect::<Option<_>>()?;
        let inside = v
            .iter()
            .zip(&exp.parameter)
            .all(|(x, s)| x.is_finite() && *x >= s.lower && *x <= s.upper);
        inside.then_some(v)
    };
    let total = all.history.len();
    let history = all
        .history
        .iter()
        .filter_map(|h| {
            remap(&h.params).map(|params| HistoryPoint {
                params,
                decision: h.decision,
            })
        })
        .collect();
    let best = all.best.as_ref().and_then(|b| {
        remap(&b.params).map(|params| Incumbent {
            params,
            ..b.clone()
        })
    });
    Ok(FromRun {
        best_kept: best.is_some() || all.best.is_none(),
        imported: Imported { history, best },
        total,
    })
}

/// What `journal salvage` recovered.
#[derive(Debug, Clone)]
pub struct Salvaged {
    /// Valid records found in the damaged journal.
    pub records: usize,
    /// Byte spans skipped (offset, length).
    pub skipped: Vec<(u64, u64)>,
    /// Outcomes carried into the new run.
    pub outcomes: usize,
    /// Outcomes left out (their iteration could not be reopened without the lost ones).
    pub dropped: usize,
    /// Iterations decided in the new run.
    pub decided: u64,
}

/// Writes every valid record of `dir`'s journal into a new run directory `out`
/// (which must hold no journal): the header, then each recovered outcome
/// through the run itself, so `out` resumes. `dir` is only read.
pub fn salvage(dir: &Path, out: &Path) -> Result<Salvaged, RunError> {
    let path = Journal::path_in(dir);
    let bytes = std::fs::read(&path).map_err(|cause| JournalError::Io {
        path: path.clone(),
        cause,
    })?;
    let found = crate::journal::scan_all(&path, &bytes)?;
    let records: Vec<Record> = found.records.iter().map(|(_, r)| r.clone()).collect();
    let (exp, imported) = journaled_experiment(dir, &records)?;
    let text = match records.first() {
        Some(Record::Header {
            experiment_text, ..
        }) => experiment_text.clone(),
        _ => String::new(),
    };
    if Journal::path_in(out).exists() {
        return Err(RunError::SalvageOntoJournal(out.display().to_string()));
    }
    let (mut run, _) = Run::open(out, exp, &text, Some(imported))?;
    let mut pending: Vec<(u64, u32, u64, Measurement, String)> = records
        .into_iter()
        .filter_map(|r| match r {
            Record::Outcome {
                iteration,
                trial,
                seed,
                measurement,
                worker,
            } => Some((iteration, trial, seed, measurement, worker)),
            _ => None,
        })
        .collect();
    let mut outcomes = 0;
    loop {
        let before = pending.len();
        let mut later = Vec::new();
        for (i, k, seed, m, w) in pending {
            match run.on_outcome(i, k, seed, m, &w) {
                Ok((Counted::New, _)) => outcomes += 1,
                Ok((Counted::Duplicate, _)) => {}
                Err(RunError::Refused(OutcomeError::UnknownIteration(_))) => {
                    later.push((i, k, seed, m, w));
                }
                Err(RunError::Refused(_)) => {}
                Err(e) => return Err(e),
            }
        }
        pending = later;
        if pending.is_empty() || pending.len() == before {
            break;
        }
    }
    Ok(Salvaged {
        records: found.records.len(),
        skipped: found.skipped,
        outcomes,
        dropped: pending.len(),
        decided: run.ev.decided(),
    })
}
