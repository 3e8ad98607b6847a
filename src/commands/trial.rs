//! `naofarm trial`: n noisy walking trials of one parameter set, locally (the
//! Table IV row), or one farm trial replayed from its run's journal.

use std::time::Instant;

use anyhow::anyhow;
use protocol::{
    measurement::Measurement, params::ParamValues, pickout::stats, Experiment, TrialModel,
};
use worker::nao::{
    footwork::Footwork,
    model::NaoModel,
    replay::Replayed,
    sim::{SimSettings, CYCLE_S},
    trial::{self, Batch, NaoTrial, StopExcess},
};

use crate::{
    args::TrialArgs,
    common::{load_experiment, parse_params, usage_unless, Failure},
};

/// `naofarm trial`: n trials of one parameter set, the Table IV row.
pub fn trial(a: &TrialArgs) -> Result<(), Failure> {
    if let (Some(dir), Some(i), Some(k)) = (&a.run_dir, a.iteration, a.trial) {
        return replay(a, dir, i, k);
    }
    let trials_ok = (1..=100_000).contains(&a.trials);
    usage_unless(trials_ok, || "--trials must be in 1..=100000".into())?;
    let (exp, start) = start_from(a)?.unzip();
    if let Some(e) = exp.as_ref().filter(|e| e.model != TrialModel::Nao) {
        return Err(Failure::Usage(anyhow!(match &e.program {
            Some(p) => format!(
                "--experiment: a trial runs the NAO; this run's trials run the program `{p}` \
                 (`report --program {p}=PATH` runs its Table IV)"
            ),
            None => "--experiment: a trial runs the NAO, not `synthetic`".into(),
        })));
    }
    let duration = a
        .duration
        .or(exp.as_ref().map(|e| e.trial_duration_s))
        .unwrap_or(10.0);
    let duration_ok = duration.is_finite() && duration > 0.0 && duration <= 3600.0;
    usage_unless(duration_ok, || {
        "--duration must be in (0, 3600] s, as an experiment's trial_duration_s".into()
    })?;
    let robot_type = a
        .robot_type
        .or(exp.as_ref().map(|e| e.robot_type))
        .unwrap_or(0);
    // The experiment's set (--set) and fixed values, then each --param over them.
    let mut params = exp
        .as_ref()
        .zip(start.as_deref())
        .map(|(e, v)| e.full_params(v))
        .unwrap_or_default();
    let given = parse_params(&a.params)?;
    for (name, v) in &given {
        match params.iter_mut().find(|(n, _)| n == name) {
            Some(slot) => slot.1 = *v,
            None => params.push((name.clone(), *v)),
        }
    }
    if let Some(e) = &exp {
        for (name, note) in crate::common::type_overrides(e, robot_type) {
            if !given.iter().any(|(n, _)| *n == name) {
                eprintln!("note: {note}");
            }
        }
    }
    let values = ParamValues::from_named(&params).map_err(|e| Failure::Usage(e.into()))?;
    NaoModel::with_params(robot_type, &values).map_err(|e| Failure::Usage(e.into()))?;
    if a.threads.is_some_and(|t| t == 0 || t > 1024) {
        return Err(Failure::Usage(anyhow!("--threads must be in 1..=1024")));
    }
    let threads = a
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, usize::from));
    let d = exp.as_ref().map(|e| e.physics).unwrap_or_default();
    let physics = protocol::Physics {
        substeps: a.substeps.unwrap_or(d.substeps),
        solver_iterations: a.solver_iterations.unwrap_or(d.solver_iterations),
        pgs_iterations: a.pgs_iterations.unwrap_or(d.pgs_iterations),
    };
    physics.validate().map_err(|(field, m)| {
        let flag = field.trim_end_matches("_kg_m2").replace('_', "-");
        Failure::Usage(anyhow!("--{flag}: {m}"))
    })?;
    let settings = SimSettings::with_physics(&physics);
    let engine = if a.no_feedback {
        trial::Engine::WALK.without_feedback()
    } else {
        trial::Engine::WALK
    };
    let first = Replayed {
        robot_type,
        seed: a.seed,
        duration_s: duration,
        params: &params,
        values: &values,
        settings,
        engine,
    };
    if let Some(path) = &a.record {
        record(path, &first)?;
    }
    if let Some(path) = &a.render {
        render(path, &first, &format!("seed {}", a.seed))?;
    }
    let t0 = Instant::now();
    let runs = trial::run_many(
        robot_type,
        &values,
        Batch {
            seed0: a.seed,
            n: a.trials,
            threads,
        },
        duration,
        settings,
        engine,
    )
    .map_err(|e| Failure::Job(e.into()))?;
    let wall = t0.elapsed().as_secs_f64();
    let results: Vec<_> = runs.iter().map(|t| t.measurement).collect();
    let s = stats(&results);
    let diverged = runs.iter().filter(|t| t.diverged).count();
    let planned = trial::planned_travel_m(robot_type, &values, duration)
        .map_err(|e| Failure::Job(e.into()))?;
    let step = trial::planned_step_m(robot_type, &values).map_err(|e| Failure::Job(e.into()))?;
    let reach = trial::reach_step_m(robot_type, &values).map_err(|e| Failure::Job(e.into()))?;
    // Over the trials that did not fall, the ones mx averages.
    let split = Footwork::mean(
        runs.iter()
            .filter(|t| !t.measurement.fell)
            .map(|t| &t.footwork),
    );
    if a.json {
        let v = serde_json::json!({
            "set": crate::common::set_key(&a.set),
            "params": params_json(&params),
            "robot_type": robot_type,
            "feedback": engine.feedback,
            "duration_s": duration,
            "physics": physics,
            "s": s.s,
            "mx": s.mx,
            "my": s.my,
            "ex": s.ex,
            "ey": s.ey,
            "planned_m": planned,
            "planned_step_m": step,
            "reach_step_m": reach,
            "footwork": split,
            "trials": runs.iter().map(trial_json).collect::<Vec<_>>(),
            "diverged": diverged,
            "worst_stop_excess": worst_stop_excess(&runs).map(|(t, e)| {
                let mut v = stop_excess_json(e);
                v["seed"] = serde_json::json!(t.seed);
                v
            }),
            "speed_capped": speed_capped_shares(&runs)
                .into_iter()
                .map(|(joint, share)| (joint, serde_json::json!(share)))
                .collect::<serde_json::Map<_, _>>(),
            "wall_s": wall,
        });
        outln!("{v}");
    } else {
        let f = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.3}"));
        outln!(
            "     s     mx     my     ex     ey   (m; {} trials of {} s)",
            a.trials,
            duration
        );
        outln!(
            "{:6.2} {:>6} {:>6} {:>6} {:>6}",
            s.s,
            f(s.mx),
            f(s.my),
            f(s.ex),
            f(s.ey)
        );
        let asked = values.walk().step_length;
        if step < asked {
            outln!(
                "the walk's plan: {planned:.3} m, in steps of {step:.4} m \
                 (xlength_step_max {asked:.4} m, capped at the legs' reach)"
            );
        } else {
            outln!("the walk's plan: {planned:.3} m, in steps of {step:.4} m");
        }
        if let Some(w) = &split {
            outln!(
                "mx split by the feet: stepping {:.3} m, sliding {:.3} m, lean {:.3} m; \
                 {} plants per trial",
                w.stepping_m,
                w.sliding_m,
                w.lean_m,
                w.plants
            );
            if w.touchdowns > 0 {
                outln!(
                    "the feet land {:+.1} mm beyond the legs' aim per step ({} touchdowns per trial)",
                    w.overreach_m * 1000.0,
                    w.touchdowns
                );
                outln!(
                    "at touchdown the feet are {:.4} m apart (the plan's step: {step:.4} m); \
                     the foot that landed before has moved on {:+.1} mm",
                    w.spacing_m,
                    w.settle_m * 1000.0
                );
            }
            outln!(
                "the torso's mean pitch: {:+.1}° (negative: leaning back)",
                w.torso_pitch_deg
            );
        }
        if diverged > 0 {
            outln!("{diverged} of the falls were the physics diverging (counted as falls, no distance)");
        }
        match worst_stop_excess(&runs) {
            Some((t, e)) => outln!(
                "farthest past a stop: {:.2}° ({} at {:.2} s, seed {})",
                e.rad.to_degrees(),
                e.joint,
                e.time_s,
                t.seed
            ),
            None => outln!("no joint went past its stops"),
        }
        let mut capped = speed_capped_shares(&runs);
        capped.sort_by(|a, b| b.1.total_cmp(&a.1));
        if !capped.is_empty() {
            let most: Vec<String> = capped
                .iter()
                .take(6)
                .map(|(j, share)| format!("{j} {:.0} %", 100.0 * share))
                .collect();
            outln!(
                "commands clamped at the speed cap, share of cycles: {}",
                most.join(", ")
            );
        }
        outln!(
            "{:.1} trials/s on {threads} thread{} ({wall:.2} s wall)",
            a.trials as f64 / wall,
            if threads == 1 { "" } else { "s" }
        );
    }
    Ok(())
}

