//! Argument definitions and dispatch to the crates.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Parser, Subcommand};
use protocol::Experiment;

use crate::net::NetArgs;

/// Exit-code classes: 2 for usage or configuration errors, 1 for a failed job.
pub enum Failure {
    /// Bad arguments, a bad file: exit 2.
    Usage(anyhow::Error),
    /// The job itself failed: exit 1.
    Job(anyhow::Error),
}

/// A distributed trial farm that co-evolves a simulated NAO's body and walk.
#[derive(Parser)]
#[command(name = "naofarm", version, about)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// All in one: a coordinator and local workers over zenoh on loopback.
    Run {
        #[command(flatten)]
        job: JobArgs,
        /// Local workers to start (each with one slot); default: one per core.
        #[arg(long)]
        workers: Option<u32>,
        /// Print one JSON line per event instead of the progress view.
        #[arg(long)]
        json: bool,
        /// The loopback endpoint to serve on (default: a free port), e.g. tcp/127.0.0.1:7447,
        /// so that `naofarm watch` can be pointed at it.
        #[arg(long, value_name = "ENDPOINT")]
        listen: Option<String>,
    },
    /// The coordinator alone (cluster use): owns the run, its journal and dispatch.
    Coordinator {
        #[command(flatten)]
        job: JobArgs,
        #[command(flatten)]
        net: NetArgs,
        /// Print one JSON line per decided iteration.
        #[arg(long)]
        json: bool,
    },
    /// A stateless worker (cluster use): runs trials for any coordinator it reaches.
    Worker {
        #[command(flatten)]
        net: NetArgs,
        /// Trials run at once (default: cores).
        #[arg(long)]
        slots: Option<u32>,
        /// Minimum wall time per trial in ms (paces the synthetic model for farm tests and benchmarks).
        #[arg(long, default_value_t = 0)]
        min_trial_ms: u64,
    },
    /// Print the rebuilt robot: mass, segment lengths, hip-to-sole height, joint table.
    Model {
        /// League robot type 0–4.
        #[arg(long = "type", default_value_t = 0)]
        robot_type: u8,
        /// Override a morphology quantity, NAME=VALUE (repeatable), e.g. ThighRelHip2_Z=-0.05.
        #[arg(long = "param", value_name = "NAME=VALUE")]
        params: Vec<String>,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Hold a standing posture with the servos; report falls and torso height.
    Stand(crate::robot::StandArgs),
    /// Run n walking trials of one parameter set locally; print the Table IV row.
    Trial(crate::robot::TrialArgs),
    /// Benchmarks: `bench clop` (regret and cost), `bench sim` (physics speed).
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Tune any noisy program locally with CLOP (an evaluator process or a script per game).
    Clop(crate::tune::ClopArgs),
    /// Follow a run from any machine (live view or JSON lines); without RUN, list the runs.
    Watch(crate::watch::WatchArgs),
    /// Print a run's decided history H (iteration, p, s, mx, my, ex, ey, decision, best).
    History {
        /// The run directory.
        dir: PathBuf,
        /// An array of JSON rows.
        #[arg(long)]
        json: bool,
        /// Comma-separated values with a header line.
        #[arg(long)]
        csv: bool,
    },
    /// Verify a run's journal (`check`) or copy its valid records into a new run (`salvage`).
    #[command(subcommand)]
    Journal(crate::journal::JournalCommand),
    /// Validate an experiment file and print it as parsed.
    Check {
        /// The experiment file (TOML).
        experiment: PathBuf,
        /// Print the parsed experiment as JSON.
        #[arg(long)]
        json: bool,
    },
}

/// Runs the chosen subcommand.
pub fn dispatch(cli: Cli) -> Result<(), Failure> {
    match cli.command {
        Command::Check { experiment, json } => check(&experiment, json),
        Command::Run {
            job,
            workers,
            json,
            listen,
        } => crate::farm::run(&job, workers, json, listen.as_deref()),
        Command::Coordinator { job, net, json } => crate::farm::coordinator(&job, &net, json),
        Command::Worker {
            net,
            slots,
            min_trial_ms,
        } => crate::farm::worker(&net, slots, min_trial_ms),
        Command::Watch(a) => crate::watch::watch(&a),
        Command::Clop(a) => crate::tune::clop(&a),
        Command::History { dir, json, csv } => crate::history::history(&dir, json, csv),
        Command::Journal(j) => crate::journal::journal(j),
        Command::Bench(b) => crate::benches::bench(b),
        Command::Stand(a) => crate::robot::stand(&a),
        Command::Trial(a) => crate::robot::trial(&a),
        Command::Model {
            robot_type,
            params,
            json,
        } => model(robot_type, &params, json),
    }
}

