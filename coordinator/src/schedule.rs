//! Who runs which trial, and when a trial goes back to the queue: the
//! coordinator service's scheduling as a pure part. The caller passes `now`
//! (tokio's clock, so tests run it under `tokio::time::pause()`); nothing here
//! reads a clock, sends a message or touches the journal.
//!
//! Workers pull: a trial is queued until a worker asking for work takes it
//! ([`Scheduler::take`], at most the asker's free slots); it is
//! *in flight* on that worker until the worker answers, its lease passes
//! ([`Scheduler::tick`]), or the worker goes (token dropped, or silent for
//! four silence periods). Workers that failed a trial, or let its lease pass,
//! are avoided for it while another live worker exists, and for one silence
//! period after it failed; workers set aside get no work. Must not: decide
//! whether an outcome counts (the run does) or block.

use std::{
    collections::{BTreeMap, BTreeSet, HashMap},
    time::Duration,
};

use tokio::time::Instant;

/// A trial: (iteration, trial index).
pub type TrialId = (u64, u32);

#[derive(Debug, Clone)]
struct WorkerInfo {
    slots: u32,
    assigned: BTreeSet<TrialId>,
    last_seen: Instant,
}

#[derive(Debug, Clone)]
struct Inflight {
    worker: String,
    dispatch: u64,
    deadline: Instant,
}

/// Whether an answer is for the dispatch in flight.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Answer {
    /// It answers the dispatch in flight on that worker.
    Held,
    /// No such worker is known (a stranger, or one already gone).
    UnknownWorker,
    /// The trial is not in flight (never sent, already answered, lease passed).
    NotInFlight,
    /// The trial is in flight on another worker.
    OtherWorker,
    /// The worker holds the trial, but under another dispatch id.
    WrongDispatch,
}

impl Answer {
    /// A short name, for counters and logs.
    #[must_use]
    pub fn reason(self) -> &'static str {
        match self {
            Self::Held => "held",
            Self::UnknownWorker => "unknown worker",
            Self::NotInFlight => "trial not in flight",
            Self::OtherWorker => "trial held by another worker",
            Self::WrongDispatch => "wrong dispatch id",
        }
    }
}

/// What passing time did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Tick {
    /// Trials whose lease passed, with the worker that held them (re-queued
    /// when the caller still wants them: [`Scheduler::enqueue`]).
    pub expired: Vec<(TrialId, String)>,
    /// Workers silent for four silence periods: the caller treats them as gone.
    pub silent: Vec<String>,
}

/// The scheduling state of one run.
#[derive(Debug, Clone)]
pub struct Scheduler {
    lease: Duration,
    silence: Duration,
    queue: BTreeSet<TrialId>,
    inflight: HashMap<TrialId, Inflight>,
    workers: BTreeMap<String, WorkerInfo>,
    set_aside: BTreeSet<String>,
    /// A failed trial is not offered again to a worker that failed it before this.
    hold: HashMap<TrialId, Instant>,
    /// Workers a trial's lease passed on: avoided for it like those that failed it.
    expired_on: HashMap<TrialId, BTreeSet<String>>,
    /// When each queued trial became ready.
    ready_since: HashMap<TrialId, Instant>,
    /// Ready → taken, per trial taken since the last [`Scheduler::drain_latencies`].
    latencies: Vec<Duration>,
}

impl Scheduler {
    /// A scheduler giving each dispatch `lease`, and work only to workers heard
    /// from within `silence`.
    #[must_use]
    pub fn new(lease: Duration, silence: Duration) -> Self {
        Self {
            lease,
            silence,
            queue: BTreeSet::new(),
            inflight: HashMap::new(),
            workers: BTreeMap::new(),
            set_aside: BTreeSet::new(),
            hold: HashMap::new(),
            expired_on: HashMap::new(),
            ready_since: HashMap::new(),
            latencies: Vec::new(),
        }
    }

    /// How long each trial taken since the last call waited, ready → taken.
    pub fn drain_latencies(&mut self) -> Vec<Duration> {
        std::mem::take(&mut self.latencies)
    }