/// The experiment `--experiment` names and the values `--set` picks in it:
/// an experiment file's expert set, or one of a run directory's Table IV
/// sets (`expert`, `optim1`: ν′, `optim2`: CLOP's mean), with the run's
/// experiment as it journaled it. `None`: no experiment.
fn start_from(a: &TrialArgs) -> Result<Option<(Experiment, Vec<f64>)>, Failure> {
    let key = crate::common::set_key(&a.set);
    let known = coordinator::evolve::TABLE_SETS;
    if !known.iter().any(|name| crate::common::set_key(name) == key) {
        return Err(Failure::Usage(anyhow!(
            "--set `{}`: the sets are `expert` and a run's `optim1` (ν′) and `optim2` (CLOP's mean)",
            a.set
        )));
    }
    let Some(path) = a.experiment.as_deref() else {
        if key == "expert" {
            return Ok(None);
        }
        return Err(Failure::Usage(anyhow!(
            "--set {key} is a set a run found: give --experiment the run's directory"
        )));
    };
    if !path.is_dir() {
        let (e, _) = load_experiment(path)?;
        if key != "expert" {
            return Err(Failure::Usage(anyhow!(
                "--set {key} is a set a run found: {} is an experiment file, which has only \
                 `expert`; give --experiment the run's directory",
                path.display()
            )));
        }
        let values = e.expert_values();
        return Ok(Some((e, values)));
    }
    let run = crate::common::replay_run(path)?;
    let found = run
        .table_sets()
        .into_iter()
        .find(|(name, _)| crate::common::set_key(name) == key);
    match found {
        Some((_, values)) => Ok(Some((run.experiment().clone(), values))),
        None => Err(Failure::Usage(anyhow!(
            "--set {key}: the run in {} has no ν′ yet (no iteration accepted)",
            path.display()
        ))),
    }
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
    if a.record.is_some() || a.render.is_some() {
        if req.model != protocol::TrialModel::Nao {
            return Err(Failure::Usage(anyhow!(
                "--record/--render: the run's model is {:?}; only NAO trials have poses",
                req.model
            )));
        }
        let what = Replayed {
            robot_type: req.robot_type,
            seed: req.seed,
            duration_s: req.duration_s,
            params: &req.params,
            values: &values,
            settings: SimSettings::with_physics(&req.physics),
            engine: trial::Engine::WALK,
        };
        if let Some(path) = &a.record {
            record(path, &what)?;
        }
        if let Some(path) = &a.render {
            render(
                path,
                &what,
                &format!("iteration {iteration}, trial {k} (seed {})", req.seed),
            )?;
        }
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
        "stop_excess": t.stop_excess.iter().map(stop_excess_json).collect::<Vec<_>>(),
        "cycles": t.cycles,
        "substeps": t.substeps,
        "footwork": t.footwork,
        "speed_capped": t
            .speed_capped
            .iter()
            .map(|c| (c.joint.clone(), serde_json::json!(c.cycles)))
            .collect::<serde_json::Map<_, _>>(),
    })
}

