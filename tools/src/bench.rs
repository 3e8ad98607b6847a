//! The CLOP benchmark harness: simple regret on the artificial problems of
//! `docs/spec/clop.md` §11, CLOP beside baselines on the same outcome streams, and the
//! cost of one tell+ask as the history grows. A benchmark, not the optimiser:
//! it reads the clock (only in [`cost`]).

use protocol::experiment::ClopSettings;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use coordinator::clop::{Clop, Dim, Outcome};
use protocol::seed::mix;

use crate::problems::Problem;

/// An optimiser under test.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Algorithm {
    /// CLOP with the benchmark configuration of §11 (mean recommendation).
    Clop,
    /// Uniform random search: √N points, √N games each, best empirical mean.
    Random,
    /// CMA-ES, each candidate scored by a batch of games; recommends its mean.
    Cmaes,
}

impl Algorithm {
    /// Parses `clop` or `random`.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "clop" => Ok(Self::Clop),
            "random" => Ok(Self::Random),
            "cmaes" => Ok(Self::Cmaes),
            o => Err(format!("unknown algorithm `{o}` (clop, cmaes, random)")),
        }
    }
}

/// One row of the regret table.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// Problem name.
    pub problem: String,
    /// Algorithm.
    pub algorithm: Algorithm,
    /// Games played.
    pub budget: u64,
    /// Independent runs.
    pub runs: usize,
    /// Mean simple regret f* − f(x̂).
    pub mean_regret: f64,
    /// Median simple regret.
    pub median_regret: f64,
    /// 90th percentile of the simple regret.
    pub p90_regret: f64,
}

/// The problem's outcome stream of run `r`: the same for every algorithm.
fn outcome_rng(seed: u64, run: usize) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(mix(seed ^ mix(run as u64)))
}

fn play(p: Problem, u: &[f64], rng: &mut ChaCha8Rng) -> Outcome {
    if rng.random::<f64>() < p.f(u) {
        Outcome::Win
    } else {
        Outcome::Loss
    }
}

/// CLOP's settings in the paper's benchmark scripts (§11).
#[must_use]
pub fn benchmark_settings() -> ClopSettings {
    ClopSettings {
        max_weight_iterations: 0,
        ..ClopSettings::default()
    }
}

/// One CLOP run: regret of the mean recommendation at each budget (ascending).
#[must_use]
pub fn clop_run(
    p: Problem,
    budgets: &[u64],
    seed: u64,
    run: usize,
    settings: ClopSettings,
) -> Vec<f64> {
    let mut c = Clop::new(vec![Dim::linear(-1.0, 1.0); p.dim()], settings);
    let mut rng = outcome_rng(seed, run);
    let ask_seed = mix(seed ^ 0xA5A5 ^ mix(run as u64 + 1));
    let mut out = Vec::new();
    let mut played = 0u64;
    for &b in budgets {
        while played < b {
            let u = c.ask(mix(ask_seed ^ played));
            let o = play(p, &u, &mut rng);
            c.tell(&u, o);
            played += 1;
        }
        out.push(p.f_star() - p.f(&c.mean()));
    }
    out
}

/// Games per CMA-ES candidate at budget `b`: about √b / λ, so that a run
/// holds about √b generations.
#[must_use]
#[allow(
    clippy::cast_precision_loss,
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss
)]
pub fn cmaes_batch(b: u64, lambda: usize) -> u64 {
    (((b as f64).sqrt() / lambda as f64).round() as u64).max(1)
}

