//! What the page shows, rebuilt from the fleet's topics: every run's status,
//! history and experiment, every worker's status, and whether the fleet
//! answers. Pure (the caller gives the time), so that the rules — when a
//! worker leaves the list, what a run's share is — are tested without a
//! network.

use std::{
    collections::BTreeMap,
    time::{Duration, Instant},
};

use protocol::{
    wire::{IterationResult, RunState, RunStatus, WorkerStatus},
    Experiment,
};
use serde_json::{json, Value};

/// A worker not heard from for this long leaves the list (it publishes its
/// status every second; its liveliness token going removes it at once).
pub const WORKER_SILENCE: Duration = Duration::from_millis(3500);

/// One run as the page knows it.
pub struct RunEntry {
    /// Its last status.
    pub status: RunStatus,
    /// Its decided iterations by index.
    pub history: BTreeMap<u64, IterationResult>,
    /// Its experiment, once its coordinator answered.
    pub experiment: Option<Experiment>,
    /// Its coordinator's liveliness token went (the run ended or its
    /// coordinator stopped); the last status stays shown.
    pub gone: bool,
    /// Since when the status has counted decisions the page lacks.
    gap_since: Option<Instant>,
}

/// How long a gap in a run's history may last before its history is asked
/// for again: a decision's result and the status after it travel apart, so
/// a status may come first; a result that was lost leaves a gap that stays.
pub const GAP_PATIENCE: Duration = Duration::from_secs(2);

impl RunEntry {
    /// Iterations decided that the page has not got.
    #[must_use]
    pub fn missing(&self) -> bool {
        (self.history.len() as u64) < self.status.decided
    }
}

/// One worker as the page knows it.
pub struct WorkerEntry {
    /// Its last status.
    pub status: WorkerStatus,
    /// When it was last heard from.
    pub heard: Instant,
}

/// The fleet as the page knows it.
#[derive(Default)]
pub struct Fleet {
    /// Whether the session reaches a router or peer.
    pub connected: bool,
    /// Runs by id.
    pub runs: BTreeMap<String, RunEntry>,
    /// Workers by id.
    pub workers: BTreeMap<String, WorkerEntry>,
}

/// What a new message asks the caller to do next.
#[derive(Debug, PartialEq, Eq)]
pub enum Ask {
    /// Nothing.
    Nothing,
    /// Ask this run's coordinator for its history (and experiment, if unknown).
    History,
}

impl Fleet {
    /// A run's status (published or answered) at `now`: whether to ask for
    /// its history (and experiment) — a new run, or a gap in its history
    /// older than [`GAP_PATIENCE`].
    pub fn status(&mut self, s: RunStatus, now: Instant) -> Ask {
        let id = s.id.clone();
        let entry = self.runs.entry(id).or_insert_with(|| RunEntry {
            status: s.clone(),
            history: BTreeMap::new(),
            experiment: None,
            gone: false,
            gap_since: None,
        });
        entry.status = s;
        entry.gone = false;
        if !entry.missing() {
            entry.gap_since = None;
        }
        let stale = entry.missing()
            && now.saturating_duration_since(*entry.gap_since.get_or_insert(now)) >= GAP_PATIENCE;
        if entry.experiment.is_none() || stale {
            entry.gap_since = None;
            Ask::History
        } else {
            Ask::Nothing
        }
    }

    /// A decided iteration of run `id`; whether it is news.
    pub fn result(&mut self, id: &str, r: IterationResult) -> bool {
        let Some(entry) = self.runs.get_mut(id) else {
            return false;
        };
        if r.run != entry.status.run {
            return false;
        }
        entry.history.insert(r.iteration, r).is_none()
    }

    /// Run `id`'s history and experiment, as its coordinator answered.
    pub fn history(&mut self, id: &str, h: Vec<IterationResult>, exp: Option<Experiment>) {
        if let Some(entry) = self.runs.get_mut(id) {
            for r in h {
                if r.run == entry.status.run {
                    entry.history.insert(r.iteration, r);
                }
            }
            if exp.is_some() {
                entry.experiment = exp;
            }
        }
    }

    /// Run `id`'s coordinator is there (again).
    pub fn coordinator_back(&mut self, id: &str) {
        if let Some(entry) = self.runs.get_mut(id) {
            entry.gone = false;
        }
    }

    /// Run `id`'s coordinator went away.
    pub fn coordinator_gone(&mut self, id: &str) {
        if let Some(entry) = self.runs.get_mut(id) {
            entry.gone = true;
        }
    }

    /// A worker's status.
    pub fn worker(&mut self, w: WorkerStatus, now: Instant) {
        self.workers.insert(
            w.worker.clone(),
            WorkerEntry {
                status: w,
                heard: now,
            },
        );
    }

