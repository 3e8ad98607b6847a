//! `naofarm bench clop`: the CLOP regret table and the cost per step.

use anyhow::anyhow;
use clap::Args;
use coordinator::{
    bench::{self, Algorithm},
    problems::Problem,
};

use crate::cli::{BenchCommand, Failure};

/// Arguments of `bench clop`.
#[derive(Args, Debug)]
pub struct ClopBenchArgs {
    /// Problem (log, flat, power, angle, step, rosenbrock, correlated, log2, log5, rosenbrock2, rosenbrock5, correlated2, or all).
    #[arg(long, default_value = "log")]
    problem: String,
    /// Budgets in games, comma-separated.
    #[arg(long, default_value = "100,1000", value_delimiter = ',')]
    budgets: Vec<u64>,
    /// Independent runs per problem and algorithm.
    #[arg(long, default_value_t = 50)]
    runs: usize,
    /// Seed of the outcome streams and samplers.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Algorithms, comma-separated (clop, random).
    #[arg(long, default_value = "clop,random", value_delimiter = ',')]
    algorithms: Vec<String>,
    /// Also measure the cost of one tell+ask at n = 100, 1000, 5000 for d = 1 and 5.
    #[arg(long)]
    cost: bool,
    /// Machine-readable output.
    #[arg(long)]
    json: bool,
}

pub fn bench(cmd: BenchCommand) -> Result<(), Failure> {
    match cmd {
        BenchCommand::Clop(a) => clop(&a),
        BenchCommand::Sim(a) => crate::robot::bench_sim(&a),
    }
}

fn clop(a: &ClopBenchArgs) -> Result<(), Failure> {
    let problems = if a.problem == "all" {
        Problem::all()
    } else {
        vec![Problem::parse(&a.problem).map_err(|e| Failure::Usage(anyhow!(e)))?]
    };
    let algs = a
        .algorithms
        .iter()
        .map(|s| Algorithm::parse(s))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| Failure::Usage(anyhow!(e)))?;
    if a.runs == 0 || a.budgets.contains(&0) {
        return Err(Failure::Usage(anyhow!(
            "--runs and every budget must be at least 1"
        )));
    }
    let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    let mut rows = Vec::new();
    for p in problems {
        rows.extend(bench::regret(p, &a.budgets, a.runs, a.seed, &algs, threads));
    }
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&rows).map_err(|e| Failure::Job(e.into()))?
        );
    } else {
        println!(
            "{:<12} {:<8} {:>8} {:>5} {:>12} {:>12} {:>12}",
            "problem", "algo", "budget", "runs", "mean regret", "median", "p90"
        );
        for r in &rows {
            println!(
                "{:<12} {:<8} {:>8} {:>5} {:>12.5} {:>12.5} {:>12.5}",
                r.problem,
                format!("{:?}", r.algorithm).to_lowercase(),
                r.budget,
                r.runs,
                r.mean_regret,
                r.median_regret,
                r.p90_regret
            );
        }
    }
    if a.cost {
        println!(
            "{:<4} {:>6} {:>8} {:>16}",
            "d", "n", "refresh", "µs per tell+ask"
        );
        for d in [1, 5] {
            for rate in [0.1, 0.0] {
                for r in bench::cost(d, &[100, 1000, 5000], rate, 20, a.seed) {
                    println!(
                        "{:<4} {:>6} {:>8} {:>16.1}",
                        r.d,
                        r.n,
                        r.refresh_rate,
                        r.seconds_per_step * 1e6
                    );
                }
            }
        }
    }
    Ok(())
}
