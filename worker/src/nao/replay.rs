//! The replay file of one NAO trial, for watching a walk: JSON lines, first a
//! header (`robot_type`, `seed`, `params` as name → value, `cycle_s`, and
//! `bodies` with `name` and `shape`), then one line per 20 ms cycle with `t`
//! and `poses`, each body's centre as `[x, y, z, qx, qy, qz, qw]` (world
//! frame: x forward, y left, z up; m).

use std::io::Write;

use protocol::params::ParamValues;

use super::{
    model::NaoModel,
    sim::{SimSettings, CYCLE_S},
    trial::{self, NaoTrial, NaoTrialError},
};

/// Why a replay could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The trial could not run.
    #[error(transparent)]
    Trial(#[from] NaoTrialError),
    /// Writing failed.
    #[error("writing the replay: {0}")]
    Io(#[from] std::io::Error),
}

/// The trial a replay shows.
#[derive(Debug, Clone, Copy)]
pub struct Replayed<'a> {
    /// League robot type.
    pub robot_type: u8,
    /// The trial's seed.
    pub seed: u64,
    /// Simulated seconds.
    pub duration_s: f64,
    /// The parameters as named in the header.
    pub params: &'a [(String, f64)],
    /// The same parameters, resolved.
    pub values: &'a ParamValues,
    /// Physics settings.
    pub settings: SimSettings,
    /// The walk engine.
    pub engine: trial::Engine,
}

/// Runs one trial and writes its replay to `out`; returns the trial.
pub fn write(out: &mut dyn Write, what: &Replayed<'_>) -> Result<NaoTrial, ReplayError> {
    let Replayed {
        robot_type,
        seed,
        duration_s,
        params,
        values,
        settings,
        engine,
    } = *what;
    let model = NaoModel::with_params(robot_type, values).map_err(NaoTrialError::from)?;
    let named: serde_json::Map<String, serde_json::Value> = params
        .iter()
        .map(|(k, v)| (k.clone(), serde_json::json!(v)))
        .collect();
    let bodies: Vec<serde_json::Value> = model
        .bodies
        .iter()
        .map(|b| serde_json::json!({"name": b.name, "shape": b.shape}))
        .collect();
    let header = serde_json::json!({
        "robot_type": robot_type,
        "seed": seed,
        "walk": engine.name(),
        "params": named,
        "cycle_s": CYCLE_S,
        "bodies": bodies,
    });
    writeln!(out, "{header}")?;
    let mut io = Ok(());
    let t = trial::run_observed(
        robot_type,
        values,
        seed,
        duration_s,
        settings,
        engine,
        &mut |sim, p| {
            if io.is_ok() {
                let line = serde_json::json!({"t": p.time_s, "poses": sim.body_poses()});
                io = writeln!(out, "{line}");
            }
        },
    )?;
    io?;
    out.flush()?;
    Ok(t)
}
