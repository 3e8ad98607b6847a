//! `naofarm bench`: `clop` (the CLOP regret table and the cost per step),
//! `farm` (throughput of real coordinator and worker processes) and `sim`
//! (the rebuilt NAO's real-time factor on one core).

use std::time::Instant;

use anyhow::anyhow;
use protocol::params::ParamValues;
use tools::{
    bench::{self, Algorithm},
    problems::Problem,
};
use worker::nao::{
    model::NaoModel,
    sim::{fallen, standing_angles, Sim, SimSettings, Start, CYCLE_S},
    trial,
};

use crate::{
    args::{BenchCommand, ClopBenchArgs, FarmBenchArgs, SimBenchArgs},
    common::Failure,
    crew::Crew,
};

/// Runs a benchmark.
pub fn bench(cmd: BenchCommand) -> Result<(), Failure> {
    match cmd {
        BenchCommand::Clop(a) => clop(&a),
        BenchCommand::Sim(a) => bench_sim(&a),
        BenchCommand::Farm(a) => farm(&a),
        BenchCommand::Fleet(a) => crate::commands::bench_fleet::fleet(&a),
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
        for d in [1, 5, 8] {
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

/// One measured farm run.
#[derive(Debug, serde::Serialize)]
struct FarmRow {
    model: &'static str,
    /// Over mutual TLS (`tls/` endpoints, role certificates), or plain TCP.
    tls: bool,
    workers: u32,
    trials: u64,
    wall_s: f64,
    trials_per_s: f64,
    coordinator_cpu_s: Option<f64>,
    coordinator_cpu_per_trial_ms: Option<f64>,
}

/// How `bench farm` names a case's link.
fn link_name(tls: bool) -> &'static str {
    if tls {
        "TLS"
    } else {
        "TCP"
    }
}

/// Runs `naofarm coordinator` with `workers` worker processes on a free
/// loopback port and reads its final JSON line.
fn farm_case(
    crew: &Crew,
    experiment: &std::path::Path,
    model: &'static str,
    workers: u32,
    iterations: u64,
    tls: Option<&std::path::Path>,
) -> anyhow::Result<FarmRow> {
    use std::io::{BufRead, BufReader, Read};
    use std::process::{Command, Stdio};
    let exe = std::env::current_exe()?;
    // The run's directory, new (the coordinator makes it) in a scratch one.
    let out = crew
        .scratch(&std::env::temp_dir(), "naofarm-bench-farm-")?
        .join("run");
    let started = std::time::Instant::now();
    // The coordinator listens on a port the OS picks and says which.
    let mut coordinator = Command::new(&exe);
    coordinator.arg("coordinator");
    if let Some(pki) = tls {
        coordinator.arg("--tls").arg(pki);
    }
    let listen = if tls.is_some() {
        "tls/127.0.0.1:0"
    } else {
        "tcp/127.0.0.1:0"
    };
    let mut coordinator = crew.spawn(
        coordinator
            .arg(experiment)
            .arg("--out")
            .arg(&out)
            .args(["--json", "--model", model, "--listen", listen])
            .args(["--iterations", &iterations.to_string()])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped()),
    )?;
    let mut err = BufReader::new(coordinator.stderr.take().ok_or_else(|| anyhow!("stderr"))?);
    let mut said = String::new();
    let endpoint = loop {
        let mut line = String::new();
        if err.read_line(&mut line)? == 0 {
            crew.wait(&coordinator)?;
            return Err(anyhow!("the coordinator failed before listening: {said}"));
        }
        if let Some(ep) = line.strip_prefix("coordinator listening on ") {
            break ep.trim().to_string();
        }
        said += &line;
    };
    let rest = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = err.read_to_string(&mut text);
        text
    });
    let mut pool = Vec::new();
    for _ in 0..workers {
        let mut w = Command::new(&exe);
        w.args(["worker", "--slots", "1", "--connect", &endpoint]);
        if let Some(pki) = tls {
            w.arg("--tls").arg(pki);
        }
        pool.push(crew.spawn(w.stdout(Stdio::null()).stderr(Stdio::null()))?);
    }
    let mut stdout = String::new();
    if let Some(mut o) = coordinator.stdout.take() {
        o.read_to_string(&mut stdout)?;
    }
    let status = crew.wait(&coordinator)?;
    let wall_s = started.elapsed().as_secs_f64();
    for w in &pool {
        crew.kill(w);
    }
    if !status.success() {
        return Err(anyhow!(
            "the coordinator failed ({status}): {said}{}",
            rest.join().unwrap_or_default()
        ));
    }
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
        tls: tls.is_some(),
        workers,
        trials,
        wall_s,
        trials_per_s: finished["status"]["trials_per_s"].as_f64().unwrap_or(0.0),
        coordinator_cpu_s: cpu,
        coordinator_cpu_per_trial_ms: cpu.map(|c| per_trial(c) * 1e3),
    })
}