    /// A worker's liveliness token went.
    pub fn worker_gone(&mut self, id: &str) -> bool {
        self.workers.remove(id).is_some()
    }

    /// Forgets workers silent for [`WORKER_SILENCE`]; whether any went.
    pub fn expire(&mut self, now: Instant) -> bool {
        let before = self.workers.len();
        self.workers
            .retain(|_, w| now.saturating_duration_since(w.heard) < WORKER_SILENCE);
        self.workers.len() != before
    }

    /// The fleet page's data: every run with its share, every worker, the
    /// utilisation.
    #[must_use]
    #[allow(clippy::cast_precision_loss)]
    pub fn snapshot(&self, now: Instant) -> Value {
        let slots: u64 = self
            .workers
            .values()
            .map(|w| u64::from(w.status.slots))
            .sum();
        let busy: u64 = self
            .workers
            .values()
            .map(|w| u64::from(w.status.busy))
            .sum();
        let mut held: BTreeMap<&str, u64> = BTreeMap::new();
        for w in self.workers.values() {
            for (run, n) in &w.status.runs {
                *held.entry(run.as_str()).or_default() += u64::from(*n);
            }
        }
        let competing = |e: &RunEntry| !e.gone && e.status.state == RunState::Running;
        let priorities: u64 = self
            .runs
            .values()
            .filter(|e| competing(e))
            .map(|e| u64::from(e.status.priority))
            .sum();
        let mut by_name: Vec<&RunEntry> = self.runs.values().collect();
        by_name.sort_by(|a, b| (&a.status.run, &a.status.id).cmp(&(&b.status.run, &b.status.id)));
        let runs: Vec<Value> = by_name
            .into_iter()
            .map(|e| {
                let s = &e.status;
                let in_flight = held.get(s.id.as_str()).copied().unwrap_or(0);
                let fair = (competing(e) && priorities > 0)
                    .then(|| f64::from(s.priority) / priorities as f64);
                json!({
                    "run": s.run,
                    "id": s.id,
                    "state": if e.gone && !s.finished && self.connected { "gone".into() } else { state_name(s.state) },
                    "priority": s.priority,
                    "decided": s.decided,
                    "planned": s.planned,
                    "accepts": s.accepts,
                    "equivalents": s.equivalents,
                    "rejects": s.rejects,
                    "best_mx": s.best.as_ref().and_then(|b| b.stats.mx),
                    "best_s": s.best.as_ref().map(|b| b.stats.s),
                    "trials_per_s": s.trials_per_s,
                    "in_flight": in_flight,
                    "share": (busy > 0).then(|| in_flight as f64 / busy as f64),
                    "fair_share": fair,
                })
            })
            .collect();
        let workers: Vec<Value> = self
            .workers
            .values()
            .map(|w| {
                let s = &w.status;
                let names: Vec<Value> = s
                    .runs
                    .iter()
                    .map(|(id, n)| {
                        let name = self
                            .runs
                            .get(id)
                            .map_or(id.as_str(), |e| e.status.run.as_str());
                        json!({"id": id, "run": name, "held": n})
                    })
                    .collect();
                json!({
                    "worker": s.worker,
                    "host": s.host,
                    "slots": s.slots,
                    "busy": s.busy,
                    "fingerprint": s.fingerprint,
                    "version": s.version,
                    "runs": names,
                    "trials": s.trials,
                    "refused": s.refused,
                    "programs": s.programs,
                    "heard_s_ago": now.saturating_duration_since(w.heard).as_secs_f64(),
                })
            })
            .collect();
        json!({
            "connected": self.connected,
            "slots": slots,
            "busy": busy,
            "utilisation": (slots > 0).then(|| busy as f64 / slots as f64),
            "runs": runs,
            "workers": workers,
        })
    }
}