/// Each joint's share of all the trials' cycles whose command the servo
/// clamped at the joint's speed cap, in the order the trials first list the
/// joints (joints never clamped left out).
fn speed_capped_shares(runs: &[NaoTrial]) -> Vec<(String, f64)> {
    let cycles: u64 = runs.iter().map(|t| t.cycles).sum();
    let mut out: Vec<(String, u64)> = Vec::new();
    for c in runs.iter().flat_map(|t| &t.speed_capped) {
        match out.iter_mut().find(|(j, _)| *j == c.joint) {
            Some((_, n)) => *n += c.cycles,
            None => out.push((c.joint.clone(), c.cycles)),
        }
    }
    out.into_iter()
        .map(|(j, n)| (j, n as f64 / cycles.max(1) as f64))
        .collect()
}

/// A joint's worst overrun past its stops as `trial --json` lists it.
fn stop_excess_json(e: &StopExcess) -> serde_json::Value {
    serde_json::json!({
        "deg": e.rad.to_degrees(),
        "joint": e.joint,
        "time_s": e.time_s,
    })
}

/// The trial whose joint went farthest past a stop, if any did.
fn worst_stop_excess(runs: &[NaoTrial]) -> Option<(&NaoTrial, &StopExcess)> {
    runs.iter()
        .flat_map(|t| t.stop_excess.iter().map(move |e| (t, e)))
        .max_by(|a, b| a.1.rad.total_cmp(&b.1.rad))
}

