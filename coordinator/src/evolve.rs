//! The evolving process (evolve.md, Algorithms 1 and 2) as a pure state machine.
//!
//! [`Evolve`] owns CLOP, ν′ and H. It emits [`Action`]s (open an iteration,
//! an iteration was decided, the run is finished) and takes trial outcomes in
//! any order, any number of times. Iteration `i` is opened exactly when
//! iteration `i − D` is decided (D = pipeline depth), so the parameter set of
//! iteration `i` is drawn from exactly the iterations `0..=i−D`, whatever the
//! timing; iterations are decided in order, and fed to CLOP in order. The
//! whole run is therefore a pure function of the experiment, its seed and the
//! set of trial outcomes.

use protocol::{
    experiment::{Experiment, PickOutConstants, Start},
    wire::{Best, Decision, Stats},
};
use serde::{Deserialize, Serialize};

use crate::clop::{Clop, Dim, Outcome};

/// What one trial returned (the part of a `TrialOutcome` that counts).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrialResult {
    /// Whether the robot fell.
    pub fell: bool,
    /// Final torso x (forward), m.
    pub x_m: f64,
    /// Final torso y (left), m.
    pub y_m: f64,
    /// Time of the fall, s.
    pub fall_time_s: Option<f64>,
    /// Simulated time, s.
    pub sim_time_s: f64,
    /// Worker that ran it (informative only; never influences decisions).
    pub worker: String,
}

impl TrialResult {
    /// Checks the numbers are finite and consistent.
    pub fn check(&self) -> Result<(), String> {
        for (name, v) in [
            ("x_m", self.x_m),
            ("y_m", self.y_m),
            ("sim_time_s", self.sim_time_s),
        ] {
            if !v.is_finite() {
                return Err(format!("{name} is {v}"));
            }
        }
        if self.fall_time_s.is_some_and(|t| !t.is_finite()) {
            return Err("fall_time_s is not finite".into());
        }
        Ok(())
    }
}

/// Statistics of an iteration (evolve.md "(ours)": m and e over the successful
/// trials, my = mean |y|, sample standard deviation; e absent with < 2 successes).
#[must_use]
pub fn stats(trials: &[TrialResult]) -> Stats {
    let ok: Vec<&TrialResult> = trials.iter().filter(|t| !t.fell).collect();
    let mean = |v: &[f64]| {
        #[allow(clippy::cast_precision_loss)]
        let n = v.len() as f64;
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / n)
    };
    let sd = |v: &[f64]| {
        #[allow(clippy::cast_precision_loss)]
        let n = v.len() as f64;
        (v.len() >= 2).then(|| {
            let m = v.iter().sum::<f64>() / n;
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
        })
    };
    let xs: Vec<f64> = ok.iter().map(|t| t.x_m).collect();
    let ys: Vec<f64> = ok.iter().map(|t| t.y_m.abs()).collect();
    let all_x: Vec<f64> = trials.iter().map(|t| t.x_m).collect();
    let all_y: Vec<f64> = trials.iter().map(|t| t.y_m.abs()).collect();
    let n = u32::try_from(trials.len()).unwrap_or(u32::MAX);
    let k = u32::try_from(ok.len()).unwrap_or(u32::MAX);
    Stats {
        trials: n,
        successes: k,
        s: if n == 0 {
            0.0
        } else {
            f64::from(k) / f64::from(n)
        },
        mx: mean(&xs),
        my: mean(&ys),
        ex: sd(&xs),
        ey: sd(&ys),
        mx_all: mean(&all_x).unwrap_or(0.0),
        my_all: mean(&all_y).unwrap_or(0.0),
    }
}