/// What `run` and `coordinator` share: the experiment, the run directory, overrides.
#[derive(clap::Args, Debug, Clone)]
pub struct JobArgs {
    /// The experiment file (TOML).
    pub experiment: PathBuf,
    /// The run directory (journal); an existing one is resumed.
    #[arg(long)]
    pub out: PathBuf,
    /// Override the number of iterations.
    #[arg(long)]
    pub iterations: Option<u64>,
    /// Override the seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Override the trial model (`nao` or `synthetic`).
    #[arg(long)]
    pub model: Option<String>,
    /// Start from an earlier run's history (its run directory).
    #[arg(long)]
    pub from: Option<PathBuf>,
    /// Seconds a worker may hold a trial before it is given to another.
    #[arg(long, default_value_t = 120.0)]
    pub lease_s: f64,
    /// Distinct workers that may fail one trial before the run stops (1–100;
    /// a resumed run may raise it to retry the trial that stopped it).
    #[arg(long, default_value_t = 3)]
    pub max_trial_failures: u32,
}

/// Benchmarks.
#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// CLOP: simple regret on the test problems beside baselines, and cost per step.
    Clop(crate::benches::ClopBenchArgs),
    /// The rebuilt NAO: real-time factor and physics steps/s, standing and walking, per settings.
    Sim(crate::robot::SimBenchArgs),
    /// The farm: trials/s and coordinator CPU per trial through real processes on loopback.
    Farm(crate::benches::FarmBenchArgs),
}

/// Writes `text` to stdout; a closed pipe (`| head`) ends quietly.
pub fn emit(text: &str) -> Result<(), Failure> {
    crate::out::write(text);
    Ok(())
}

/// Reads and validates an experiment file (a usage error when it is bad).
pub fn load_experiment(path: &Path) -> Result<(Experiment, String), Failure> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read {}", path.display()))
        .map_err(Failure::Usage)?;
    let e = Experiment::from_toml(&text)
        .with_context(|| format!("{}", path.display()))
        .map_err(Failure::Usage)?;
    Ok((e, text))
}

fn check(path: &Path, json: bool) -> Result<(), Failure> {
    let (e, _) = load_experiment(path)?;
    if json {
        let text = serde_json::to_string_pretty(&e)
            .context("encode JSON")
            .map_err(Failure::Job)?;
        outln!("{text}");
        return Ok(());
    }
    outln!(
        "experiment `{}` (seed {}, model {:?}, robot type {}, start {:?})",
        e.name,
        e.seed,
        e.model,
        e.robot_type,
        e.start
    );
    outln!(
        "  {} iterations x {} trials of {} s, pipeline depth {}",
        e.iterations,
        e.trials_per_iteration,
        e.trial_duration_s,
        e.pipeline_depth
    );
    outln!("  parameters (L):");
    for p in &e.parameter {
        outln!(
            "    {:<36} {:<8} [{}, {}]  expert {}",
            p.name,
            format!("{:?}", p.kind).to_lowercase(),
            p.lower,
            p.upper,
            p.expert_value()
        );
    }
    if !e.fixed.is_empty() {
        outln!("  fixed:");
        for (k, v) in &e.fixed {
            outln!("    {k:<36} {v}");
        }
    }
    let k = &e.pickout;
    outln!(
        "  pickOut: SUCCESS_RATE {} XY_RATIO {} alpha {} beta {} gamma {}",
        k.success_rate,
        k.xy_ratio,
        k.alpha,
        k.beta,
        k.gamma
    );
    let c = &e.clop;
    outln!(
        "  CLOP: H {} DrawElo {} correlations {} prior {} refresh {} max weight iterations {} nMCMC {}",
        c.h,
        c.draw_elo,
        if c.correlations { "all" } else { "none" },
        c.prior_strength,
        c.refresh_rate,
        c.max_weight_iterations,
        c.n_mcmc
    );
    Ok(())
}