fn farm(a: &FarmBenchArgs) -> Result<(), Failure> {
    for &w in &a.workers {
        crate::common::flag_in("--workers", w, 1..=256)?;
    }
    crate::common::flag_in("--iterations", a.iterations, 1..=10_000_000)?;
    crate::common::flag_in("--nao-iterations", a.nao_iterations, 0..=10_000_000)?;
    // Refuse a bad file before starting any process.
    crate::common::load_experiment(&a.experiment)?;
    let exp = &a.experiment;
    // Every process and file of the bench goes with it, however it ends.
    let crew = Crew::new();
    // With --tls: certificates for every role, made as a user makes them.
    let pki = if a.tls {
        let pki = crew
            .scratch(&std::env::temp_dir(), "naofarm-bench-pki-")
            .map_err(|e| Failure::Job(e.into()))?
            .join("pki");
        let made = std::process::Command::new(
            std::env::current_exe().map_err(|e| Failure::Job(e.into()))?,
        )
        .arg("certs")
        .arg(&pki)
        .output()
        .map_err(|e| Failure::Job(e.into()))?;
        if !made.status.success() {
            return Err(Failure::Job(anyhow!(
                "naofarm certs failed: {}",
                String::from_utf8_lossy(&made.stderr)
            )));
        }
        Some(pki)
    } else {
        None
    };
    // Plain TCP, and TLS when asked for.
    let mut links: Vec<Option<&std::path::Path>> = vec![None];
    if let Some(pki) = &pki {
        links.push(Some(pki));
    }
    let mut rows = Vec::new();
    for &w in &a.workers {
        for &t in &links {
            eprintln!("synthetic, {w} worker(s), {}…", link_name(t.is_some()));
            rows.push(
                farm_case(&crew, exp, "synthetic", w, a.iterations, t).map_err(Failure::Job)?,
            );
        }
    }
    if a.nao_iterations > 0 {
        for w in [1, 2] {
            for &t in &links {
                eprintln!("nao, {w} worker(s), {}…", link_name(t.is_some()));
                rows.push(
                    farm_case(&crew, exp, "nao", w, a.nao_iterations, t).map_err(Failure::Job)?,
                );
            }
        }
    }
    drop(crew);
    if a.json {
        let text = serde_json::to_string_pretty(&rows).map_err(|e| Failure::Job(e.into()))?;
        return crate::common::emit(&format!("{text}\n"));
    }
    let mut out = format!(
        "{:<10} {:>4} {:>7} {:>7} {:>8} {:>10} {:>16} {:>22}\n",
        "model",
        "link",
        "workers",
        "trials",
        "wall s",
        "trials/s",
        "coord. CPU s",
        "coord. CPU ms/trial"
    );
    let f = |v: Option<f64>, p: usize| v.map_or("-".to_string(), |v| format!("{v:.p$}"));
    for r in &rows {
        out += &format!(
            "{:<10} {:>4} {:>7} {:>7} {:>8.2} {:>10.1} {:>16} {:>22}\n",
            r.model,
            link_name(r.tls),
            r.workers,
            r.trials,
            r.wall_s,
            r.trials_per_s,
            f(r.coordinator_cpu_s, 2),
            f(r.coordinator_cpu_per_trial_ms, 3)
        );
    }
    let nao: Vec<&FarmRow> = rows.iter().filter(|r| r.model == "nao" && !r.tls).collect();
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
    crate::common::emit(&out)
}

struct Row {
    label: String,
    motion: &'static str,
    settings: SimSettings,
    sim_s: f64,
    steps: f64,
    wall_s: f64,
    /// CPU time of the measuring thread: unlike the wall time, it leaves
    /// out the time other processes of a shared machine had the core.
    cpu_s: f64,
    fell: bool,
}

/// The CPU time this thread has used, s (a measurement runs on its thread).
fn thread_cpu_s() -> f64 {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::ThreadCPUTime);
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}

fn measure_stand(settings: SimSettings, seconds: f64) -> Result<Row, Failure> {
    let model =
        NaoModel::with_params(0, &ParamValues::default()).map_err(|e| Failure::Job(e.into()))?;
    let q = standing_angles(&model);
    let (t0, cpu0) = (Instant::now(), thread_cpu_s());
    let mut sim = Sim::new(&model, settings, &Start::upright(q.clone()))
        .map_err(|e| Failure::Job(e.into()))?;
    let mut p = sim.perceive();
    let mut fell = false;
    for _ in 0..(seconds / CYCLE_S).round() as u64 {
        p = sim.hold(&q).map_err(|e| Failure::Job(e.into()))?;
        fell |= fallen(&p);
    }
    Ok(Row {
        label: String::new(),
        motion: "stand",
        settings,
        sim_s: p.time_s,
        steps: p.time_s / CYCLE_S * f64::from(settings.substeps),
        wall_s: t0.elapsed().as_secs_f64(),
        cpu_s: thread_cpu_s() - cpu0,
        fell,
    })
}

