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
    /// The experiment file's key, on a file's walk and on its open-loop twin.
    file: Option<&'static str>,
    motion: &'static str,
    settings: SimSettings,
    sim_s: f64,
    /// Physics steps taken: a banded file's row runs walks at several steps.
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
        file: None,
        motion: "stand",
        settings,
        sim_s: p.time_s,
        steps: p.time_s / CYCLE_S * f64::from(settings.substeps),
        wall_s: t0.elapsed().as_secs_f64(),
        cpu_s: thread_cpu_s() - cpu0,
        fell,
    })
}

fn measure_walk(
    settings: SimSettings,
    seconds: f64,
    walk: protocol::WalkEngine,
    params: &ParamValues,
) -> Result<Row, Failure> {
    let engine = trial::Engine::of(walk);
    // What the trial runs on (the arms free where the walk swings them).
    let ran = trial::walk_settings(settings, &engine.gait.with_params(params));
    let (t0, cpu0) = (Instant::now(), thread_cpu_s());
    let t = trial::run_observed(0, params, 1, seconds, settings, engine, &mut |_, _, _| {})
        .map_err(|e| Failure::Job(e.into()))?;
    Ok(Row {
        label: String::new(),
        file: None,
        motion: match walk {
            protocol::WalkEngine::OpenLoop => "walk",
            protocol::WalkEngine::ClosedLoop => "walk-cl",
        },
        settings: ran,
        sim_s: t.measurement.sim_time_s,
        steps: t.measurement.sim_time_s / CYCLE_S * f64::from(settings.substeps),
        wall_s: t0.elapsed().as_secs_f64(),
        cpu_s: thread_cpu_s() - cpu0,
        fell: t.measurement.fell,
    })
}

/// A shipped experiment file whose walk `bench sim` measures beside the
/// default, as the file sets it.
struct FileWalk {
    /// The file's text.
    text: &'static str,
    /// Its key in the JSON output (`{key}_realtime_factor`,
    /// `{key}_share_of_open_loop`); with spaces for underscores, its name in
    /// the summary lines and errors.
    key: &'static str,
    /// Its row's label.
    label: &'static str,
}

impl FileWalk {
    /// Its name in the summary lines and errors.
    fn name(&self) -> String {
        self.key.replace('_', " ")
    }
}

/// The files `bench sim` measures, the converged first.
const FILES: [FileWalk; 11] = [
    // Converged physics with its fixed values.
    FileWalk {
        text: include_str!("../../experiments/physical-technical-converged.toml"),
        key: "converged",
        label: "converged files: 10x2ms, no double support",
    },
    // The farm's step with the contact problem solved further.
    FileWalk {
        text: include_str!("../../experiments/physical-technical-stiff.toml"),
        key: "stiff",
        label: "stiff file: 2x10ms, pgs 32, its engine",
    },
    // The farm's step with stops that hold within it.
    FileWalk {
        text: include_str!("../../experiments/physical-technical-firm.toml"),
        key: "firm",
        label: "firm file: 2x10ms, pgs 28, firm stops, 60Hz",
    },
    // The firm physics with the arms swinging (and so not welded).
    FileWalk {
        text: include_str!("../../experiments/physical-technical-arms.toml"),
        key: "arms",
        label: "arms file: the firm file's, arms swinging",
    },
    // The arms file at 4 x 5 ms.
    FileWalk {
        text: include_str!("../../experiments/physical-technical-arms-5ms.toml"),
        key: "arms_5ms",
        label: "arms 5 ms file: the arms file's at 4x5ms",
    },
    // The arms file at 4 x 5 ms with the stance hip's roll at 0.09 rad:
    // the file that keeps every bound of the pace issue but the speed.
    FileWalk {
        text: include_str!("../../experiments/physical-technical-arms-5ms-roll.toml"),
        key: "arms_5ms_roll",
        label: "roll file: the arms 5 ms, hip roll 0.09",
    },
    // The roll file with its steps aimed and its feet placed against a
    // forward lean, whose experiment 2 keeps every bound of the pace issue
    // but the speed at every seed measured. Its expert walk is, to the bit,
    // that of the capped file (`…-lean-reach.toml`: the steps
    // capped at the legs' reach, which the expert's are within, and a stop
    // row a step ahead, which none of its trials needs), so this row
    // measures both.
    FileWalk {
        text: include_str!("../../experiments/physical-technical-arms-5ms-roll-aim-lean.toml"),
        key: "arms_5ms_roll_aim_lean",
        label: "lean file: the roll's, aimed, lean placed",
    },
    // The file README recommends: the capped file with the elbow yaws
    // welded (no walk stands on their 5 ms swing), the stance hip's roll
    // against the gyro's roll rate (the damp file's), and the steps read
    // along the walk's heading, whose optima keep to their plan. The damp
    // file's walk is the same but for one rotation a touchdown.
    FileWalk {
        text: include_str!(
            "../../experiments/physical-technical-arms-5ms-roll-aim-lean-reach-damp-heading.toml"
        ),
        key: "arms_5ms_heading",
        label: "heading file: damp, steps read along the heading",
    },
    // The heading file with the tilt read from gravity as a vector, the
    // torso's lean held by both legs, and each step read before the other
    // foot leaves: the file whose optima walk 6 m at every seed as planned
    // (docs/walk.md, "Steps read before the other foot leaves").
    FileWalk {
        text: include_str!(
            "../../experiments/physical-technical-arms-5ms-roll-aim-lean-reach-damp-heading-hold-before.toml"
        ),
        key: "arms_5ms_before",
        label: "before file: heading, held, read before",
    },
    // The step-period file with each trial's step drawn from a band.
    FileWalk {
        text: include_str!("../../experiments/physical-technical-converged-period-band.toml"),
        key: "band",
        label: "band file: each of 16-30 steps per cycle",
    },
    // The band file with its steps capped at the legs' reach and aimed
    // short by their overreach: the file whose optima keep every distance
    // bound (docs/walk.md, "Steps aimed short by the legs' overreach").
    FileWalk {
        text: include_str!(
            "../../experiments/physical-technical-converged-period-band-reach-aim.toml"
        ),
        key: "band_reach_aim",
        label: "reach-aim file: the band's, capped, aimed",
    },
];