pub(crate) fn parse_params(params: &[String]) -> Result<Vec<(String, f64)>, Failure> {
    params
        .iter()
        .map(|p| {
            let (name, value) = p.split_once('=').ok_or_else(|| {
                Failure::Usage(anyhow::anyhow!("--param `{p}`: expected NAME=VALUE"))
            })?;
            let v: f64 = value.trim().parse().map_err(|_| {
                Failure::Usage(anyhow::anyhow!("--param `{p}`: `{value}` is not a number"))
            })?;
            if !v.is_finite() {
                return Err(Failure::Usage(anyhow::anyhow!(
                    "--param `{p}`: not a finite number"
                )));
            }
            Ok((name.trim().to_string(), v))
        })
        .collect()
}

/// The league's type `robot_type` with morphology overrides NAME=VALUE (a
/// walk parameter or an unknown name is a usage error).
pub(crate) fn morphology(
    robot_type: u8,
    params: &[String],
) -> Result<worker::nao::model::Morphology, Failure> {
    use worker::nao::model::{ModelError, Morphology};
    let mut m = Morphology::of_type(robot_type).map_err(|e| Failure::Usage(e.into()))?;
    for (name, v) in parse_params(params)? {
        let p = protocol::params::find(&name).ok_or(ModelError::Unknown(name.clone()));
        p.and_then(|p| m.set(p.param, v))
            .map_err(|e| Failure::Usage(e.into()))?;
    }
    Ok(m)
}

fn model(robot_type: u8, params: &[String], json: bool) -> Result<(), Failure> {
    use worker::nao::model::NaoModel;
    let m = morphology(robot_type, params)?;
    let model = NaoModel::new(m).map_err(|e| Failure::Usage(e.into()))?;
    let mo = &model.morphology;
    if json {
        let joints: Vec<serde_json::Value> = model
            .joints
            .iter()
            .map(|j| {
                serde_json::json!({
                    "name": j.name,
                    "parent": model.bodies[j.parent].name,
                    "child": model.bodies[j.child].name,
                    "anchor_m": j.anchor,
                    "axis": j.axis,
                    "lower_rad": j.limits_rad.0,
                    "upper_rad": j.limits_rad.1,
                    "max_speed_rad_s": j.max_speed_rad_s,
                })
            })
            .collect();
        let v = serde_json::json!({
            "robot_type": mo.robot_type,
            "total_mass_kg": model.total_mass_kg(),
            "thigh_m": mo.thigh_m(),
            "tibia_m": mo.tibia_m(),
            "hip_to_sole_m": mo.hip_to_sole_m(),
            "torso_to_sole_m": mo.torso_to_sole_m(),
            "hip_width_m": mo.hip_width_m(),
            "centre_of_mass_m": model.centre_of_mass(),
            "morphology": mo,
            "joints": joints,
        });
        outln!(
            "{}",
            serde_json::to_string_pretty(&v).map_err(|e| Failure::Job(e.into()))?
        );
        return Ok(());
    }
    outln!(
        "NAO type {} (frame: x forward, y left, z up; torso-centred, zero pose)",
        mo.robot_type
    );
    outln!("  total mass        {:.4} kg", model.total_mass_kg());
    outln!(
        "  thigh / tibia     {:.5} / {:.5} m",
        mo.thigh_m(),
        mo.tibia_m()
    );
    outln!("  hip to sole       {:.5} m", mo.hip_to_sole_m());
    outln!("  torso to sole     {:.5} m", mo.torso_to_sole_m());
    outln!("  hip width         {:.5} m", mo.hip_width_m());
    let c = model.centre_of_mass();
    outln!(
        "  centre of mass    ({:.4}, {:.4}, {:.4}) m",
        c[0],
        c[1],
        c[2]
    );
    outln!(
        "  {:<6} {:<10} {:<10} {:>9} {:>9} {:>9}",
        "joint",
        "parent",
        "child",
        "lower°",
        "upper°",
        "rad/s"
    );
    for j in &model.joints {
        outln!(
            "  {:<6} {:<10} {:<10} {:>9.1} {:>9.1} {:>9.4}",
            j.name,
            model.bodies[j.parent].name,
            model.bodies[j.child].name,
            j.limits_rad.0.to_degrees(),
            j.limits_rad.1.to_degrees(),
            j.max_speed_rad_s
        );
    }
    Ok(())
}
