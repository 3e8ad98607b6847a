//! The run's own thread: it owns the [`Run`] (journal, pickOut, CLOP) and
//! applies outcomes, failures and control actions in the order the service
//! sends them, so that CLOP's fits and draws and the journal's fsyncs never
//! hold up the service's event loop (leases, heartbeats, work requests).
//!
//! The service keeps a [`Snapshot`] of what it shows (status, history) and
//! the few facts it decides with (which trials are pending, who failed
//! them); the decider sends a new snapshot whenever it changes. Must not: talk
//! to zenoh or read a clock other than to time its own work.

use std::{collections::BTreeSet, sync::mpsc, thread::JoinHandle, time::Instant};

use protocol::{
    measurement::Measurement,
    wire::{Best, Control, IterationResult, TrialOutcome},
    Experiment,
};

use crate::{
    evolve::{Counted, OpenedIteration},
    run::{Effect, FailureVerdict, Run, RunError},
};

/// What the service shows of the run, as of the decider's last reply.
#[derive(Debug, Clone, PartialEq)]
pub struct Snapshot {
    /// Iterations opened.
    pub opened: u64,
    /// Iterations decided.
    pub decided: u64,
    /// ACCEPT, EQUIVALENT, REJECT counts.
    pub counts: (u64, u64, u64),
    /// ν′ (Optim.1).
    pub best: Option<Best>,
    /// CLOP's mean (Optim.2), named.
    pub optim2: Vec<(String, f64)>,
    /// Iterations decided when `optim2` was computed.
    pub optim2_decided: u64,
    /// Every planned iteration decided.
    pub finished: bool,
    /// The journaled priority.
    pub priority: u32,
    /// Journaled as paused.
    pub paused: bool,
}

/// A running coordinator refits CLOP's mean (Optim.2, which watchers see)
/// once every this many decisions: the fit costs more as the history grows
/// (at 3,000 outcomes it was most of the run's thread's CPU per decision).
pub const OPTIM2_EVERY: u64 = 10;

impl Snapshot {
    /// Reads it off `run`, CLOP's mean included.
    #[must_use]
    pub fn of(run: &Run) -> Self {
        Self::after(run, None)
    }

    /// Reads it off `run`; CLOP's mean is taken from `last` while the run
    /// goes on and fewer than [`OPTIM2_EVERY`] decisions came since it was
    /// computed.
    #[must_use]
    pub fn after(run: &Run, last: Option<&Snapshot>) -> Self {
        let ev = run.evolve();
        let decided = ev.decided();
        let finished = ev.finished();
        let (optim2, optim2_decided) = match last {
            Some(l) if !finished && decided < l.optim2_decided + OPTIM2_EVERY => {
                (l.optim2.clone(), l.optim2_decided)
            }
            _ => (ev.named(&ev.optim2()), decided),
        };
        Self {
            opened: ev.opened(),
            decided,
            counts: ev.counts(),
            best: ev.best_wire(),
            optim2,
            optim2_decided,
            finished,
            priority: run.priority(),
            paused: run.paused(),
        }
    }
}

/// An effect of the run, ready for the service to act on.
#[derive(Debug, Clone, PartialEq)]
pub enum Fx {
    /// Trials of an opened iteration to run (its parameters named, for the params topic).
    Open(OpenedIteration, Vec<u32>, Vec<(String, f64)>),
    /// An iteration was decided (as the results topic carries it).
    Decided(Box<IterationResult>),
    /// The run is complete.
    Finished,
}

/// Converts the run's effects (the service's initial ones included).
#[must_use]
pub fn effects(run: &Run, effects: Vec<Effect>) -> Vec<Fx> {
    let ev = run.evolve();
    effects
        .into_iter()
        .map(|e| match e {
            Effect::Dispatch(o, ks) => {
                let named = ev.named(&o.params);
                Fx::Open(o, ks, named)
            }
            Effect::Decided(d) => Fx::Decided(Box::new(result_of(run, &d))),
            Effect::Finished => Fx::Finished,
        })
        .collect()
}

/// A decided iteration as the results topic carries it.
#[must_use]
pub fn result_of(run: &Run, d: &crate::evolve::DecidedIteration) -> IterationResult {
    let ev = run.evolve();
    IterationResult {
        run: ev.experiment().name.clone(),
        iteration: d.iteration,
        params: ev.named(&d.params),
        stats: d.stats.clone(),
        decision: d.decision,
        best: d.best.as_ref().map(|b| ev.wire_best(b)),
    }
}

