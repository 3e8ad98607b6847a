//! The evolving process (`docs/spec/evolve.md`, Algorithms 1 and 2) as a pure state machine.
//!
//! [`Evolve`] owns CLOP, ν′ and H. It emits [`Action`]s (open an iteration,
//! an iteration was decided, the run is finished) and takes trial outcomes in
//! any order, any number of times. Iteration `i` is opened exactly when
//! iteration `i − D` is decided (D = pipeline depth), so the parameter set of
//! iteration `i` is drawn from exactly the iterations `0..=i−D`, whatever the
//! timing; iterations are decided in order, and fed to CLOP in order. The
//! whole run is therefore a pure function of the experiment, its seed and the
//! set of trial outcomes.

pub use protocol::measurement::Measurement;
pub use protocol::pickout::{pick_out, stats, HistoryPoint, Incumbent};
use protocol::{
    experiment::{Experiment, Start},
    wire::{Best, Decision, Stats},
};
use serde::{Deserialize, Serialize};

use crate::clop::{Clop, Dim, Outcome};

use protocol::seed::clop_seed;
pub use protocol::seed::{mix, trial_seed};

/// An iteration handed out for trials.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OpenedIteration {
    /// Iteration index.
    pub iteration: u64,
    /// Parameter set p, optimised parameters in external units (CLOP order).
    pub params: Vec<f64>,
    /// Seeds of its trials, by trial index.
    pub seeds: Vec<u64>,
    /// Whether this is the expert set (start from expert values).
    pub expert: bool,
}

/// An entry of the decided history.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DecidedIteration {
    /// Iteration index.
    pub iteration: u64,
    /// Its parameter set (external units, CLOP order).
    pub params: Vec<f64>,
    /// Its statistics.
    pub stats: Stats,
    /// pickOut's decision.
    pub decision: Decision,
    /// ν′ after the decision.
    pub best: Option<Incumbent>,
}

/// A history as bits (iterations, parameters, decisions and statistics), for
/// comparing two histories exactly: equal bits, equal histories.
#[must_use]
pub fn history_bits(h: &[DecidedIteration]) -> Vec<u64> {
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

/// A history imported from an earlier run (`--from RUN_DIR`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Imported {
    /// H's (p, h) pairs in their order, p in external units.
    pub history: Vec<HistoryPoint>,
    /// The earlier run's ν′.
    pub best: Option<Incumbent>,
}

/// What the driver must do next.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Journal this iteration, then dispatch its trials.
    Open(OpenedIteration),
    /// Journal this decision, then publish it.
    Decided(DecidedIteration),
    /// Every planned iteration is decided.
    Finished,
}

/// Why an outcome was not taken.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OutcomeError {
    /// The iteration is not open (never opened, or already decided and dropped).
    #[error("iteration {0} is not open")]
    UnknownIteration(u64),
    /// The trial index is out of range.
    #[error("iteration {iteration} has no trial {trial}")]
    UnknownTrial {
        /// Iteration.
        iteration: u64,
        /// Trial index.
        trial: u32,
    },
    /// The seed does not match the one the trial was issued with.
    #[error("trial {iteration}/{trial}: seed {got} does not match {expected}")]
    WrongSeed {
        /// Iteration.
        iteration: u64,
        /// Trial index.
        trial: u32,
        /// Seed received.
        got: u64,
        /// Seed issued.
        expected: u64,
    },
    /// A number is not finite.
    #[error("trial {iteration}/{trial}: {why}")]
    Invalid {
        /// Iteration.
        iteration: u64,
        /// Trial index.
        trial: u32,
        /// What is wrong.
        why: String,
    },
}

/// How an accepted outcome was counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Counted {
    /// A new outcome: journal it (then apply with [`Evolve::apply`]).
    New,
    /// Already have it: ignore.
    Duplicate,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Pending {
    opened: OpenedIteration,
    internal: Vec<f64>,
    results: Vec<Option<Measurement>>,
}

/// The evolving loop.
#[derive(Debug, Clone, PartialEq)]
pub struct Evolve {
    exp: Experiment,
    clop: Clop,
    pending: std::collections::BTreeMap<u64, Pending>,
    next_open: u64,
    decided: u64,
    best: Option<Incumbent>,
    history: Vec<DecidedIteration>,
    imported_len: usize,
}

