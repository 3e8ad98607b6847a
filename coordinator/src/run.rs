//! A run on disk: the evolve state machine bound to its journal.
//!
//! [`Run::open`] creates a run directory or resumes one (replaying the journal,
//! never re-running initialisation over restored state); [`Run::on_outcome`]
//! journals a new outcome before applying it. Both return [`Effect`]s for the
//! transport: trials to dispatch, decisions to publish. Everything an effect
//! refers to is durable before the effect is returned.

use std::{collections::BTreeSet, path::Path};

use protocol::{experiment::text_hash, Experiment, TrialRequest};

use crate::{
    evolve::{
        Action, Counted, DecidedIteration, Evolve, Imported, OpenedIteration, OutcomeError,
        TrialResult,
    },
    journal::{Journal, JournalError, Record},
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
    /// The journal's header holds an experiment this build cannot read.
    #[error("{dir}: the journal's experiment does not parse: {why}")]
    BadHeader {
        /// The run directory.
        dir: String,
        /// The parser's message.
        why: String,
    },
}

/// A run: the loop plus its journal.
#[derive(Debug)]
pub struct Run {
    ev: Evolve,
    journal: Journal,
    journaled_open: BTreeSet<u64>,
    journaled_decided: BTreeSet<u64>,
    resumed: bool,
}

fn effective_json(exp: &Experiment) -> String {
    serde_json::to_string(exp).unwrap_or_default()
}

impl Run {
    /// Creates a run in `dir`, or resumes the one there.
    ///
    /// `imported` (a history from `--from`) is used only when creating.
    pub fn open(
        dir: &Path,
        exp: Experiment,
        exp_text: &str,
        imported: Option<Imported>,
    ) -> Result<(Self, Vec<Effect>), RunError> {
        if Journal::path_in(dir).exists() {
            return Self::resume(dir, exp);
        }
        let imported = imported.unwrap_or_default();
        let header = Record::Header {
            experiment_text: exp_text.to_string(),
            experiment_hash: text_hash(exp_text),
            experiment_json: effective_json(&exp),
            version: env!("CARGO_PKG_VERSION").to_string(),
            imported: imported.clone(),
        };
        let journal = Journal::create(dir, &header)?;
        let (ev, actions) = Evolve::start(exp, &imported);
        let mut run = Self {
            ev,
            journal,
            journaled_open: BTreeSet::new(),
            journaled_decided: BTreeSet::new(),
            resumed: false,
        };
        let effects = run.act(actions)?;
        Ok((run, effects))
    }