/// One CMA-ES run per budget (the batch size depends on the budget): the
/// regret of its mean after the last whole generation within the budget.
#[must_use]
pub fn cmaes_run(p: Problem, b: u64, seed: u64, run: usize) -> f64 {
    let mut rng = outcome_rng(seed, run);
    let mut es = crate::cmaes::Cmaes::new(p.dim(), mix(seed ^ 0xC3A5 ^ mix(run as u64 + 1)));
    let batch = cmaes_batch(b, es.lambda());
    let per_generation = batch * es.lambda() as u64;
    let mut played = 0;
    while played + per_generation <= b {
        let cands = es.ask();
        let fitness: Vec<f64> = cands
            .iter()
            .map(|c| {
                let u = crate::cmaes::Cmaes::clamp(c);
                let wins = (0..batch)
                    .filter(|_| play(p, &u, &mut rng) == Outcome::Win)
                    .count();
                #[allow(clippy::cast_precision_loss)]
                let mean = wins as f64 / batch as f64;
                mean
            })
            .collect();
        es.tell(&cands, &fitness);
        played += per_generation;
    }
    p.f_star() - p.f(&es.recommend())
}

/// One random-search run at budget `b`.
#[must_use]
pub fn random_run(p: Problem, b: u64, seed: u64, run: usize) -> f64 {
    let mut rng = outcome_rng(seed, run);
    let mut pick = ChaCha8Rng::seed_from_u64(mix(seed ^ 0x5A5A ^ mix(run as u64 + 1)));
    #[allow(
        clippy::cast_precision_loss,
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss
    )]
    let per = ((b as f64).sqrt().floor() as u64).max(1);
    let mut best = (f64::NEG_INFINITY, vec![0.0; p.dim()]);
    let mut played = 0;
    while played + per <= b.max(per) {
        let u: Vec<f64> = (0..p.dim()).map(|_| pick.random_range(-1.0..1.0)).collect();
        let wins = (0..per)
            .filter(|_| play(p, &u, &mut rng) == Outcome::Win)
            .count();
        #[allow(clippy::cast_precision_loss)]
        let mean = wins as f64 / per as f64;
        if mean > best.0 {
            best = (mean, u);
        }
        played += per;
    }
    p.f_star() - p.f(&best.1)
}

fn summarise(problem: Problem, algorithm: Algorithm, budget: u64, mut v: Vec<f64>) -> Row {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    #[allow(clippy::cast_precision_loss)]
    let mean = v.iter().sum::<f64>() / n.max(1) as f64;
    let q = |f: f64| {
        #[allow(
            clippy::cast_precision_loss,
            clippy::cast_possible_truncation,
            clippy::cast_sign_loss
        )]
        let i = ((n.saturating_sub(1)) as f64 * f).round() as usize;
        v.get(i).copied().unwrap_or(f64::NAN)
    };
    Row {
        problem: problem.name(),
        algorithm,
        budget,
        runs: n,
        mean_regret: mean,
        median_regret: q(0.5),
        p90_regret: q(0.9),
    }
}