/// pickOut (Algorithm 2). `best` is ν′ (None while undefined).
///
/// Rules of ours: no successful trial or mx ≤ 0 is REJECT; an ex that is
/// absent (fewer than 2 successes) counts as 0.
#[must_use]
pub fn pick_out(nu: &Stats, best: Option<&Stats>, k: &PickOutConstants) -> Decision {
    let (Some(mx), Some(my)) = (nu.mx, nu.my) else {
        return Decision::Reject;
    };
    if nu.s < k.success_rate {
        return Decision::Reject; // line 1
    }
    if mx <= 0.0 {
        return Decision::Reject; // (ours)
    }
    if my / mx > k.xy_ratio {
        return Decision::Reject; // line 2
    }
    let Some(best) = best else {
        return Decision::Accept; // line 3
    };
    let bmx = best.mx.unwrap_or(0.0);
    let bex = best.ex.unwrap_or(0.0);
    let ex = nu.ex.unwrap_or(0.0);
    if mx < bmx - k.alpha * bex {
        Decision::Reject // line 4
    } else if mx < bmx - k.beta * bex {
        Decision::Equivalent // line 5
    } else if ex < k.gamma * bex {
        Decision::Accept // line 6
    } else if mx < bmx {
        Decision::Equivalent // line 7
    } else {
        Decision::Accept // line 8
    }
}

/// SplitMix64 finaliser: the one seed-mixing function of the run.
#[must_use]
pub fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The seed of trial k of iteration i: a function of (run seed, i, k) only.
#[must_use]
pub fn trial_seed(run_seed: u64, iteration: u64, trial: u32) -> u64 {
    mix(mix(mix(run_seed) ^ iteration) ^ (u64::from(trial) | 0x5452_0000_0000_0000))
}

fn clop_seed(run_seed: u64, iteration: u64) -> u64 {
    mix(mix(mix(run_seed ^ 0x434c_4f50) ^ iteration))
}

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
    /// ν′ after the decision: (iteration, params, stats).
    pub best: Option<(u64, Vec<f64>, Stats)>,
}

/// A history imported from an earlier run (`--from RUN_DIR`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct Imported {
    /// (p, h) pairs in their order, p in external units.
    pub history: Vec<(Vec<f64>, Decision)>,
    /// The earlier run's ν′.
    pub best: Option<(u64, Vec<f64>, Stats)>,
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
    results: Vec<Option<TrialResult>>,
}

