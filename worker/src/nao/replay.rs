//! The replay file of one NAO trial, for watching a walk: JSON lines, first a
//! header (`robot_type`, `seed`, `params` as name → value, `cycle_s`, and
//! `bodies` with `name` and `shape`, `joints` with the model's joint names,
//! `planted_n`, the load from which a foot counts as planted,
//! [`super::footwork::PLANTED_N`]),
//! then one line per 20 ms cycle with `t`; `poses`, each body's centre as
//! `[x, y, z, qx, qy, qz, qw]` (world frame: x forward, y left, z up; m);
//! `angles`, each joint's angle at the cycle's end, and `targets`, the angle
//! the cycle's servo commands steered it to (both rad, in `joints` order; the
//! angles are the simulation's, without the sensors' noise); and `load`, the
//! ground's vertical force on the left and right foot (N). `scripts/tracking.py`
//! reads the last three: how the joints track, and where the steps land.

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
        "feedback": engine.feedback,
        "params": named,
        "cycle_s": CYCLE_S,
        "bodies": bodies,
        "joints": model.joints.iter().map(|j| j.name.as_str()).collect::<Vec<_>>(),
        "planted_n": super::footwork::PLANTED_N,
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
        &mut |sim, p, targets| {
            if io.is_ok() {
                let line = serde_json::json!({
                    "t": p.time_s,
                    "poses": sim.body_poses(),
                    "angles": p.joint_angles_rad,
                    "targets": targets,
                    "load": [p.foot_force_n[0][2], p.foot_force_n[1][2]],
                });
                io = writeln!(out, "{line}");
            }
        },
    )?;
    io?;
    out.flush()?;
    Ok(t)
}