    fn resume(dir: &Path, exp: Experiment) -> Result<(Self, Vec<Effect>), RunError> {
        let dirs = dir.display().to_string();
        let (journal, replay) = Journal::open(dir)?;
        if let Some((offset, len)) = replay.torn {
            tracing::warn!(journal = %journal.path().display(), offset, len, "dropped a torn last record");
        }
        let mut records = replay.records.into_iter();
        let Some(Record::Header {
            experiment_json,
            imported,
            ..
        }) = records.next()
        else {
            return Err(JournalError::NoHeader {
                path: journal.path().to_path_buf(),
            }
            .into());
        };
        // Compared as experiments, not as text: a journal written before a
        // field existed reads it at its default.
        let theirs = serde_json::from_str::<Experiment>(&experiment_json);
        if !matches!(&theirs, Ok(t) if *t == exp) {
            let why = match theirs {
                Ok(theirs) if theirs.name != exp.name => {
                    format!("run `{}`, not `{}`", theirs.name, exp.name)
                }
                Ok(theirs) if theirs.seed != exp.seed => {
                    format!("seed {}, not {}", theirs.seed, exp.seed)
                }
                Ok(theirs) if theirs.physics != exp.physics => {
                    format!("physics {:?}, not {:?}", theirs.physics, exp.physics)
                }
                Ok(_) => "its settings differ".to_string(),
                Err(e) => format!("unreadable header: {e}"),
            };
            return Err(RunError::OtherExperiment { dir: dirs, why });
        }
        let (mut ev, mut actions) = Evolve::start(exp, &imported);
        let mut opened_records = Vec::new();
        let mut decided_records = Vec::new();
        for rec in records {
            match rec {
                Record::Header { .. } => {
                    return Err(RunError::Diverged {
                        dir: dirs,
                        iteration: 0,
                        why: "a second header".into(),
                    })
                }
                Record::Opened(o) => opened_records.push(o),
                Record::Decided(d) => decided_records.push(d),
                Record::Outcome {
                    iteration,
                    trial,
                    seed,
                    result,
                } => {
                    let more = ev.apply(iteration, trial, seed, result).map_err(|e| {
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
        };
        for o in opened_records {
            let same = actions
                .iter()
                .any(|a| matches!(a, Action::Open(x) if x == &o));
            if !same {
                return Err(RunError::Diverged {
                    dir: dirs,
                    iteration: o.iteration,
                    why: "the journaled parameter set differs from the replayed one".into(),
                });
            }
            run.journaled_open.insert(o.iteration);
        }
        for d in decided_records {
            let same = actions
                .iter()
                .any(|a| matches!(a, Action::Decided(x) if x == &d));
            if !same {
                return Err(RunError::Diverged {
                    dir: dirs,
                    iteration: d.iteration,
                    why: "the journaled decision differs from the replayed one".into(),
                });
            }
            run.journaled_decided.insert(d.iteration);
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
        result: TrialResult,
    ) -> Result<(Counted, Vec<Effect>), RunError> {
        match self.ev.classify(iteration, trial, seed, &result)? {
            Counted::Duplicate => Ok((Counted::Duplicate, Vec::new())),
            Counted::New => {
                self.journal.append(&Record::Outcome {
                    iteration,
                    trial,
                    seed,
                    result: result.clone(),
                })?;
                let actions = self.ev.apply(iteration, trial, seed, result)?;
                Ok((Counted::New, self.act(actions)?))
            }
        }
    }

    /// Whether an outcome for (iteration, trial) would still be taken.
    #[must_use]
    pub fn is_pending(&self, iteration: u64, trial: u32) -> bool {
        self.ev
            .missing()
            .iter()
            .any(|(o, ks)| o.iteration == iteration && ks.contains(&trial))
    }

    /// The trial request for trial `k` of an opened iteration.
    #[must_use]
    pub fn request(&self, opened: &OpenedIteration, k: u32, dispatch: u64) -> TrialRequest {
        let exp = self.ev.experiment();
        TrialRequest {
            run: exp.name.clone(),
            iteration: opened.iteration,
            trial: k,
            seed: opened.seeds.get(k as usize).copied().unwrap_or_default(),
            model: exp.model,
            robot_type: exp.robot_type,
            duration_s: exp.trial_duration_s,
            params: exp.full_params(&opened.params),
            dispatch,
            physics: exp.physics,
        }
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
}

/// Reads a run's journal without opening it for writing (a torn tail is
/// skipped, not repaired): its path and records.
fn read_journal(dir: &Path) -> Result<(std::path::PathBuf, crate::journal::Replay), RunError> {
    let path = Journal::path_in(dir);
    let bytes = std::fs::read(&path).map_err(|cause| JournalError::Io {
        path: path.clone(),
        cause,
    })?;
    let replay = Journal::parse(&path, &bytes)?;
    Ok((path, replay))
}

/// Reads an earlier run's H and ν′ for `--from RUN_DIR` (its own imports included).
pub fn load_history(dir: &Path) -> Result<Imported, RunError> {
    let (_, replay) = read_journal(dir)?;
    let mut out = Imported::default();
    for rec in replay.records {
        match rec {
            Record::Header { imported, .. } => out = imported,
            Record::Decided(d) => {
                out.history.push((d.params.clone(), d.decision));
                if d.best.is_some() {
                    out.best = d.best;
                }
            }
            Record::Opened(_) | Record::Outcome { .. } => {}
        }
    }
    Ok(out)
}

/// A finished or running run as its journal tells it: the effective experiment
/// and the decided history (for `naofarm history`). Reading never writes.
pub fn read_run(dir: &Path) -> Result<(Experiment, Vec<DecidedIteration>), RunError> {
    let (path, replay) = read_journal(dir)?;
    let mut exp = None;
    let mut decided = Vec::new();
    for rec in replay.records {
        match rec {
            Record::Header {
                experiment_json, ..
            } => {
                exp = Some(
                    serde_json::from_str::<Experiment>(&experiment_json).map_err(|e| {
                        RunError::BadHeader {
                            dir: dir.display().to_string(),
                            why: e.to_string(),
                        }
                    })?,
                );
            }
            Record::Decided(d) => decided.push(d),
            Record::Opened(_) | Record::Outcome { .. } => {}
        }
    }
    let exp = exp.ok_or(JournalError::NoHeader { path })?;
    Ok((exp, decided))
}

/// Runs every effect to completion in this thread with `trial` (tests, local tools).
///
/// `order` permutes each batch of pending trials (to show order does not matter).
pub fn drive_local(
    run: &mut Run,
    effects: Vec<Effect>,
    trial: &dyn Fn(&TrialRequest) -> TrialResult,
    order: &mut dyn FnMut(&mut Vec<TrialRequest>),
) -> Result<(), RunError> {
    let mut queue: Vec<TrialRequest> = Vec::new();
    let push = |run: &Run, effects: Vec<Effect>, queue: &mut Vec<TrialRequest>| {
        for e in effects {
            if let Effect::Dispatch(o, ks) = e {
                for k in ks {
                    queue.push(run.request(&o, k, 0));
                }
            }
        }
    };
    push(run, effects, &mut queue);
    while !queue.is_empty() {
        order(&mut queue);
        let req = queue.remove(0);
        let r = trial(&req);
        let (_, effects) = run.on_outcome(req.iteration, req.trial, req.seed, r)?;
        push(run, effects, &mut queue);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    const EXP: &str = r#"
name = "syn"
seed = 42
iterations = 40
trials_per_iteration = 6
pipeline_depth = 3
model = "synthetic"
start = "expert"

[[parameter]]
name = "ThighRelHip2_Z"
lower = -0.08
upper = -0.03
expert = -0.04

[[parameter]]
name = "xlength_step_max"
lower = 0.02
upper = 0.15
expert = 0.08

[clop]
draw_elo = 100.0
n_mcmc = 200
"#;

    fn exp() -> Experiment {
        Experiment::from_toml(EXP).unwrap()
    }

    fn synthetic(req: &TrialRequest) -> TrialResult {
        let r = worker::run_trial(req).unwrap();
        TrialResult {
            fell: r.fell,
            x_m: r.x_m,
            y_m: r.y_m,
            fall_time_s: r.fall_time_s,
            sim_time_s: r.sim_time_s,
            worker: "test".into(),
        }
    }

    fn tmp(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("naofarm-run-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    fn bits(h: &[DecidedIteration]) -> Vec<u64> {
        // Every number of the history, as bits, plus the decisions.
        let mut v = Vec::new();
        for d in h {
            v.push(d.iteration);
            v.extend(d.params.iter().map(|x| x.to_bits()));
            v.push(d.decision as u64);
            v.extend(
                [d.stats.mx, d.stats.my, d.stats.ex, d.stats.ey]
                    .iter()
                    .map(|x| x.map_or(u64::MAX, f64::to_bits)),
            );
        }
        v
    }

    fn full_run(name: &str, shuffle_seed: Option<u64>) -> Vec<DecidedIteration> {
        let dir = tmp(name);
        let (mut run, effects) = Run::open(&dir, exp(), EXP, None).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(shuffle_seed.unwrap_or(0));
        let mut order = |q: &mut Vec<TrialRequest>| {
            if shuffle_seed.is_some() {
                let n = q.len();
                q.swap(0, rng.random_range(0..n));
            }
        };
        drive_local(&mut run, effects, &synthetic, &mut order).unwrap();
        assert!(run.evolve().finished());
        run.evolve().history().to_vec()
    }

    #[test]
    fn a_run_completes_and_the_order_of_outcomes_does_not_matter() {
        let a = full_run("order-a", None);
        let b = full_run("order-b", Some(7));
        assert_eq!(a.len(), 40);
        assert_eq!(bits(&a), bits(&b));
        assert!(
            a[0].params == vec![-0.04, 0.08],
            "the expert set is iteration 0"
        );
        let accepts = a
            .iter()
            .filter(|d| d.decision == protocol::Decision::Accept)
            .count();
        assert!(accepts >= 2, "{accepts}");
    }

    #[test]
    fn duplicates_count_once_and_bad_outcomes_change_nothing() {
        let dir = tmp("dup");
        let (mut run, effects) = Run::open(&dir, exp(), EXP, None).unwrap();
        let Effect::Dispatch(o, _) = &effects[0] else {
            panic!()
        };
        let req = run.request(o, 0, 0);
        let r = synthetic(&req);
        let (c, _) = run.on_outcome(0, 0, req.seed, r.clone()).unwrap();
        assert_eq!(c, Counted::New);
        let (c, _) = run.on_outcome(0, 0, req.seed, r.clone()).unwrap();
        assert_eq!(c, Counted::Duplicate);
        let mut nan = r.clone();
        nan.x_m = f64::NAN;
        assert!(matches!(
            run.on_outcome(0, 1, run.request(o, 1, 0).seed, nan),
            Err(RunError::Refused(_))
        ));
        assert!(matches!(
            run.on_outcome(99, 0, 0, r.clone()),
            Err(RunError::Refused(OutcomeError::UnknownIteration(99)))
        ));
        assert!(matches!(
            run.on_outcome(0, 77, 0, r.clone()),
            Err(RunError::Refused(OutcomeError::UnknownTrial { .. }))
        ));
        assert!(matches!(
            run.on_outcome(0, 1, 12345, r),
            Err(RunError::Refused(OutcomeError::WrongSeed { .. }))
        ));
        drop(run);
        let (_, replay) = Journal::open(&dir).unwrap();
        let outcomes = replay
            .records
            .iter()
            .filter(|r| matches!(r, Record::Outcome { .. }))
            .count();
        assert_eq!(outcomes, 1, "only the one good outcome reached the journal");
    }

    #[test]
    fn resume_after_a_crash_gives_the_same_history_bit_for_bit() {
        let reference = full_run("resume-ref", None);
        for stop_after in [1usize, 17, 60, 150] {
            let dir = tmp(&format!("resume-{stop_after}"));
            let (mut run, effects) = Run::open(&dir, exp(), EXP, None).unwrap();
            // Run part of it, then "crash" (drop everything in memory).
            let mut queue: Vec<TrialRequest> = Vec::new();
            let enqueue = |run: &Run, effects: Vec<Effect>, q: &mut Vec<TrialRequest>| {
                for e in effects {
                    if let Effect::Dispatch(o, ks) = e {
                        q.extend(ks.into_iter().map(|k| run.request(&o, k, 0)));
                    }
                }
            };
            enqueue(&run, effects, &mut queue);
            for _ in 0..stop_after {
                let req = queue.remove(0);
                let (_, effects) = run
                    .on_outcome(req.iteration, req.trial, req.seed, synthetic(&req))
                    .unwrap();
                enqueue(&run, effects, &mut queue);
            }
            drop(run);
            let (mut run, effects) = Run::open(&dir, exp(), EXP, None).unwrap();
            assert!(run.resumed());
            drive_local(&mut run, effects, &synthetic, &mut |_| {}).unwrap();
            let (_, replay) = Journal::open(&dir).unwrap();
            let decided: Vec<DecidedIteration> = replay
                .records
                .into_iter()
                .filter_map(|r| {
                    if let Record::Decided(d) = r {
                        Some(d)
                    } else {
                        None
                    }
                })
                .collect();
            assert_eq!(
                bits(&decided),
                bits(&reference),
                "stopped after {stop_after}"
            );
        }
    }

    /// Experiment 2's file with the synthetic model and `iterations`, `depth`.
    fn physical_technical(iterations: u64, depth: u32) -> (Experiment, String) {
        let text = include_str!("../../experiments/physical-technical.toml")
            .replace("model = \"nao\"", "model = \"synthetic\"")
            .replace("iterations = 500", &format!("iterations = {iterations}"))
            .replace("pipeline_depth = 4", &format!("pipeline_depth = {depth}"));
        (Experiment::from_toml(&text).unwrap(), text)
    }

    fn run_to_end(name: &str, exp: Experiment, text: &str) -> Run {
        let dir = tmp(name);
        let (mut run, effects) = Run::open(&dir, exp, text, None).unwrap();
        drive_local(&mut run, effects, &synthetic, &mut |_| {}).unwrap();
        assert!(run.evolve().finished());
        run
    }

    #[test]
    fn two_hundred_synthetic_iterations_converge() {
        let (exp, text) = physical_technical(200, 4);
        let run = run_to_end("converge", exp, &text);
        let ev = run.evolve();
        let h = ev.history();
        assert_eq!(h.len(), 200);
        let kept = |part: &[DecidedIteration]| {
            part.iter()
                .filter(|d| d.decision != protocol::Decision::Reject)
                .count()
        };
        let (first, last) = (kept(&h[..50]), kept(&h[150..]));
        assert!(
            last > first,
            "ACCEPT+EQUIVALENT share must grow: {first}/50 in the first quarter, {last}/50 in the last"
        );
        // The synthetic optimum (worker::synthetic::SHAPE; the step length's
        // best lies where speed saturates before the balance penalty, ~0.125 m).
        let optimum = [-0.038, 0.80, 0.014, 0.038, 0.125];
        let ranges = [0.05, 0.35, 0.029, 0.045, 0.13];
        let off = |p: &[f64]| -> f64 {
            p.iter()
                .zip(optimum.iter().zip(ranges))
                .map(|(v, (o, r))| ((v - o) / r).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        let expert = off(&h[0].params);
        let (_, nu_p, _) = ev.best().expect("a best exists");
        let optim1 = off(nu_p);
        let optim2 = off(&ev.optim2());
        eprintln!(
            "kept {first}/50 then {last}/50; distance expert {expert:.3}, Optim.1 {optim1:.3}, Optim.2 {optim2:.3}"
        );
        assert!(
            optim1 < 0.6 * expert && optim2 < 0.6 * expert,
            "distance to the optimum in range units: expert {expert:.3}, Optim.1 {optim1:.3}, Optim.2 {optim2:.3}"
        );
    }

    #[test]
    fn pipeline_depths_one_and_four_are_each_reproducible() {
        for depth in [1, 4] {
            let (exp, text) = physical_technical(30, depth);
            let a = run_to_end(&format!("depth{depth}-a"), exp.clone(), &text);
            let b = run_to_end(&format!("depth{depth}-b"), exp, &text);
            assert_eq!(a.evolve().history().len(), 30);
            assert_eq!(
                bits(a.evolve().history()),
                bits(b.evolve().history()),
                "D = {depth}"
            );
        }
    }

    #[test]
    fn a_journal_of_another_experiment_is_refused() {
        let dir = tmp("other");
        let (run, _) = Run::open(&dir, exp(), EXP, None).unwrap();
        drop(run);
        let other = EXP.replace("seed = 42", "seed = 43");
        let e = Run::open(&dir, Experiment::from_toml(&other).unwrap(), &other, None).unwrap_err();
        assert!(e.to_string().contains("another experiment"), "{e}");
        let finer = format!("{EXP}\n[physics]\nsubsteps = 8\n");
        let e = Run::open(&dir, Experiment::from_toml(&finer).unwrap(), &finer, None).unwrap_err();
        assert!(e.to_string().contains("physics"), "{e}");
    }

    /// A journal header written before `[physics]` existed resumes at the
    /// default physics; the run's trial requests carry the experiment's.
    #[test]
    fn physics_reach_the_requests_and_old_headers_read_the_default() {
        let dir = tmp("physics");
        let (run, _) = Run::open(&dir, exp(), EXP, None).unwrap();
        drop(run);
        let (_, replay) = crate::journal::Journal::open(&dir).unwrap();
        let Some(crate::journal::Record::Header {
            experiment_json, ..
        }) = replay.records.first()
        else {
            panic!("no header");
        };
        let mut v: serde_json::Value = serde_json::from_str(experiment_json).unwrap();
        assert!(v.as_object_mut().unwrap().remove("physics").is_some());
        let old: Experiment = serde_json::from_value(v).unwrap();
        assert_eq!(old, exp());
        let finer = format!("{EXP}\n[physics]\nsubsteps = 8\npgs_iterations = 6\n");
        let fe = Experiment::from_toml(&finer).unwrap();
        let (run, effects) = Run::open(&tmp("physics-b"), fe, &finer, None).unwrap();
        let req = effects
            .iter()
            .find_map(|e| match e {
                Effect::Dispatch(o, _) => Some(run.request(o, 0, 0)),
                _ => None,
            })
            .unwrap();
        assert_eq!(req.physics.substeps, 8);
        assert_eq!(req.physics.pgs_iterations, 6);
        assert_eq!(req.physics.solver_iterations, 1);
    }

    #[test]
    fn starting_from_an_earlier_history_uses_it() {
        let dir = tmp("from-a");
        let (mut run, effects) = Run::open(&dir, exp(), EXP, None).unwrap();
        drive_local(&mut run, effects, &synthetic, &mut |_| {}).unwrap();
        let imported = load_history(&dir).unwrap();
        assert_eq!(imported.history.len(), 40);
        assert!(imported.best.is_some());
        let dir2 = tmp("from-b");
        let text = EXP.replace("start = \"expert\"", "start = \"scratch\"");
        let (mut run2, effects) = Run::open(
            &dir2,
            Experiment::from_toml(&text).unwrap(),
            &text,
            Some(imported.clone()),
        )
        .unwrap();
        assert_eq!(run2.evolve().imported_len(), 40);
        assert_eq!(
            run2.evolve().best(),
            imported.best.as_ref(),
            "ν′ carries over"
        );
        drive_local(&mut run2, effects, &synthetic, &mut |_| {}).unwrap();
        let again = load_history(&dir2).unwrap();
        assert_eq!(again.history.len(), 80, "H accumulates");
    }
}