/// The evolving loop.
#[derive(Debug, Clone, PartialEq)]
pub struct Evolve {
    exp: Experiment,
    clop: Clop,
    pending: std::collections::BTreeMap<u64, Pending>,
    next_open: u64,
    decided: u64,
    best: Option<(u64, Vec<f64>, Stats)>,
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
        for (p, h) in &imported.history {
            let u = clop.to_internal(p);
            clop.tell(&u, to_outcome(*h));
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
        r: &TrialResult,
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
        r: TrialResult,
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
            let results: Vec<TrialResult> = p.results.into_iter().flatten().collect();
            let st = stats(&results);
            let decision = pick_out(&st, self.best.as_ref().map(|b| &b.2), &self.exp.pickout);
            if decision == Decision::Accept {
                self.best = Some((i, p.opened.params.clone(), st.clone()));
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
    pub fn best(&self) -> Option<&(u64, Vec<f64>, Stats)> {
        self.best.as_ref()
    }

    /// CLOP's mean recommendation (Optim.2), external units.
    #[must_use]
    pub fn optim2(&self) -> Vec<f64> {
        self.clop.to_external(&self.clop.mean())
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
                .map(|d| (d.params.clone(), d.decision))
                .collect(),
            best: self.best.clone(),
        }
    }

    /// ν′ in wire form.
    #[must_use]
    pub fn best_wire(&self) -> Option<Best> {
        self.best.as_ref().map(|(i, p, s)| Best {
            iteration: *i,
            params: self.named(p),
            stats: s.clone(),
        })
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
mod tests {
    use super::*;

    fn st(s: f64, mx: Option<f64>, my: f64, ex: Option<f64>) -> Stats {
        Stats {
            trials: 10,
            successes: 10,
            s,
            mx,
            my: mx.map(|_| my),
            ex,
            ey: None,
            mx_all: mx.unwrap_or(0.0),
            my_all: my,
        }
    }

    #[test]
    fn pick_out_every_line_and_edge() {
        use Decision::{Accept as A, Equivalent as E, Reject as R};
        let k = PickOutConstants::default();
        let best = st(1.0, Some(2.0), 0.1, Some(0.1));
        let zero_e = st(1.0, Some(2.0), 0.1, Some(0.0));
        let cases: Vec<(&str, Stats, Option<&Stats>, Decision)> = vec![
            (
                "line 1: s below SUCCESS_RATE",
                st(0.7, Some(3.0), 0.1, Some(0.1)),
                Some(&best),
                R,
            ),
            (
                "line 1 edge: s exactly SUCCESS_RATE passes",
                st(0.75, Some(3.0), 0.1, Some(0.01)),
                Some(&best),
                A,
            ),
            ("ours: no success", st(0.0, None, 0.0, None), None, R),
            ("ours: mx <= 0", st(1.0, Some(0.0), 0.0, Some(0.1)), None, R),
            ("ours: mx < 0", st(1.0, Some(-1.0), 0.0, Some(0.1)), None, R),
            (
                "line 2: my/mx above XY_RATIO",
                st(1.0, Some(1.0), 0.26, Some(0.1)),
                None,
                R,
            ),
            (
                "line 2 edge: my/mx exactly XY_RATIO passes",
                st(1.0, Some(1.0), 0.25, Some(0.1)),
                None,
                A,
            ),
            (
                "line 3: no best yet",
                st(1.0, Some(0.5), 0.1, Some(0.1)),
                None,
                A,
            ),
            (
                "line 4: far below",
                st(1.0, Some(1.69), 0.1, Some(0.1)),
                Some(&best),
                R,
            ),
            (
                "line 5: below by more than beta e",
                st(1.0, Some(1.85), 0.1, Some(0.01)),
                Some(&best),
                E,
            ),
            (
                "line 6: within beta e and more precise",
                st(1.0, Some(1.95), 0.1, Some(0.05)),
                Some(&best),
                A,
            ),
            (
                "line 7: within beta e, less precise, below",
                st(1.0, Some(1.95), 0.1, Some(0.2)),
                Some(&best),
                E,
            ),
            (
                "line 8: above, less precise",
                st(1.0, Some(2.05), 0.1, Some(0.2)),
                Some(&best),
                A,
            ),
            (
                "e'x = 0: below is REJECT",
                st(1.0, Some(1.99), 0.1, Some(0.0)),
                Some(&zero_e),
                R,
            ),
            (
                "e'x = 0: equal is ACCEPT",
                st(1.0, Some(2.0), 0.1, Some(0.0)),
                Some(&zero_e),
                A,
            ),
            (
                "e'x = 0: above is ACCEPT",
                st(1.0, Some(2.1), 0.1, Some(0.3)),
                Some(&zero_e),
                A,
            ),
        ];
        for (name, nu, b, want) in cases {
            assert_eq!(pick_out(&nu, b, &k), want, "{name}");
        }
    }

    #[test]
    fn stats_over_successful_trials() {
        let t = |fell, x: f64, y: f64| TrialResult {
            fell,
            x_m: x,
            y_m: y,
            fall_time_s: fell.then_some(1.0),
            sim_time_s: 10.0,
            worker: String::new(),
        };
        let s = stats(&[
            t(false, 1.0, -0.2),
            t(false, 3.0, 0.2),
            t(true, 0.1, 0.0),
            t(false, 2.0, 0.2),
        ]);
        assert_eq!(s.successes, 3);
        assert_eq!(s.s, 0.75);
        assert_eq!(s.mx, Some(2.0));
        assert!((s.my.unwrap() - 0.2).abs() < 1e-12, "my is the mean of |y|");
        assert_eq!(s.ex, Some(1.0), "sample sd (n - 1)");
        assert!((s.mx_all - 1.525).abs() < 1e-12);
        let one = stats(&[t(false, 1.0, 0.0)]);
        assert_eq!(one.ex, None);
    }

    #[test]
    fn seeds_depend_only_on_run_iteration_trial() {
        assert_eq!(trial_seed(1, 2, 3), trial_seed(1, 2, 3));
        assert_ne!(trial_seed(1, 2, 3), trial_seed(1, 3, 2));
        assert_ne!(trial_seed(1, 2, 3), trial_seed(2, 2, 3));
    }
}
