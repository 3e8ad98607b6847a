//! `naofarm stand`, `naofarm trial` and `naofarm bench sim`: the rebuilt NAO
//! run locally, without the farm.

use std::time::Instant;

use anyhow::anyhow;
use clap::Args;
use protocol::{measurement::Measurement, pickout::stats};
use worker::nao::trial::NaoTrial;
use worker::nao::{
    model::NaoModel,
    sim::{fallen, standing_angles, Sim, SimSettings, Start, CYCLE_S},
    trial,
};

use crate::cli::{parse_params, Failure};
use protocol::params::ParamValues;

/// Arguments of `stand`.
#[derive(Args, Debug)]
pub struct StandArgs {
    /// League robot type 0–4.
    #[arg(long = "type", default_value_t = 0)]
    robot_type: u8,
    /// Override a morphology quantity, NAME=VALUE (repeatable).
    #[arg(long = "param", value_name = "NAME=VALUE")]
    params: Vec<String>,
    /// Simulated seconds.
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Machine-readable output.
    #[arg(long)]
    json: bool,
}

/// `naofarm stand`: hold the standing posture with the servos.
pub fn stand(a: &StandArgs) -> Result<(), Failure> {
    if !(a.seconds.is_finite() && a.seconds > 0.0 && a.seconds <= 3600.0) {
        return Err(Failure::Usage(anyhow!("--seconds must be in (0, 3600]")));
    }
    let m = crate::cli::morphology(a.robot_type, &a.params)?;
    let model = NaoModel::new(m).map_err(|e| Failure::Usage(e.into()))?;
    let q = standing_angles(&model);
    let mut sim = Sim::new(&model, SimSettings::default(), &Start::upright(q.clone()))
        .map_err(|e| Failure::Job(e.into()))?;
    let mut p = sim.perceive();
    let (mut lo, mut hi) = (p.torso_position_m[2], p.torso_position_m[2]);
    let mut fell_at = None;
    let cycles = (a.seconds / CYCLE_S).round() as u64;
    for _ in 0..cycles {
        p = sim.hold(&q).map_err(|e| Failure::Job(e.into()))?;
        lo = lo.min(p.torso_position_m[2]);
        hi = hi.max(p.torso_position_m[2]);
        if fell_at.is_none() && fallen(&p) {
            fell_at = Some(p.time_s);
        }
    }
    if a.json {
        let v = serde_json::json!({
            "robot_type": a.robot_type,
            "seconds": p.time_s,
            "fell": fell_at.is_some(),
            "fall_time_s": fell_at,
            "torso_height_min_m": lo,
            "torso_height_max_m": hi,
            "final_torso_position_m": p.torso_position_m,
            "final_torso_rotation_xyzw": p.torso_rotation,
            "final_torso_tilt_rad": p.torso_tilt_rad,
            "final_joint_angles_rad": model.joints.iter().zip(&p.joint_angles_rad)
                .map(|(j, a)| (j.name.clone(), serde_json::json!(a)))
                .collect::<serde_json::Map<String, serde_json::Value>>(),
        });
        outln!("{v}");
    } else {
        outln!(
            "type {} stood {:.2} s: {}",
            a.robot_type,
            p.time_s,
            match fell_at {
                Some(t) => format!("FELL at {t:.2} s"),
                None => "did not fall".into(),
            }
        );
        outln!("torso height min {lo:.4} m, max {hi:.4} m");
        let t = p.torso_position_m;
        outln!(
            "final torso ({:.4}, {:.4}, {:.4}) m, tilt {:.2}°",
            t[0],
            t[1],
            t[2],
            p.torso_tilt_rad.to_degrees()
        );
    }
    Ok(())
}

