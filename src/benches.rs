//! `naofarm bench clop` (the CLOP regret table and the cost per step) and
//! `naofarm bench farm` (throughput of real coordinator and worker processes).

use anyhow::anyhow;
use clap::Args;
use tools::{
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
    /// Algorithms, comma-separated (clop, cmaes, random).
    #[arg(long, default_value = "clop,cmaes,random", value_delimiter = ',')]
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
        BenchCommand::Farm(a) => farm(&a),
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
        outln!(
            "{}",
            serde_json::to_string_pretty(&rows).map_err(|e| Failure::Job(e.into()))?
        );
    } else {
        outln!(
            "{:<12} {:<8} {:>8} {:>5} {:>12} {:>12} {:>12}",
            "problem",
            "algo",
            "budget",
            "runs",
            "mean regret",
            "median",
            "p90"
        );
        for r in &rows {
            outln!(
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
        outln!(
            "{:<4} {:>6} {:>8} {:>16}",
            "d",
            "n",
            "refresh",
            "µs per tell+ask"
        );
        for d in [1, 5] {
            for rate in [0.1, 0.0] {
                for r in bench::cost(d, &[100, 1000, 5000], rate, 20, a.seed) {
                    outln!(
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

/// Arguments of `bench farm`.
#[derive(Args, Debug)]
pub struct FarmBenchArgs {
    /// Worker processes (one slot each) for the zero-cost synthetic runs.
    #[arg(long, default_value = "1,4,16", value_delimiter = ',')]
    workers: Vec<u32>,
    /// Iterations of each synthetic run (10 trials each, pipeline depth 4).
    #[arg(long, default_value_t = 150)]
    iterations: u64,
    /// Iterations of the NAO runs with 1 and 2 workers (0: skip them).
    #[arg(long, default_value_t = 4)]
    nao_iterations: u64,
    /// The experiment whose space and constants the runs use (the model is set per case).
    #[arg(long, default_value = "experiments/physical-technical.toml")]
    experiment: std::path::PathBuf,
    /// Machine-readable output.
    #[arg(long)]
    json: bool,
}

/// One measured farm run.
#[derive(Debug, serde::Serialize)]
struct FarmRow {
    model: &'static str,
    workers: u32,
    trials: u64,
    wall_s: f64,
    trials_per_s: f64,
    coordinator_cpu_s: Option<f64>,
    coordinator_cpu_per_trial_ms: Option<f64>,
}

/// Kills the worker processes however the bench ends.
struct Workers(Vec<std::process::Child>);

impl Drop for Workers {
    fn drop(&mut self) {
        for c in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Runs `naofarm coordinator` with `workers` worker processes on a free
/// loopback port and reads its final JSON line.
fn farm_case(
    experiment: &std::path::Path,
    model: &'static str,
    workers: u32,
    iterations: u64,
) -> anyhow::Result<FarmRow> {
    use std::process::{Command, Stdio};
    let exe = std::env::current_exe()?;
    let port = crate::net::free_loopback_port()?;
    let endpoint = format!("tcp/127.0.0.1:{port}");
    let out = std::env::temp_dir().join(format!(
        "naofarm-bench-farm-{}-{model}-{workers}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&out);
    let mut pool = Workers(Vec::new());
    for _ in 0..workers {
        pool.0.push(
            Command::new(&exe)
                .args(["worker", "--slots", "1", "--connect", &endpoint])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()?,
        );
    }
    let started = std::time::Instant::now();
    let done = Command::new(&exe)
        .arg("coordinator")
        .arg(experiment)
        .arg("--out")
        .arg(&out)
        .args(["--json", "--model", model, "--listen", &endpoint])
        .args(["--iterations", &iterations.to_string()])
        .output()?;
    let wall_s = started.elapsed().as_secs_f64();
    drop(pool);
    let _ = std::fs::remove_dir_all(&out);
    if !done.status.success() {
        return Err(anyhow!(
            "the coordinator failed ({}): {}",
            done.status,
            String::from_utf8_lossy(&done.stderr)
        ));
    }
    let stdout = String::from_utf8_lossy(&done.stdout);
    let finished: serde_json::Value = stdout
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .find(|v| v["event"] == "finished")
        .ok_or_else(|| anyhow!("the coordinator printed no final line"))?;
    let trials = finished["accepted"].as_u64().unwrap_or(0);
    let cpu = finished["cpu_s"].as_f64();
    #[allow(clippy::cast_precision_loss)]
    let per_trial = |x: f64| if trials > 0 { x / trials as f64 } else { 0.0 };
    Ok(FarmRow {
        model,
        workers,
        trials,
        wall_s,
        trials_per_s: finished["status"]["trials_per_s"].as_f64().unwrap_or(0.0),
        coordinator_cpu_s: cpu,
        coordinator_cpu_per_trial_ms: cpu.map(|c| per_trial(c) * 1e3),
    })
}

fn farm(a: &FarmBenchArgs) -> Result<(), Failure> {
    if a.workers.iter().any(|&w| w == 0 || w > 256) || a.iterations == 0 {
        return Err(Failure::Usage(anyhow!(
            "--workers must be in 1..=256 and --iterations at least 1"
        )));
    }
    // Refuse a bad file before starting any process.
    crate::cli::load_experiment(&a.experiment)?;
    let exp = &a.experiment;
    let mut rows = Vec::new();
    for &w in &a.workers {
        eprintln!("synthetic, {w} worker(s)…");
        rows.push(farm_case(exp, "synthetic", w, a.iterations).map_err(Failure::Job)?);
    }
    if a.nao_iterations > 0 {
        for w in [1, 2] {
            eprintln!("nao, {w} worker(s)…");
            rows.push(farm_case(exp, "nao", w, a.nao_iterations).map_err(Failure::Job)?);
        }
    }
    if a.json {
        let text = serde_json::to_string_pretty(&rows).map_err(|e| Failure::Job(e.into()))?;
        return crate::cli::emit(&format!("{text}\n"));
    }
    let mut out = format!(
        "{:<10} {:>7} {:>7} {:>8} {:>10} {:>16} {:>22}\n",
        "model", "workers", "trials", "wall s", "trials/s", "coord. CPU s", "coord. CPU ms/trial"
    );
    let f = |v: Option<f64>, p: usize| v.map_or("-".to_string(), |v| format!("{v:.p$}"));
    for r in &rows {
        out += &format!(
            "{:<10} {:>7} {:>7} {:>8.2} {:>10.1} {:>16} {:>22}\n",
            r.model,
            r.workers,
            r.trials,
            r.wall_s,
            r.trials_per_s,
            f(r.coordinator_cpu_s, 2),
            f(r.coordinator_cpu_per_trial_ms, 3)
        );
    }
    let nao: Vec<&FarmRow> = rows.iter().filter(|r| r.model == "nao").collect();
    if let [one, two] = nao.as_slice() {
        if one.trials_per_s > 0.0 {
            out += &format!(
                "NAO speed-up from 1 to 2 workers: {:.2}x ({:.1} -> {:.1} trials/s)\n",
                two.trials_per_s / one.trials_per_s,
                one.trials_per_s,
                two.trials_per_s
            );
        }
    }
    crate::cli::emit(&out)
}