impl Evolve {
    /// Starts a run; returns the loop and the first actions (the first D iterations).
    #[must_use]
    pub fn start(exp: Experiment, imported: &Imported) -> (Self, Vec<Action>) {
        let dims = exp
            .parameter
            .iter()
            .map(|p| Dim {
                kind: p.kind,
                lo: p.lower,
                hi: p.upper,
            })
            .collect();
        let mut clop = Clop::new(dims, exp.clop);
        for h in &imported.history {
            let u = clop.to_internal(&h.params);
            clop.tell(&u, to_outcome(h.decision));
        }
        let mut ev = Self {
            exp,
            clop,
            pending: std::collections::BTreeMap::new(),
            next_open: 0,
            decided: 0,
            best: imported.best.clone(),
            history: Vec::new(),
            imported_len: imported.history.len(),
        };
        let mut actions = Vec::new();
        let depth = u64::from(ev.exp.pipeline_depth).min(ev.exp.iterations);
        for _ in 0..depth {
            actions.push(Action::Open(ev.open_next()));
        }
        (ev, actions)
    }

    fn open_next(&mut self) -> OpenedIteration {
        let i = self.next_open;
        self.next_open += 1;
        let expert = i == 0 && self.exp.start == Start::Expert;
        let (internal, params) = if expert {
            let v = self.exp.expert_values();
            (self.clop.to_internal(&v), v)
        } else {
            let u = self.clop.ask(clop_seed(self.exp.seed, i));
            let v = self.clop.to_external(&u);
            (u, v)
        };
        let seeds = (0..self.exp.trials_per_iteration)
            .map(|k| trial_seed(self.exp.seed, i, k))
            .collect();
        let opened = OpenedIteration {
            iteration: i,
            params,
            seeds,
            expert,
        };
        self.pending.insert(
            i,
            Pending {
                opened: opened.clone(),
                internal,
                results: vec![None; self.exp.trials_per_iteration as usize],
            },
        );
        opened
    }

    /// Checks an outcome without changing anything: new, duplicate, or refused.
    pub fn classify(
        &self,
        iteration: u64,
        trial: u32,
        seed: u64,
        r: &Measurement,
    ) -> Result<Counted, OutcomeError> {
        let p = self
            .pending
            .get(&iteration)
            .ok_or(OutcomeError::UnknownIteration(iteration))?;
        let slot = p
            .results
            .get(trial as usize)
            .ok_or(OutcomeError::UnknownTrial { iteration, trial })?;
        let expected = p.opened.seeds[trial as usize];
        if seed != expected {
            return Err(OutcomeError::WrongSeed {
                iteration,
                trial,
                got: seed,
                expected,
            });
        }
        r.check().map_err(|why| OutcomeError::Invalid {
            iteration,
            trial,
            why,
        })?;
        Ok(if slot.is_some() {
            Counted::Duplicate
        } else {
            Counted::New
        })
    }

    /// Takes an outcome (already journaled when it is new) and returns what follows.
    pub fn apply(
        &mut self,
        iteration: u64,
        trial: u32,
        seed: u64,
        r: Measurement,
    ) -> Result<Vec<Action>, OutcomeError> {
        if self.classify(iteration, trial, seed, &r)? == Counted::Duplicate {
            return Ok(Vec::new());
        }
        if let Some(p) = self.pending.get_mut(&iteration) {
            p.results[trial as usize] = Some(r);
        }
        Ok(self.decide_ready())
    }

    fn decide_ready(&mut self) -> Vec<Action> {
        let mut actions = Vec::new();
        loop {
            let i = self.decided;
            let complete = self
                .pending
                .get(&i)
                .is_some_and(|p| p.results.iter().all(Option::is_some));
            if !complete {
                break;
            }
            let Some(p) = self.pending.remove(&i) else {
                break;
            };
            let results: Vec<Measurement> = p.results.into_iter().flatten().collect();
            let st = stats(&results);
            let decision = pick_out(&st, self.best.as_ref().map(|b| &b.stats), &self.exp.pickout);
            if decision == Decision::Accept {
                self.best = Some(Incumbent {
                    iteration: i,
                    params: p.opened.params.clone(),
                    stats: st.clone(),
                });
            }
            self.clop.tell(&p.internal, to_outcome(decision));
            self.decided += 1;
            let d = DecidedIteration {
                iteration: i,
                params: p.opened.params,
                stats: st,
                decision,
                best: self.best.clone(),
            };
            self.history.push(d.clone());
            actions.push(Action::Decided(d));
            if self.next_open < self.exp.iterations {
                actions.push(Action::Open(self.open_next()));
            }
            if self.decided == self.exp.iterations {
                actions.push(Action::Finished);
            }
        }
        actions
    }

    /// The experiment.
    #[must_use]
    pub fn experiment(&self) -> &Experiment {
        &self.exp
    }

    /// The decided history of this run (without imported entries).
    #[must_use]
    pub fn history(&self) -> &[DecidedIteration] {
        &self.history
    }