/// Arguments of `trial`.
#[derive(Args, Debug)]
pub struct TrialArgs {
    /// Start from a named set (`expert`, the paper's expert values).
    #[arg(long, default_value = "expert")]
    set: String,
    /// Override a parameter, NAME=VALUE (repeatable).
    #[arg(long = "param", value_name = "NAME=VALUE")]
    params: Vec<String>,
    /// Number of trials.
    #[arg(long, default_value_t = 10)]
    trials: u64,
    /// Seed of the first trial (then +1 per trial).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// League robot type 0–4.
    #[arg(long = "type", default_value_t = 0)]
    robot_type: u8,
    /// Trial duration, simulated seconds.
    #[arg(long, default_value_t = 10.0)]
    duration: f64,
    /// Threads (default: cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Physics sub-steps per 20 ms cycle, 1–50 (default 2; see `bench sim`).
    #[arg(long)]
    substeps: Option<u32>,
    /// Rapier solver iterations per sub-step, 1–16 (default 1).
    #[arg(long)]
    solver_iterations: Option<u32>,
    /// Rapier PGS iterations per solver iteration, 1–200 (default 12).
    #[arg(long)]
    pgs_iterations: Option<u32>,
    /// Reflected rotor inertia of every motorised hinge, kg·m², 0–0.1
    /// (default 0: the league's robot has none).
    #[arg(long)]
    armature: Option<f64>,
    /// Record the first trial (seed --seed; with --run, the farm trial):
    /// every body's pose each 20 ms cycle, as JSON lines, for a replay.
    #[arg(long, value_name = "FILE")]
    record: Option<std::path::PathBuf>,
    /// Replay a farm trial of this run directory (with --iteration and
    /// --trial): its parameters, robot type, physics and seed come from the
    /// journal, and the result is compared with the journaled one bit for bit.
    #[arg(
        long = "run",
        value_name = "DIR",
        requires_all = ["iteration", "trial"],
        conflicts_with_all = ["params", "trials", "seed", "robot_type", "duration", "substeps",
            "solver_iterations", "pgs_iterations", "armature"]
    )]
    run_dir: Option<std::path::PathBuf>,
    /// With --run: the iteration.
    #[arg(long, requires = "run_dir")]
    iteration: Option<u64>,
    /// With --run: the trial index within the iteration.
    #[arg(long, requires = "run_dir")]
    trial: Option<u32>,
    /// Machine-readable output with every trial.
    #[arg(long)]
    json: bool,
}