/// Runs the regret benchmark over `runs` independent runs on `threads` threads.
#[must_use]
pub fn regret(
    p: Problem,
    budgets: &[u64],
    runs: usize,
    seed: u64,
    algorithms: &[Algorithm],
    threads: usize,
) -> Vec<Row> {
    let mut budgets = budgets.to_vec();
    budgets.sort_unstable();
    let threads = threads.max(1);
    let mut rows = Vec::new();
    for &alg in algorithms {
        let per_run: Vec<Vec<f64>> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..threads)
                .map(|t| {
                    let budgets = &budgets;
                    s.spawn(move || {
                        (t..runs)
                            .step_by(threads)
                            .map(|r| match alg {
                                Algorithm::Clop => {
                                    (r, clop_run(p, budgets, seed, r, benchmark_settings()))
                                }
                                Algorithm::Random => (
                                    r,
                                    budgets.iter().map(|&b| random_run(p, b, seed, r)).collect(),
                                ),
                                Algorithm::Cmaes => (
                                    r,
                                    budgets.iter().map(|&b| cmaes_run(p, b, seed, r)).collect(),
                                ),
                            })
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            let mut all: Vec<(usize, Vec<f64>)> = handles
                .into_iter()
                .flat_map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
                .collect();
            all.sort_by_key(|(r, _)| *r);
            all.into_iter().map(|(_, v)| v).collect()
        });
        for (bi, &b) in budgets.iter().enumerate() {
            rows.push(summarise(
                p,
                alg,
                b,
                per_run.iter().map(|v| v[bi]).collect(),
            ));
        }
    }
    rows
}

/// Cost of one tell+ask with `n` games already told, dimension `d`.
#[derive(Debug, Clone, Serialize)]
pub struct CostRow {
    /// Dimension.
    pub d: usize,
    /// History size before the measured step.
    pub n: u64,
    /// Refresh rate (0 = after every outcome).
    pub refresh_rate: f64,
    /// Mean seconds per tell+ask over the measured steps.
    pub seconds_per_step: f64,
}

/// Measures tell+ask cost at history sizes `ns`, `steps` steps each.
#[must_use]
pub fn cost(d: usize, ns: &[u64], refresh_rate: f64, steps: u64, seed: u64) -> Vec<CostRow> {
    let p = if d == 1 {
        Problem::Log
    } else {
        Problem::LogX(d)
    };
    let mut c = Clop::new(vec![Dim::linear(-1.0, 1.0); d], ClopSettings::default());
    let mut rng = outcome_rng(seed, 0);
    let mut rows = Vec::new();
    let mut played = 0;
    let mut ns = ns.to_vec();
    ns.sort_unstable();
    for n in ns {
        // Grow the history cheaply: outcomes told at sampled points without timing.
        while played < n {
            let u = c.ask(played);
            let o = play(p, &u, &mut rng);
            c.tell(&u, o);
            played += 1;
        }
        let start = std::time::Instant::now();
        let mut probe = c.clone().with_refresh_rate(refresh_rate);
        for k in 0..steps {
            let u = probe.ask(n + k);
            let o = play(p, &u, &mut rng);
            probe.tell(&u, o);
        }
        #[allow(clippy::cast_precision_loss)]
        let per = start.elapsed().as_secs_f64() / steps.max(1) as f64;
        rows.push(CostRow {
            d,
            n,
            refresh_rate,
            seconds_per_step: per,
        });
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clop_regret_on_log_falls_with_the_budget() {
        let rows = regret(Problem::Log, &[100, 2000], 16, 1, &[Algorithm::Clop], 2);
        assert_eq!(rows.len(), 2);
        assert!(rows[1].mean_regret < rows[0].mean_regret, "{rows:?}");
        assert!(rows[1].mean_regret < 0.01, "{rows:?}");
    }

    #[test]
    fn cmaes_improves_on_the_centre_with_a_budget() {
        // At the centre of the box Log's regret is f* − f(0); CMA-ES must do better.
        let centre = Problem::Log.f_star() - Problem::Log.f(&[0.0]);
        let rows = regret(Problem::Log, &[2000], 16, 1, &[Algorithm::Cmaes], 2);
        assert!(rows[0].mean_regret < centre, "{rows:?} vs centre {centre}");
        assert!(rows[0].mean_regret.is_finite());
    }

    #[test]
    fn the_same_seed_gives_the_same_regrets_whatever_the_threads() {
        let algs = [Algorithm::Random, Algorithm::Clop];
        let bits = |rows: &[Row]| -> Vec<(u64, u64, u64)> {
            rows.iter()
                .map(|r| {
                    (
                        r.mean_regret.to_bits(),
                        r.median_regret.to_bits(),
                        r.p90_regret.to_bits(),
                    )
                })
                .collect()
        };
        let one = regret(Problem::Rosenbrock, &[200], 6, 1, &algs, 1);
        let three = regret(Problem::Rosenbrock, &[200], 6, 1, &algs, 3);
        assert_eq!(
            bits(&one),
            bits(&three),
            "the streams are per (seed, run), not per thread"
        );
        let other = regret(Problem::Rosenbrock, &[200], 6, 2, &algs, 1);
        assert_ne!(bits(&one), bits(&other), "another seed, other streams");
        assert!(one
            .iter()
            .all(|r| r.mean_regret >= 0.0 && r.mean_regret < 0.5));
    }
}