/// What the service asks of the run.
#[derive(Debug)]
pub enum Cmd {
    /// Apply an outcome the service took (the answer to the dispatch in
    /// flight, plausible, of the right seed); it comes back with the reply.
    Outcome(Box<TrialOutcome>),
    /// Journal a failure of a trial on a worker.
    Failure {
        /// Iteration.
        iteration: u64,
        /// Trial.
        trial: u32,
        /// The worker.
        worker: String,
        /// Why.
        reason: String,
    },
    /// Journal and apply a control action.
    Control {
        /// What.
        action: Control,
        /// Who asked.
        by: String,
        /// Handed back with the reply (which query to answer).
        tag: u64,
    },
    /// Journal the run's worker fingerprint (before any outcome of its
    /// workers: commands are applied in order). No reply unless it fails.
    Fingerprint {
        /// The fingerprint.
        fingerprint: u64,
        /// The pinning worker's naofarm version.
        version: String,
        /// The pinning worker.
        worker: String,
    },
}

/// The run's answers, in the order of the commands.
#[derive(Debug)]
pub enum Reply {
    /// An outcome was applied.
    Applied {
        /// The outcome (to publish, now that it is journaled).
        outcome: Box<TrialOutcome>,
        /// New or duplicate.
        counted: Counted,
        /// What follows from it.
        effects: Vec<Fx>,
        /// The state after it, when it changed (an iteration opened or was
        /// decided; computing it draws on CLOP, so not after every outcome).
        snapshot: Option<Box<Snapshot>>,
        /// Seconds the run took (journal, pickOut, CLOP).
        took_s: f64,
    },
    /// A failure was journaled (or ignored: the trial was no longer pending).
    Failed {
        /// Iteration.
        iteration: u64,
        /// Trial.
        trial: u32,
        /// The verdict.
        verdict: FailureVerdict,
    },
    /// A control action was journaled and applied, or refused.
    Controlled {
        /// The command's tag.
        tag: u64,
        /// The action.
        action: Control,
        /// Who asked.
        by: String,
        /// Refused with this reason, or done.
        result: Result<(), String>,
        /// The state after it.
        snapshot: Box<Snapshot>,
    },
    /// The run failed (the journal): the service stops with this.
    Fatal(RunError),
}

/// The decider thread and its channels.
pub struct Decider {
    /// Commands in.
    pub tx: mpsc::Sender<Cmd>,
    /// Replies out.
    pub rx: tokio::sync::mpsc::UnboundedReceiver<Reply>,
    /// The thread (joined once `tx` is dropped: everything sent is then
    /// applied); it returns the CPU seconds it used (Linux; `None` elsewhere).
    pub handle: JoinHandle<Option<f64>>,
}

impl Decider {
    /// Moves `run` onto its own thread.
    ///
    /// # Errors
    /// When the thread cannot be started.
    pub fn start(run: Run) -> std::io::Result<Self> {
        let (tx, cmds) = mpsc::channel::<Cmd>();
        let (out, rx) = tokio::sync::mpsc::unbounded_channel();
        let handle = std::thread::Builder::new()
            .name("naofarm-run".into())
            .spawn(move || {
                serve(run, &cmds, &out);
                thread_cpu_seconds()
            })?;
        Ok(Self { tx, rx, handle })
    }

    /// Stops taking commands and waits until everything sent is applied and
    /// the run (its journal and lock) is closed.
    pub fn finish(self) -> Option<f64> {
        drop(self.tx);
        self.handle.join().unwrap_or_else(|_| {
            tracing::error!("the run's thread panicked");
            None
        })
    }
}

/// Test hook, switched on at run time: `NAOFARM_FAULT_DECIDE_HOLD=MS@N` holds
/// the run's thread for MS milliseconds after it applied its N-th outcome (a
/// stand-in for a long CLOP fit), to show that the service keeps serving.
pub const HOLD_VAR: &str = "NAOFARM_FAULT_DECIDE_HOLD";

fn hold_hook() -> Option<(u64, u64)> {
    let v = std::env::var(HOLD_VAR).ok()?;
    let (ms, n) = v.split_once('@')?;
    Some((ms.parse().ok()?, n.parse().ok()?))
}

/// CPU time (user + system) the calling thread has used, from
/// `/proc/thread-self/stat` (Linux; clock ticks of 1/100 s). `None` elsewhere.
#[must_use]
pub fn thread_cpu_seconds() -> Option<f64> {
    crate::cpu::cpu_seconds_of("/proc/thread-self/stat")
}