/// `naofarm trial`: n trials of one parameter set, the Table IV row.
pub fn trial(a: &TrialArgs) -> Result<(), Failure> {
    if let (Some(dir), Some(i), Some(k)) = (&a.run_dir, a.iteration, a.trial) {
        return replay(a, dir, i, k);
    }
    if a.set != "expert" {
        return Err(Failure::Usage(anyhow!(
            "--set `{}`: the only named set is `expert`",
            a.set
        )));
    }
    if a.trials == 0 || a.trials > 100_000 {
        return Err(Failure::Usage(anyhow!("--trials must be in 1..=100000")));
    }
    if !(a.duration.is_finite() && a.duration > 0.0 && a.duration <= 600.0) {
        return Err(Failure::Usage(anyhow!("--duration must be in (0, 600] s")));
    }
    let params = parse_params(&a.params)?;
    let values = ParamValues::from_named(&params).map_err(|e| Failure::Usage(e.into()))?;
    NaoModel::with_params(a.robot_type, &values).map_err(|e| Failure::Usage(e.into()))?;
    if a.threads.is_some_and(|t| t == 0 || t > 1024) {
        return Err(Failure::Usage(anyhow!("--threads must be in 1..=1024")));
    }
    let threads = a
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, usize::from));
    let d = protocol::Physics::default();
    let physics = protocol::Physics {
        substeps: a.substeps.unwrap_or(d.substeps),
        solver_iterations: a.solver_iterations.unwrap_or(d.solver_iterations),
        pgs_iterations: a.pgs_iterations.unwrap_or(d.pgs_iterations),
        armature_kg_m2: a.armature.unwrap_or(d.armature_kg_m2),
    };
    physics.validate().map_err(|(field, m)| {
        let flag = field.trim_end_matches("_kg_m2").replace('_', "-");
        Failure::Usage(anyhow!("--{flag}: {m}"))
    })?;
    let settings = SimSettings::with_physics(&physics);
    if let Some(path) = &a.record {
        let what = Recording {
            robot_type: a.robot_type,
            seed: a.seed,
            duration: a.duration,
            params: &params,
            values: &values,
        };
        record(path, &what, settings)?;
    }
    let t0 = Instant::now();
    let runs = trial::run_many(
        a.robot_type,
        &values,
        a.seed,
        a.trials,
        a.duration,
        threads,
        settings,
    )
    .map_err(|e| Failure::Job(e.into()))?;
    let wall = t0.elapsed().as_secs_f64();
    let results: Vec<_> = runs.iter().map(|t| t.measurement).collect();
    let s = stats(&results);
    let diverged = runs.iter().filter(|t| t.diverged).count();
    if a.json {
        let v = serde_json::json!({
            "params": params_json(&params),
            "robot_type": a.robot_type,
            "s": s.s,
            "mx": s.mx,
            "my": s.my,
            "ex": s.ex,
            "ey": s.ey,
            "trials": runs.iter().map(trial_json).collect::<Vec<_>>(),
            "diverged": diverged,
            "wall_s": wall,
        });
        outln!("{v}");
    } else {
        let f = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.3}"));
        outln!(
            "     s     mx     my     ex     ey   (m; {} trials of {} s)",
            a.trials,
            a.duration
        );
        outln!(
            "{:6.2} {:>6} {:>6} {:>6} {:>6}",
            s.s,
            f(s.mx),
            f(s.my),
            f(s.ex),
            f(s.ey)
        );
        if diverged > 0 {
            outln!("{diverged} of the falls were the physics diverging (counted as falls, no distance)");
        }
        outln!(
            "{:.1} trials/s on {threads} threads ({wall:.2} s wall)",
            a.trials as f64 / wall
        );
    }
    Ok(())
}

/// Whether two measurements are the same to the bit.
fn same_bits(a: &Measurement, b: &Measurement) -> bool {
    a.fell == b.fell
        && a.x_m.to_bits() == b.x_m.to_bits()
        && a.y_m.to_bits() == b.y_m.to_bits()
        && a.fall_time_s.map(f64::to_bits) == b.fall_time_s.map(f64::to_bits)
        && a.sim_time_s.to_bits() == b.sim_time_s.to_bits()
}

fn measurement_json(m: &Measurement) -> serde_json::Value {
    serde_json::json!({
        "fell": m.fell,
        "x_m": m.x_m,
        "y_m": m.y_m,
        "fall_time_s": m.fall_time_s,
        "sim_time_s": m.sim_time_s,
    })
}