/// The walk of a shipped experiment file, as the file sets it (its physics
/// and its fixed values, with its expert set), measured like the others; or,
/// with `open_loop`, the open loop's expert walk on that walk's physics (the
/// file's steps, solver, contacts and stops, and the same joints welded), so
/// that the two differ in the walk alone.
/// A file with a band of steps walks once at each step of its band, and its
/// row sums them: the farm's trials draw their steps uniformly from the
/// band, so that is what a trial costs on average.
fn measure_file_walk(f: &FileWalk, seconds: f64, open_loop: bool) -> Result<Row, Failure> {
    let bad = |e: String| Failure::Job(anyhow!("the {} experiment file: {e}", f.name()));
    let file = protocol::Experiment::from_toml(f.text).map_err(|e| bad(e.to_string()))?;
    let params = ParamValues::from_named(&file.full_params(&file.expert_values()))
        .map_err(|e| bad(e.to_string()))?;
    let gait = trial::Engine::of(file.walk).gait.with_params(&params);
    let settings = trial::walk_settings(SimSettings::with_physics(&file.physics), &gait);
    let (walk, params) = if open_loop {
        (protocol::WalkEngine::OpenLoop, ParamValues::default())
    } else {
        (file.walk, params)
    };
    let mut sum: Option<Row> = None;
    for substeps in settings.substeps_band() {
        let fixed = SimSettings {
            substeps,
            substeps_max: 0,
            ..settings
        };
        let r = measure_walk(fixed, seconds, walk, &params)?;
        sum = Some(match sum {
            None => r,
            Some(t) => Row {
                sim_s: t.sim_s + r.sim_s,
                steps: t.steps + r.steps,
                wall_s: t.wall_s + r.wall_s,
                cpu_s: t.cpu_s + r.cpu_s,
                fell: t.fell || r.fell,
                ..t
            },
        });
    }
    let mut r = sum.ok_or_else(|| bad("no physics steps".into()))?;
    r.label = f.label.into();
    r.file = Some(f.key);
    // The band's steps, as the file gives them (each run had one of them).
    r.settings = SimSettings {
        substeps: settings.substeps,
        substeps_max: settings.substeps_max,
        ..r.settings
    };
    Ok(r)
}