    /// Number of decided iterations.
    #[must_use]
    pub fn decided(&self) -> u64 {
        self.decided
    }

    /// Number of opened iterations.
    #[must_use]
    pub fn opened(&self) -> u64 {
        self.next_open
    }

    /// Whether every planned iteration is decided.
    #[must_use]
    pub fn finished(&self) -> bool {
        self.decided >= self.exp.iterations
    }

    /// Whether trial `trial` of iteration `iteration` is open and without an outcome.
    #[must_use]
    pub fn is_pending(&self, iteration: u64, trial: u32) -> bool {
        self.pending
            .get(&iteration)
            .and_then(|p| p.results.get(trial as usize))
            .is_some_and(Option::is_none)
    }

    /// The parameter set of an open iteration.
    #[must_use]
    pub fn open_params(&self, iteration: u64) -> Option<&[f64]> {
        self.pending
            .get(&iteration)
            .map(|p| p.opened.params.as_slice())
    }

    /// Open iterations and the trial indices still without an outcome.
    #[must_use]
    pub fn missing(&self) -> Vec<(OpenedIteration, Vec<u32>)> {
        self.pending
            .values()
            .map(|p| {
                let ks = p
                    .results
                    .iter()
                    .enumerate()
                    .filter(|(_, r)| r.is_none())
                    .filter_map(|(k, _)| u32::try_from(k).ok())
                    .collect();
                (p.opened.clone(), ks)
            })
            .collect()
    }

    /// ν′ (Optim.1): iteration, params, stats.
    #[must_use]
    pub fn best(&self) -> Option<&Incumbent> {
        self.best.as_ref()
    }

    /// CLOP's mean recommendation (Optim.2), external units.
    #[must_use]
    pub fn optim2(&self) -> Vec<f64> {
        self.clop.to_external(&self.clop.mean())
    }

    /// The parameter sets Table IV names, in its order: `Expert` (the
    /// experiment's), `Optim.1` (ν′, once an iteration was accepted or a
    /// history imported one) and `Optim.2` (CLOP's mean); external units,
    /// CLOP's order. `naofarm report` runs these, and `naofarm trial --set`
    /// picks one by name.
    #[must_use]
    pub fn table_sets(&self) -> Vec<(&'static str, Vec<f64>)> {
        let [expert, optim1, optim2] = TABLE_SETS;
        let mut sets = vec![(expert, self.exp.expert_values())];
        sets.extend(self.best.as_ref().map(|b| (optim1, b.params.clone())));
        sets.push((optim2, self.optim2()));
        sets
    }

    /// Decision counts (accept, equivalent, reject) of this run.
    #[must_use]
    pub fn counts(&self) -> (u64, u64, u64) {
        let c = |d| self.history.iter().filter(|h| h.decision == d).count() as u64;
        (
            c(Decision::Accept),
            c(Decision::Equivalent),
            c(Decision::Reject),
        )
    }

    /// Number of imported (p, h) pairs.
    #[must_use]
    pub fn imported_len(&self) -> usize {
        self.imported_len
    }

    /// The full H of this run: imported pairs are not included.
    #[must_use]
    pub fn to_imported(&self) -> Imported {
        Imported {
            history: self
                .history
                .iter()
                .map(|d| HistoryPoint {
                    params: d.params.clone(),
                    decision: d.decision,
                })
                .collect(),
            best: self.best.clone(),
        }
    }

    /// ν′ in wire form.
    #[must_use]
    pub fn best_wire(&self) -> Option<Best> {
        self.best.as_ref().map(|b| self.wire_best(b))
    }

    /// ν′ as watchers see it (parameters by name).
    #[must_use]
    pub fn wire_best(&self, b: &Incumbent) -> Best {
        Best {
            iteration: b.iteration,
            params: self.named(&b.params),
            stats: b.stats.clone(),
        }
    }

    /// Pairs parameter names with values (CLOP order).
    #[must_use]
    pub fn named(&self, values: &[f64]) -> Vec<(String, f64)> {
        self.exp
            .parameter
            .iter()
            .zip(values)
            .map(|(p, v)| (p.name.clone(), *v))
            .collect()
    }
}

/// The names of Table IV's sets, in its order ([`Evolve::table_sets`]).
pub const TABLE_SETS: [&str; 3] = ["Expert", "Optim.1", "Optim.2"];

/// ACCEPT = Win, EQUIVALENT = Draw, REJECT = Loss.
#[must_use]
pub fn to_outcome(d: Decision) -> Outcome {
    match d {
        Decision::Accept => Outcome::Win,
        Decision::Equivalent => Outcome::Draw,
        Decision::Reject => Outcome::Loss,
    }
}

#[cfg(test)]
mod tests;