/// A run state as the topics spell it.
fn state_name(s: RunState) -> Value {
    serde_json::to_value(s).unwrap_or_else(|_| Value::String(format!("{s:?}").to_lowercase()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::wire::{Decision, Stats};

    fn status(id: &str, priority: u32, decided: u64) -> RunStatus {
        RunStatus {
            run: format!("run-{id}"),
            id: id.into(),
            priority,
            state: RunState::Running,
            planned: 10,
            opened: decided,
            decided,
            accepts: decided,
            equivalents: 0,
            rejects: 0,
            best: None,
            optim2: Vec::new(),
            optim2_decided: 0,
            workers: 1,
            trials_per_s: 1.0,
            finished: false,
            failures: Vec::new(),
            refused: Vec::new(),
        }
    }

    fn worker(id: &str, slots: u32, runs: &[(&str, u32)]) -> WorkerStatus {
        WorkerStatus {
            worker: id.into(),
            host: "h".into(),
            slots,
            busy: runs.iter().map(|r| r.1).sum(),
            fingerprint: "0123456789abcdef".into(),
            version: "0.1.0".into(),
            runs: runs.iter().map(|(r, n)| ((*r).to_string(), *n)).collect(),
            trials: 3,
            refused: 0,
            programs: vec![],
            containment: String::new(),
        }
    }

    fn experiment() -> Experiment {
        let text = "name = \"run-a\"\nseed = 1\niterations = 10\nmodel = \"synthetic\"\n\n\
                    [[parameter]]\nname = \"ThighRelHip2_Z\"\nlower = -0.08\nupper = -0.03\nexpert = -0.04\n";
        Experiment::from_toml(text).unwrap()
    }

    fn result(run: &str, i: u64) -> IterationResult {
        IterationResult {
            run: run.into(),
            iteration: i,
            params: vec![("ThighRelHip2_Z".into(), -0.05)],
            stats: Stats {
                trials: 1,
                successes: 1,
                s: 1.0,
                mx: Some(1.0),
                my: Some(0.0),
                ex: None,
                ey: None,
                mx_all: 1.0,
                my_all: 0.0,
            },
            decision: Decision::Accept,
            best: None,
        }
    }

    /// Shares of the slots in use against the shares by priority, among the
    /// runs that compete (a paused run has no fair share).
    #[test]
    fn a_runs_share_is_its_trials_in_flight_against_its_prioritys() {
        let mut f = Fleet::default();
        let now = Instant::now();
        f.status(status("a", 3, 0), now);
        f.status(status("b", 1, 0), now);
        let mut paused = status("c", 4, 0);
        paused.state = RunState::Paused;
        f.status(paused, now);
        f.worker(worker("w1", 8, &[("a", 6), ("b", 2)]), now);
        let v = f.snapshot(now);
        assert_eq!(v["utilisation"], 1.0);
        let runs = v["runs"].as_array().unwrap();
        assert_eq!(runs[0]["share"], 0.75);
        assert_eq!(runs[0]["fair_share"], 0.75);
        assert_eq!(runs[1]["fair_share"], 0.25);
        assert_eq!(runs[2]["fair_share"], Value::Null);
        assert_eq!(runs[2]["state"], "paused");
        assert_eq!(v["workers"][0]["runs"][0]["run"], "run-a");
    }

    /// A worker leaves the list when its token goes, or when it has been
    /// silent for [`WORKER_SILENCE`].
    #[test]
    fn a_worker_leaves_when_its_token_goes_or_it_falls_silent() {
        let mut f = Fleet::default();
        let t0 = Instant::now();
        f.worker(worker("w1", 2, &[]), t0);
        f.worker(worker("w2", 2, &[]), t0);
        assert!(f.worker_gone("w1"));
        assert!(!f.expire(t0 + Duration::from_secs(3)));
        assert!(f.expire(t0 + WORKER_SILENCE));
        assert!(f.workers.is_empty());
    }

    /// A new run's history is asked for at once; a gap, once it has lasted
    /// [`GAP_PATIENCE`] (a status may come before its decision's result);
    /// results of another run's name are not taken.
    #[test]
    fn a_gap_in_the_history_that_stays_asks_for_it_again() {
        let mut f = Fleet::default();
        let t0 = Instant::now();
        assert_eq!(f.status(status("a", 1, 2), t0), Ask::History);
        assert!(f.result("a", result("run-a", 0)));
        assert!(!f.result("a", result("run-a", 0)));
        assert!(!f.result("a", result("other", 1)));
        assert!(!f.result("nobody", result("run-a", 1)));
        f.history(
            "a",
            vec![result("run-a", 0), result("run-a", 1)],
            Some(experiment()),
        );
        assert!(!f.runs["a"].missing());
        assert_eq!(f.status(status("a", 1, 2), t0), Ask::Nothing);
        // Iteration 2's status before its result: no question yet.
        assert_eq!(f.status(status("a", 1, 3), t0), Ask::Nothing);
        assert!(f.result("a", result("run-a", 2)));
        assert_eq!(f.status(status("a", 1, 3), t0 + GAP_PATIENCE), Ask::Nothing);
        // Iteration 3's result is lost: asked once the gap has lasted.
        assert_eq!(f.status(status("a", 1, 4), t0), Ask::Nothing);
        assert_eq!(
            f.status(status("a", 1, 4), t0 + GAP_PATIENCE / 2),
            Ask::Nothing
        );
        assert_eq!(f.status(status("a", 1, 4), t0 + GAP_PATIENCE), Ask::History);
        f.connected = true;
        f.coordinator_gone("a");
        assert_eq!(f.snapshot(Instant::now())["runs"][0]["state"], "gone");
        f.coordinator_back("a");
        assert_eq!(f.snapshot(Instant::now())["runs"][0]["state"], "running");
    }
}