/// One measurement of `bench sim`: a variant's motion, or a file's walk.
enum Spec {
    /// Label, settings and motion (`stand`, `walk`, `walk-cl`).
    Variant(&'static str, SimSettings, &'static str),
    /// A file's walk, or with `true` the open loop on its physics.
    File(&'static FileWalk, bool),
}

/// `naofarm bench sim`: real-time factor and physics steps per second on one core.
pub fn bench_sim(a: &SimBenchArgs) -> Result<(), Failure> {
    if !(a.seconds.is_finite() && a.seconds >= 1.0 && a.seconds <= 600.0) {
        return Err(Failure::Usage(anyhow!("--seconds must be in [1, 600]")));
    }
    if !(1..=100).contains(&a.rounds) {
        return Err(Failure::Usage(anyhow!("--rounds must be in [1, 100]")));
    }
    let d = SimSettings::default();
    let variants = [
        ("default: 2x10ms, pgs 12, welded upper body", d),
        (
            "4x5ms, pgs 8, welded",
            SimSettings {
                substeps: 4,
                pgs_iterations: 8,
                ..d
            },
        ),
        (
            "2x10ms, pgs 12, full 22 hinges",
            SimSettings {
                weld_upper_body: false,
                ..d
            },
        ),
        (
            "2x10ms, pgs 12, 4 solver iterations",
            SimSettings {
                solver_iterations: 4,
                ..d
            },
        ),
        (
            "1x20ms, pgs 40, welded",
            SimSettings {
                substeps: 1,
                pgs_iterations: 40,
                ..d
            },
        ),
        (
            "impulse joints, 2x10ms, pgs 12, welded",
            SimSettings {
                impulse_joints: true,
                ..d
            },
        ),
        (
            "impulse joints, 4x5ms, 4 solver its",
            SimSettings {
                impulse_joints: true,
                substeps: 4,
                solver_iterations: 4,
                ..d
            },
        ),
        (
            "impulse joints, 10x2ms, 8 solver its",
            SimSettings {
                impulse_joints: true,
                substeps: 10,
                solver_iterations: 8,
                ..d
            },
        ),
        (
            "2x10ms, pgs 4, welded",
            SimSettings {
                pgs_iterations: 4,
                ..d
            },
        ),
    ];
    let expert = ParamValues::default();
    // Every measurement, in the order of the table: the variants' three
    // motions, then the files' walks.
    let mut specs: Vec<Spec> = Vec::new();
    for (label, s) in variants {
        for motion in ["stand", "walk", "walk-cl"] {
            specs.push(Spec::Variant(label, s, motion));
        }
    }
    // Each file's walk, then at once its open-loop twin, so that the two
    // meet the same spell of a shared machine; each file with the indices
    // of the two measurements.
    let mut files: Vec<(&FileWalk, usize, usize)> = Vec::new();
    for f in &FILES {
        files.push((f, specs.len(), specs.len() + 1));
        specs.push(Spec::File(f, false));
        specs.push(Spec::File(f, true));
    }
    // Rounds of every measurement in turn: a slow spell of a shared
    // machine then slows each row alike, and the ratios are per round.
    let mut runs: Vec<Vec<Row>> = specs.iter().map(|_| Vec::new()).collect();
    for _ in 0..a.rounds {
        for (spec, run) in specs.iter().zip(&mut runs) {
            let mut r = match *spec {
                Spec::Variant(_, s, "stand") => measure_stand(s, a.seconds)?,
                Spec::Variant(_, s, "walk") => {
                    measure_walk(s, a.seconds, protocol::WalkEngine::OpenLoop, &expert)?
                }
                Spec::Variant(_, s, _) => {
                    measure_walk(s, a.seconds, protocol::WalkEngine::ClosedLoop, &expert)?
                }
                Spec::File(f, open_loop) => measure_file_walk(f, a.seconds, open_loop)?,
            };
            match spec {
                Spec::Variant(label, ..) => r.label = (*label).to_string(),
                Spec::File(f, true) => r.label = format!("open loop, {} physics", f.name()),
                Spec::File(_, false) => {}
            }
            run.push(r);
        }
    }
    let rtf = |r: &Row| r.sim_s / r.wall_s;
    let cpu_rtf = |r: &Row| r.sim_s / r.cpu_s;
    let sps = |r: &Row| r.steps / r.wall_s;
    // Each measurement's row of median real-time factor.
    let rows: Vec<&Row> = runs
        .iter()
        .map(|run| {
            let mut by_speed: Vec<&Row> = run.iter().collect();
            by_speed.sort_by(|a, b| rtf(a).total_cmp(&rtf(b)));
            by_speed[by_speed.len() / 2]
        })
        .collect();
    // Each measurement's median real-time factor by its thread's CPU clock.
    let cpu: Vec<f64> = runs
        .iter()
        .map(|run| {
            let mut f: Vec<f64> = run.iter().map(cpu_rtf).collect();
            f.sort_by(f64::total_cmp);
            f[f.len() / 2]
        })
        .collect();
    let find = |motion: &str| {
        rows.iter()
            .position(|r| r.motion == motion && r.settings == d)
            .ok_or_else(|| Failure::Job(anyhow!("no default {motion} row")))
    };
    let (headline, closed) = (find("walk")?, find("walk-cl")?);
    let open_loop = headline;
    // A measurement's speed against another's: the median over the rounds
    // of the ratio within each round.
    let share = |of: usize, to: usize, per: &dyn Fn(&Row) -> f64| {
        let mut ratios: Vec<f64> = runs[of]
            .iter()
            .zip(&runs[to])
            .map(|(a, b)| per(a) / per(b))
            .collect();
        ratios.sort_by(f64::total_cmp);
        let spread = (ratios[0], ratios[ratios.len() - 1]);
        (ratios[ratios.len() / 2], spread)
    };
    // The closed-loop walk's speed as a share of the open loop's, measured in
    // the same rounds at the default settings.
    let (closed_share, closed_spread) = share(closed, headline, &cpu_rtf);
    let converged = files[0].1;
    // What a physics step costs there against the default's: about the same,
    // so the converged walk's share follows its steps per cycle (docs/walk.md,
    // "Why no code speed-up meets the 80 % on converged physics").
    let (converged_step_share, _) = share(converged, closed, &sps);
    let (hi, ci) = (headline, closed);
    let (headline, closed, converged) = (rows[headline], rows[closed], rows[converged]);
    if a.json {
        let mut v = serde_json::json!({
            "rounds": a.rounds,
            "realtime_factor": rtf(headline),
            "cpu_realtime_factor": cpu[hi],
            "steps_per_second": sps(headline),
            "motion": "expert walk, type 0, default settings, one core",
            "shares_by": "the measuring thread's CPU clock",
            "closed_loop_realtime_factor": rtf(closed),
            "closed_loop_cpu_realtime_factor": cpu[ci],
            "closed_loop_share_of_open_loop": closed_share,
            "closed_loop_share_spread": [closed_spread.0, closed_spread.1],
            "converged_steps_per_second_share": converged_step_share,
            "rows": rows.iter().zip(&cpu).map(|(r, c)| serde_json::json!({
                "settings": r.label,
                "file": r.file,
                "motion": r.motion,
                "substeps": r.settings.substeps,
                "substeps_max": r.settings.substeps_max,
                "solver_iterations": r.settings.solver_iterations,
                "pgs_iterations": r.settings.pgs_iterations,
                "weld_upper_body": r.settings.weld_upper_body,
                "weld_head": r.settings.weld_head,
                "contact_hz": r.settings.contact_hz,
                "firm_stops": r.settings.firm_stops,
                "realtime_factor": rtf(r),
                "cpu_realtime_factor": c,
                "steps_per_second": sps(r),
                "fell": r.fell,
                "sim_s": r.sim_s,
            })).collect::<Vec<_>>(),
        });
        for (f, i, t) in &files {
            let (of_open, spread) = share(*i, open_loop, &cpu_rtf);
            let (of_twin, twin_spread) = share(*i, *t, &cpu_rtf);
            v[format!("{}_realtime_factor", f.key)] = rtf(rows[*i]).into();
            v[format!("{}_cpu_realtime_factor", f.key)] = cpu[*i].into();
            v[format!("{}_share_of_open_loop", f.key)] = of_open.into();
            v[format!("{}_share_spread", f.key)] = serde_json::json!([spread.0, spread.1]);
            v[format!("{}_share_of_open_loop_on_its_physics", f.key)] = of_twin.into();
            v[format!("{}_share_on_its_physics_spread", f.key)] =
                serde_json::json!([twin_spread.0, twin_spread.1]);
        }
        outln!("{v}");
    } else {
        outln!(
            "medians of {} rounds, each measurement in turn in every round; \
             realtime× by the wall clock and by the thread's CPU clock, shares by CPU",
            a.rounds
        );
        outln!(
            "{:<44} {:>7} {:>10} {:>10} {:>12} {:>6}",
            "settings",
            "motion",
            "realtime×",
            "CPU rt×",
            "steps/s",
            "fell"
        );
        for (r, c) in rows.iter().copied().zip(&cpu) {
            outln!(
                "{:<44} {:>7} {:>10.1} {:>10.1} {:>12.0} {:>6}",
                r.label,
                r.motion,
                rtf(r),
                c,
                sps(r),
                r.fell
            );
        }
        outln!(
            "closed-loop walk at the default settings: {:.1}x real time ({:.1}x by CPU), {:.0} % of the open loop's ({:.0}–{:.0} % over the rounds)",
            rtf(closed),
            cpu[ci],
            100.0 * closed_share,
            100.0 * closed_spread.0,
            100.0 * closed_spread.1
        );
        for (f, i, t) in &files {
            let (of_open, spread) = share(*i, open_loop, &cpu_rtf);
            let (of_twin, twin_spread) = share(*i, *t, &cpu_rtf);
            outln!(
                "closed-loop walk of the {} experiment: {:.1}x real time ({:.1}x by CPU), {:.0} % of the open loop's at the default ({:.0}–{:.0} %), {:.0} % of the open loop's on its physics ({:.0}–{:.0} %)",
                f.name(),
                rtf(rows[*i]),
                cpu[*i],
                100.0 * of_open,
                100.0 * spread.0,
                100.0 * spread.1,
                100.0 * of_twin,
                100.0 * twin_spread.0,
                100.0 * twin_spread.1
            );
            if f.key == "converged" {
                outln!(
                    "  per physics step: {:.2}x the default closed loop's steps/s, with {} steps per cycle against {}",
                    converged_step_share,
                    converged.settings.substeps,
                    closed.settings.substeps
                );
            }
        }
    }
    Ok(())
}
