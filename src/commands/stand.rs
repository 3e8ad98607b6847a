//! `naofarm stand`: the rebuilt NAO holding its standing posture with the servos.

use anyhow::anyhow;
use worker::nao::{
    model::NaoModel,
    sim::{fallen, standing_angles, Sim, SimSettings, Start, CYCLE_S},
};

use crate::{args::StandArgs, common::Failure};

/// `naofarm stand`: hold the standing posture with the servos.
pub fn stand(a: &StandArgs) -> Result<(), Failure> {
    if !(a.seconds.is_finite() && a.seconds > 0.0 && a.seconds <= 3600.0) {
        return Err(Failure::Usage(anyhow!("--seconds must be in (0, 3600]")));
    }
    let m = crate::common::morphology(a.robot_type, &a.params)?;
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