fn serve(
    mut run: Run,
    cmds: &mpsc::Receiver<Cmd>,
    out: &tokio::sync::mpsc::UnboundedSender<Reply>,
) {
    let hold = hold_hook();
    let mut applied = 0u64;
    let mut last: Option<Snapshot> = None;
    while let Ok(cmd) = cmds.recv() {
        if let Some((ms, n)) = hold {
            if matches!(cmd, Cmd::Outcome { .. }) {
                applied += 1;
                if applied == n + 1 {
                    tracing::warn!(ms, "fault hook {HOLD_VAR}: the run's thread holds");
                    std::thread::sleep(std::time::Duration::from_millis(ms));
                    tracing::warn!("fault hook {HOLD_VAR}: the run's thread goes on");
                }
            }
        }
        let reply = match cmd {
            Cmd::Fingerprint {
                fingerprint,
                version,
                worker,
            } => match run.pin_fingerprint(fingerprint, &version, &worker) {
                Ok(()) => continue,
                Err(e) => Reply::Fatal(e),
            },
            Cmd::Outcome(o) => {
                let clock = Instant::now();
                match run.on_outcome(o.iteration, o.trial, o.seed, o.measurement(), &o.worker) {
                    Ok((counted, fx)) => {
                        let took_s = clock.elapsed().as_secs_f64();
                        let snapshot = (!fx.is_empty()).then(|| {
                            let s = Snapshot::after(&run, last.as_ref());
                            last = Some(s.clone());
                            Box::new(s)
                        });
                        Reply::Applied {
                            outcome: o,
                            counted,
                            effects: effects(&run, fx),
                            snapshot,
                            took_s,
                        }
                    }
                    Err(e) => Reply::Fatal(e),
                }
            }
            Cmd::Failure {
                iteration,
                trial,
                worker,
                reason,
            } => match run.on_failure(iteration, trial, &worker, &reason) {
                Ok(verdict) => Reply::Failed {
                    iteration,
                    trial,
                    verdict,
                },
                Err(e) => Reply::Fatal(e),
            },
            Cmd::Control { action, by, tag } => {
                let result = if run.evolve().finished() {
                    Err("the run is finished".to_string())
                } else {
                    match run.control(action, &by) {
                        Ok(()) => Ok(()),
                        Err(RunError::BadControl { why }) => Err(why),
                        Err(e) => {
                            let _ = out.send(Reply::Fatal(e));
                            return;
                        }
                    }
                };
                let s = Snapshot::of(&run);
                last = Some(s.clone());
                Reply::Controlled {
                    tag,
                    action,
                    by,
                    result,
                    snapshot: Box::new(s),
                }
            }
        };
        let fatal = matches!(reply, Reply::Fatal(_));
        if out.send(reply).is_err() || fatal {
            return;
        }
    }
}

/// What the service needs to know of the run besides the snapshot: fixed
/// facts, taken before the run moves to its thread.
#[derive(Debug, Clone)]
pub struct Facts {
    /// The effective experiment.
    pub experiment: Experiment,
    /// The run id.
    pub id: String,
    /// Per pending trial that failed: the workers that failed it.
    pub failed: std::collections::BTreeMap<(u64, u32), BTreeSet<String>>,
    /// Trials pending (opened, no outcome yet).
    pub pending: BTreeSet<(u64, u32)>,
    /// The fingerprint of the run's workers: the journaled one (a resumed
    /// run's), then the one the service pins for the run's first asker.
    pub fingerprint: Option<u64>,
}

impl Facts {
    /// Reads them off `run`.
    #[must_use]
    pub fn of(run: &Run) -> Self {
        let ev = run.evolve();
        let mut pending = BTreeSet::new();
        for (opened, missing) in ev.missing() {
            for k in missing {
                pending.insert((opened.iteration, k));
            }
        }
        let failed = pending
            .iter()
            .map(|&(i, k)| ((i, k), run.failed_workers(i, k)))
            .filter(|(_, w)| !w.is_empty())
            .collect();
        Self {
            experiment: ev.experiment().clone(),
            id: run.id().to_string(),
            failed,
            pending,
            fingerprint: run.fingerprint(),
        }
    }
}

/// Checks an outcome the service is about to take: the seed of that trial
/// and the measurement's numbers (the run would refuse otherwise).
pub fn check(
    opened: &OpenedIteration,
    trial: u32,
    seed: u64,
    m: &Measurement,
) -> Result<(), String> {
    match opened.seeds.get(trial as usize) {
        None => return Err("no such trial".into()),
        Some(s) if *s != seed => return Err("wrong seed".into()),
        Some(_) => {}
    }
    m.check()
}