    /// A worker was heard from: its heartbeat (with its slots), or its
    /// liveliness token (`None`: one slot until its first heartbeat).
    pub fn worker_seen(&mut self, id: &str, slots: Option<u32>, now: Instant) {
        let w = self
            .workers
            .entry(id.to_string())
            .or_insert_with(|| WorkerInfo {
                slots: 1,
                assigned: BTreeSet::new(),
                last_seen: now,
            });
        if let Some(s) = slots {
            w.slots = s;
        }
        w.last_seen = now;
    }

    /// Worker `id` says it is running the dispatches `running`: the leases of
    /// its trials in flight under those ids start again from `now`, so a
    /// trial longer than its lease stays with a worker that keeps speaking.
    /// A trial it no longer names keeps its lease and comes back when that
    /// passes.
    pub fn renew(&mut self, id: &str, running: &[u64], now: Instant) {
        let Some(w) = self.workers.get(id) else {
            return;
        };
        for t in &w.assigned {
            if let Some(f) = self.inflight.get_mut(t) {
                if f.worker == id && running.contains(&f.dispatch) {
                    f.deadline = now + self.lease;
                }
            }
        }
    }

    /// A worker is gone: returns the trials it held (no longer in flight).
    pub fn worker_gone(&mut self, id: &str) -> Vec<TrialId> {
        let Some(w) = self.workers.remove(id) else {
            return Vec::new();
        };
        w.assigned
            .into_iter()
            .filter(|t| self.inflight.remove(t).is_some())
            .collect()
    }

    /// Queues a trial to run (again), ready from `now`.
    pub fn enqueue(&mut self, t: TrialId, now: Instant) {
        if !self.inflight.contains_key(&t) && self.queue.insert(t) {
            self.ready_since.insert(t, now);
        }
    }

    /// The trial is done (decided or no longer wanted): off the queue and out of flight.
    pub fn forget(&mut self, t: TrialId) {
        self.queue.remove(&t);
        self.ready_since.remove(&t);
        self.hold.remove(&t);
        self.expired_on.remove(&t);
        if let Some(f) = self.inflight.remove(&t) {
            if let Some(w) = self.workers.get_mut(&f.worker) {
                w.assigned.remove(&t);
            }
        }
    }

    /// `by` answered trial `t` echoing `dispatch` (an outcome or a failure):
    /// whether that answers the dispatch in flight, sent to `by`. Only then is
    /// the trial out of flight; `by` was heard from either way.
    pub fn answered(&mut self, t: TrialId, by: &str, dispatch: u64, now: Instant) -> Answer {
        let Some(w) = self.workers.get_mut(by) else {
            return Answer::UnknownWorker;
        };
        w.last_seen = now;
        match self.inflight.get(&t) {
            None => Answer::NotInFlight,
            Some(f) if f.worker != by => Answer::OtherWorker,
            Some(f) if f.dispatch != dispatch => Answer::WrongDispatch,
            Some(_) => {
                self.inflight.remove(&t);
                w.assigned.remove(&t);
                Answer::Held
            }
        }
    }

    /// Trial `t` just failed on a worker: it is queued again, and offered to a
    /// worker that already failed it only one silence period from now (other
    /// workers, or ones joining meanwhile, get it first).
    pub fn failed(&mut self, t: TrialId, now: Instant) {
        self.hold.insert(t, now + self.silence);
        self.enqueue(t, now);
    }

    /// Sets a worker aside: it gets no more work.
    pub fn set_aside(&mut self, id: &str) {
        self.set_aside.insert(id.to_string());
    }

    /// Expires leases and finds silent workers.
    pub fn tick(&mut self, now: Instant) -> Tick {
        let mut expired: Vec<(TrialId, String)> = self
            .inflight
            .iter()
            .filter(|(_, f)| f.deadline <= now)
            .map(|(t, f)| (*t, f.worker.clone()))
            .collect();
        expired.sort();
        for (t, id) in &expired {
            self.inflight.remove(t);
            if let Some(w) = self.workers.get_mut(id) {
                w.assigned.remove(t);
            }
            self.expired_on.entry(*t).or_default().insert(id.clone());
        }
        let silent = self
            .workers
            .iter()
            .filter(|(_, w)| now.saturating_duration_since(w.last_seen) > self.silence * 4)
            .map(|(id, _)| id.clone())
            .collect();
        Tick { expired, silent }
    }

