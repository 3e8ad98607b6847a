//! `naofarm model`: the rebuilt robot (mass, segments, joint table).

use crate::common::{morphology, Failure};

/// How `model` prints the robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// A table for people.
    Text,
    /// One JSON document.
    Json,
    /// An entry of SimSpark's `naorobottypes.rb`.
    Simspark,
}

/// Prints the league's type with morphology overrides.
pub fn model(robot_type: u8, params: &[String], format: Format) -> Result<(), Failure> {
    use worker::nao::model::NaoModel;
    let m = morphology(robot_type, params)?;
    let model = NaoModel::new(m).map_err(|e| Failure::Usage(e.into()))?;
    let mo = &model.morphology;
    if format == Format::Simspark {
        outln!("{}", mo.simspark_type());
        return Ok(());
    }
    if format == Format::Json {
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