/// `naofarm trial --run DIR --iteration I --trial K`: re-runs a farm trial
/// exactly as its worker did, and compares it with the journal.
fn replay(a: &TrialArgs, dir: &std::path::Path, iteration: u64, k: u32) -> Result<(), Failure> {
    use coordinator::run::{farm_trial, RunError};
    let ft = farm_trial(dir, iteration, k).map_err(|e| match e {
        RunError::Refused(_) => Failure::Usage(anyhow!("--run {}: {e}", dir.display())),
        RunError::Journal(coordinator::journal::JournalError::Io { .. }) => {
            Failure::Usage(e.into())
        }
        e => Failure::Job(e.into()),
    })?;
    let req = &ft.request;
    let values = ParamValues::from_named(&req.params).map_err(|e| Failure::Job(e.into()))?;
    if let Some(path) = &a.record {
        if req.model != protocol::TrialModel::Nao {
            return Err(Failure::Usage(anyhow!(
                "--record: the run's model is {:?}; only NAO trials have poses",
                req.model
            )));
        }
        let what = Recording {
            robot_type: req.robot_type,
            seed: req.seed,
            duration: req.duration_s,
            params: &req.params,
            values: &values,
        };
        record(path, &what, SimSettings::with_physics(&req.physics))?;
    }
    let m = worker::run_trial(req).map_err(|e| Failure::Job(e.into()))?;
    let same = ft.journaled.as_ref().map(|(j, _)| same_bits(j, &m));
    if a.json {
        outln!(
            "{}",
            serde_json::json!({
                "run": req.run,
                "iteration": iteration,
                "trial": k,
                "seed": req.seed,
                "robot_type": req.robot_type,
                "params": params_json(&req.params),
                "replayed": measurement_json(&m),
                "journaled": ft.journaled.as_ref().map(|(j, _)| measurement_json(j)),
                "worker": ft.journaled.as_ref().map(|(_, w)| w),
                "identical": same,
            })
        );
    } else {
        let line = |m: &Measurement| {
            format!(
                "x {} m, y {} m, {}",
                m.x_m,
                m.y_m,
                m.fall_time_s
                    .map_or("no fall".to_string(), |t| format!("fell at {t} s"))
            )
        };
        outln!(
            "run `{}` iteration {iteration} trial {k} (seed {}): {}",
            req.run,
            req.seed,
            line(&m)
        );
        match &ft.journaled {
            Some((j, w)) => outln!(
                "journaled by worker {w}: {} — {}",
                line(j),
                if same == Some(true) {
                    "identical to the bit"
                } else {
                    "DIFFERENT"
                }
            ),
            None => outln!("not journaled yet (the trial has not been run on the farm)"),
        }
    }
    if same == Some(false) {
        return Err(Failure::Job(anyhow!(
            "the replay of iteration {iteration} trial {k} differs from the journal \
             (another build or CPU than the worker that ran it?)"
        )));
    }
    Ok(())
}

/// One trial as `trial --json` lists it.
fn trial_json(t: &NaoTrial) -> serde_json::Value {
    let m = &t.measurement;
    serde_json::json!({
        "seed": t.seed,
        "fell": m.fell,
        "x": m.x_m,
        "y": m.y_m,
        "fall_time_s": m.fall_time_s,
        "diverged": t.diverged,
        "sim_time_s": m.sim_time_s,
    })
}

/// A parameter set as a JSON object of name → value.
fn params_json(params: &[(String, f64)]) -> serde_json::Map<String, serde_json::Value> {
    params
        .iter()
        .map(|(k, v)| (k.clone(), serde_json::json!(v)))
        .collect()
}

/// One trial to record: which robot, seed, duration and parameters.
#[derive(Clone, Copy)]
struct Recording<'a> {
    robot_type: u8,
    seed: u64,
    duration: f64,
    params: &'a [(String, f64)],
    values: &'a ParamValues,
}

/// Writes the replay of one trial: a header line (robot type, seed,
/// parameters, body names and shapes), then one line per cycle with the time
/// and every body's centre pose (x, y, z, qx, qy, qz, qw; world frame, m).
fn record(
    path: &std::path::Path,
    what: &Recording<'_>,
    settings: SimSettings,
) -> Result<(), Failure> {
    let Recording {
        robot_type,
        seed,
        duration,
        params,
        values,
    } = *what;
    use std::io::Write;
    let file = std::fs::File::create(path)
        .map_err(|e| Failure::Usage(anyhow!("--record {}: {e}", path.display())))?;
    let mut out = std::io::BufWriter::new(file);
    let model = NaoModel::with_params(robot_type, values).map_err(|e| Failure::Usage(e.into()))?;
    let header = serde_json::json!({
        "robot_type": robot_type,
        "seed": seed,
        "params": params_json(params),
        "cycle_s": CYCLE_S,
        "bodies": model.bodies.iter().map(|b| serde_json::json!({"name": b.name, "shape": b.shape})).collect::<Vec<_>>(),
    });
    let mut io = writeln!(out, "{header}");
    let t = trial::run_observed(
        robot_type,
        values,
        seed,
        duration,
        settings,
        &mut |sim, p| {
            if io.is_ok() {
                let line = serde_json::json!({"t": p.time_s, "poses": sim.body_poses()});
                io = writeln!(out, "{line}");
            }
        },
    )
    .map_err(|e| Failure::Job(e.into()))?;
    io.and_then(|()| out.flush())
        .map_err(|e| Failure::Job(anyhow!("--record {}: {e}", path.display())))?;
    eprintln!(
        "recorded seed {} ({} cycles{}) to {}",
        seed,
        (t.measurement.sim_time_s / CYCLE_S).round(),
        if t.measurement.fell { ", fell" } else { "" },
        path.display()
    );
    Ok(())
}