/// A parameter set as a JSON object of name → value.
fn params_json(params: &[(String, f64)]) -> serde_json::Map<String, serde_json::Value> {
    params
        .iter()
        .map(|(k, v)| (k.clone(), serde_json::json!(v)))
        .collect()
}

/// Refuses (exit 2) to write `flag`'s `path` over a file that `ours` does
/// not recognise, by its first 64 KiB, as one this command wrote (`what`):
/// a new path, or an earlier replay or animation, is written; anything else
/// (a journal, someone's file) keeps its bytes.
fn ours_to_write(
    path: &std::path::Path,
    flag: &str,
    what: &str,
    ours: impl Fn(&[u8]) -> bool,
) -> Result<(), Failure> {
    use std::io::Read as _;
    let Ok(meta) = std::fs::metadata(path) else {
        return Ok(());
    };
    let usage = |why: &str| Failure::Usage(anyhow!("{flag} {}: {why}", path.display()));
    if !meta.is_file() {
        return Err(usage("exists and is not a file"));
    }
    let mut head = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(64 * 1024).read_to_end(&mut head))
        .map_err(|e| usage(&e.to_string()))?;
    if meta.len() > 0 && !ours(&head) {
        return Err(usage(&format!(
            "exists and is not {what}; give a new path (it is kept as it is)"
        )));
    }
    Ok(())
}

/// Writes the replay of one trial: a header line (robot type, seed,
/// parameters, body names and shapes), then one line per cycle with the time
/// and every body's centre pose (x, y, z, qx, qy, qz, qw; world frame, m).
fn record(path: &std::path::Path, what: &Replayed<'_>) -> Result<(), Failure> {
    ours_to_write(path, "--record", "a naofarm replay", |head| {
        let line = head.split(|&b| b == b'\n').next().unwrap_or_default();
        serde_json::from_slice::<serde_json::Value>(line).is_ok_and(|h| {
            ["robot_type", "seed", "cycle_s", "bodies", "joints"]
                .iter()
                .all(|k| h.get(k).is_some())
        })
    })?;
    let file = std::fs::File::create(path)
        .map_err(|e| Failure::Usage(anyhow!("--record {}: {e}", path.display())))?;
    let mut out = std::io::BufWriter::new(file);
    let t = worker::nao::replay::write(&mut out, what)
        .map_err(|e| Failure::Job(anyhow!("--record {}: {e}", path.display())))?;
    eprintln!(
        "recorded seed {} ({} cycles{}) to {}",
        what.seed,
        (t.measurement.sim_time_s / CYCLE_S).round(),
        if t.measurement.fell { ", fell" } else { "" },
        path.display()
    );
    Ok(())
}

/// Writes the animated SVG of one trial.
fn render(path: &std::path::Path, what: &Replayed<'_>, title: &str) -> Result<(), Failure> {
    ours_to_write(path, "--render", "a naofarm trial animation", |head| {
        head.starts_with(b"<svg ")
            && String::from_utf8_lossy(head).contains(crate::render::TRIAL_SVG_CAPTION)
    })?;
    let svg = crate::render::trial_svg(what, title)
        .map_err(|e| Failure::Job(anyhow!("--render {}: {e}", path.display())))?;
    std::fs::write(path, svg)
        .map_err(|e| Failure::Usage(anyhow!("--render {}: {e}", path.display())))?;
    eprintln!("rendered seed {} to {}", what.seed, path.display());
    Ok(())
}