/// The expert set's walk (seed 1) on `settings`.
fn measure_walk(settings: SimSettings, seconds: f64) -> Result<Row, Failure> {
    let params = ParamValues::default();
    let (t0, cpu0) = (Instant::now(), thread_cpu_s());
    let t = trial::run(0, &params, 1, seconds, settings, trial::Engine::WALK)
        .map_err(|e| Failure::Job(e.into()))?;
    Ok(Row {
        label: String::new(),
        motion: "walk",
        settings,
        sim_s: t.measurement.sim_time_s,
        steps: t.measurement.sim_time_s / CYCLE_S * f64::from(settings.substeps),
        wall_s: t0.elapsed().as_secs_f64(),
        cpu_s: thread_cpu_s() - cpu0,
        fell: t.measurement.fell,
    })
}

/// `naofarm bench sim`: real-time factor and physics steps per second on one
/// core, of the shipped physics standing and walking, and of the walk at
/// other step and solver counts (the `trial` knobs), each measurement in
/// turn in every round.
pub fn bench_sim(a: &SimBenchArgs) -> Result<(), Failure> {
    if !(a.seconds.is_finite() && a.seconds >= 1.0 && a.seconds <= 600.0) {
        return Err(Failure::Usage(anyhow!("--seconds must be in [1, 600]")));
    }
    if !(1..=100).contains(&a.rounds) {
        return Err(Failure::Usage(anyhow!("--rounds must be in [1, 100]")));
    }
    let d = SimSettings::default();
    let specs: Vec<(&str, SimSettings, &str)> = vec![
        ("shipped: 4x5ms, 28 PGS", d, "stand"),
        ("shipped: 4x5ms, 28 PGS", d, "walk"),
        ("2x10ms, 28 PGS", SimSettings { substeps: 2, ..d }, "walk"),
        ("8x2.5ms, 28 PGS", SimSettings { substeps: 8, ..d }, "walk"),
        (
            "4x5ms, 12 PGS",
            SimSettings {
                pgs_iterations: 12,
                ..d
            },
            "walk",
        ),
    ];
    // Rounds of every measurement in turn: a slow spell of a shared
    // machine then slows each row alike.
    let mut runs: Vec<Vec<Row>> = specs.iter().map(|_| Vec::new()).collect();
    for _ in 0..a.rounds {
        for ((label, s, motion), run) in specs.iter().zip(&mut runs) {
            let mut r = match *motion {
                "stand" => measure_stand(*s, a.seconds)?,
                _ => measure_walk(*s, a.seconds)?,
            };
            r.label = (*label).to_string();
            run.push(r);
        }
    }
    let rtf = |r: &Row| r.sim_s / r.wall_s;
    let cpu_rtf = |r: &Row| r.sim_s / r.cpu_s;
    let sps = |r: &Row| r.steps / r.cpu_s;
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    // Each measurement's medians over the rounds: real time by the wall
    // clock, and by the thread's CPU clock, and physics steps per CPU second.
    let rows: Vec<(&Row, f64, f64, f64)> = runs
        .iter()
        .map(|run| {
            (
                &run[0],
                median(run.iter().map(rtf).collect()),
                median(run.iter().map(cpu_rtf).collect()),
                median(run.iter().map(sps).collect()),
            )
        })
        .collect();
    let shipped = rows[1];
    if a.json {
        let v = serde_json::json!({
            "rounds": a.rounds,
            "motion": "expert walk, type 0, shipped physics, one core",
            "realtime_factor": shipped.1,
            "cpu_realtime_factor": shipped.2,
            "steps_per_second": shipped.3,
            "rows": rows.iter().map(|(r, wall, cpu, steps)| serde_json::json!({
                "settings": r.label,
                "motion": r.motion,
                "substeps": r.settings.substeps,
                "solver_iterations": r.settings.solver_iterations,
                "pgs_iterations": r.settings.pgs_iterations,
                "realtime_factor": wall,
                "cpu_realtime_factor": cpu,
                "steps_per_second": steps,
                "fell": r.fell,
                "sim_s": r.sim_s,
            })).collect::<Vec<_>>(),
        });
        outln!("{v}");
    } else {
        outln!(
            "medians of {} rounds, each measurement in turn in every round; \
             realtime× by the wall clock and by the thread's CPU clock, steps per CPU second",
            a.rounds
        );
        outln!(
            "{:<28} {:>7} {:>10} {:>10} {:>12} {:>6}",
            "settings",
            "motion",
            "realtime×",
            "CPU rt×",
            "steps/s",
            "fell"
        );
        for (r, wall, cpu, steps) in &rows {
            outln!(
                "{:<28} {:>7} {:>10.1} {:>10.1} {:>12.0} {:>6}",
                r.label,
                r.motion,
                wall,
                cpu,
                steps,
                r.fell
            );
        }
    }
    Ok(())
}