/// Arguments of `bench sim`.
#[derive(Args, Debug)]
pub struct SimBenchArgs {
    /// Simulated seconds per measurement.
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Machine-readable output.
    #[arg(long)]
    json: bool,
}

struct Row {
    label: String,
    motion: &'static str,
    settings: SimSettings,
    sim_s: f64,
    wall_s: f64,
    fell: bool,
}

fn measure_stand(settings: SimSettings, seconds: f64) -> Result<Row, Failure> {
    let model =
        NaoModel::with_params(0, &ParamValues::default()).map_err(|e| Failure::Job(e.into()))?;
    let q = standing_angles(&model);
    let t0 = Instant::now();
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
        wall_s: t0.elapsed().as_secs_f64(),
        fell,
    })
}

fn measure_walk(settings: SimSettings, seconds: f64) -> Result<Row, Failure> {
    let t0 = Instant::now();
    let t = trial::run_observed(
        0,
        &ParamValues::default(),
        1,
        seconds,
        settings,
        &mut |_, _| {},
    )
    .map_err(|e| Failure::Job(e.into()))?;
    Ok(Row {
        label: String::new(),
        motion: "walk",
        settings,
        sim_s: t.measurement.sim_time_s,
        wall_s: t0.elapsed().as_secs_f64(),
        fell: t.measurement.fell,
    })
}

/// `naofarm bench sim`: real-time factor and physics steps per second on one core.
pub fn bench_sim(a: &SimBenchArgs) -> Result<(), Failure> {
    if !(a.seconds.is_finite() && a.seconds >= 1.0 && a.seconds <= 600.0) {
        return Err(Failure::Usage(anyhow!("--seconds must be in [1, 600]")));
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
    let mut rows = Vec::new();
    for (label, s) in variants {
        for motion in ["stand", "walk"] {
            let mut r = if motion == "stand" {
                measure_stand(s, a.seconds)?
            } else {
                measure_walk(s, a.seconds)?
            };
            r.label = label.to_string();
            rows.push(r);
        }
    }
    let rtf = |r: &Row| r.sim_s / r.wall_s;
    let sps = |r: &Row| r.sim_s / CYCLE_S * f64::from(r.settings.substeps) / r.wall_s;
    let headline = rows
        .iter()
        .find(|r| r.motion == "walk" && r.settings == d)
        .ok_or_else(|| Failure::Job(anyhow!("no default walk row")))?;
    if a.json {
        let v = serde_json::json!({
            "realtime_factor": rtf(headline),
            "steps_per_second": sps(headline),
            "motion": "expert walk, type 0, default settings, one core",
            "rows": rows.iter().map(|r| serde_json::json!({
                "settings": r.label,
                "motion": r.motion,
                "substeps": r.settings.substeps,
                "solver_iterations": r.settings.solver_iterations,
                "pgs_iterations": r.settings.pgs_iterations,
                "weld_upper_body": r.settings.weld_upper_body,
                "realtime_factor": rtf(r),
                "steps_per_second": sps(r),
                "fell": r.fell,
            })).collect::<Vec<_>>(),
        });
        outln!("{v}");
    } else {
        outln!(
            "{:<44} {:>6} {:>10} {:>12} {:>6}",
            "settings",
            "motion",
            "realtime×",
            "steps/s",
            "fell"
        );
        for r in &rows {
            outln!(
                "{:<44} {:>6} {:>10.1} {:>12.0} {:>6}",
                r.label,
                r.motion,
                rtf(r),
                sps(r),
                r.fell
            );
        }
    }
    Ok(())
}