    fn usable(&self, id: &str, w: &WorkerInfo, now: Instant) -> bool {
        now.saturating_duration_since(w.last_seen) <= self.silence && !self.set_aside.contains(id)
    }

    /// Worker `id` asks for up to `want` trials: hands it queued trials, at
    /// most its free slots, each under a new dispatch id from `new_id`. A trial
    /// that failed on `id` (`failed(t)`), or whose lease passed on it, waits for
    /// another live worker while one exists, and for one silence period after
    /// the failure in any case. A set-aside worker gets nothing. The trials are
    /// in flight on `id` until `now + lease`. The asker counts as heard from.
    pub fn take(
        &mut self,
        id: &str,
        slots: u32,
        want: u32,
        now: Instant,
        failed: &dyn Fn(TrialId) -> BTreeSet<String>,
        new_id: &mut dyn FnMut() -> u64,
    ) -> Vec<(TrialId, u64)> {
        self.worker_seen(id, Some(slots), now);
        if self.set_aside.contains(id) {
            return Vec::new();
        }
        let free = self.workers.get(id).map_or(0, |w| {
            u64::from(w.slots).saturating_sub(w.assigned.len() as u64)
        });
        let room = usize::try_from(free.min(u64::from(want))).unwrap_or(usize::MAX);
        // Choose first (the queue in order, no more than the room), then take.
        let picked: Vec<TrialId> = self
            .queue
            .iter()
            .copied()
            .filter(|&t| {
                let mut failed = failed(t);
                failed.extend(self.expired_on.get(&t).into_iter().flatten().cloned());
                if !failed.contains(id) {
                    return true;
                }
                let held = self.hold.get(&t).is_some_and(|until| now < *until);
                let fresh_exists = self
                    .workers
                    .iter()
                    .any(|(w, info)| self.usable(w, info, now) && !failed.contains(w));
                !(held || fresh_exists)
            })
            .take(room)
            .collect();
        let mut out = Vec::with_capacity(picked.len());
        for t in picked {
            self.queue.remove(&t);
            if let Some(since) = self.ready_since.remove(&t) {
                self.latencies.push(now.saturating_duration_since(since));
            }
            if let Some(w) = self.workers.get_mut(id) {
                w.assigned.insert(t);
            }
            let dispatch = new_id();
            self.inflight.insert(
                t,
                Inflight {
                    worker: id.to_string(),
                    dispatch,
                    deadline: now + self.lease,
                },
            );
            out.push((t, dispatch));
        }
        out
    }

    /// Trials queued, ready to hand out.
    #[must_use]
    pub fn ready(&self) -> usize {
        self.queue.len()
    }

    /// Trials in flight.
    #[must_use]
    pub fn in_flight(&self) -> usize {
        self.inflight.len()
    }

    /// Workers holding at least one trial.
    #[must_use]
    pub fn serving(&self) -> usize {
        self.workers
            .values()
            .filter(|w| !w.assigned.is_empty())
            .count()
    }

    /// Workers known (live or not yet swept).
    #[must_use]
    pub fn workers(&self) -> usize {
        self.workers.len()
    }

    /// Trials held by `id`.
    #[must_use]
    pub fn held_by(&self, id: &str) -> usize {
        self.workers.get(id).map_or(0, |w| w.assigned.len())
    }

    /// Whether `t` is queued.
    #[must_use]
    pub fn is_queued(&self, t: TrialId) -> bool {
        self.queue.contains(&t)
    }

    /// The dispatch id `t` is in flight under.
    #[must_use]
    pub fn dispatch_of(&self, t: TrialId) -> Option<u64> {
        self.inflight.get(&t).map(|f| f.dispatch)
    }

    /// The worker `t` is in flight on.
    #[must_use]
    pub fn holder(&self, t: TrialId) -> Option<&str> {
        self.inflight.get(&t).map(|f| f.worker.as_str())
    }
}

#[cfg(test)]
mod tests;
