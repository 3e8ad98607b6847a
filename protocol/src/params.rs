//! The registry of parameter names an experiment may optimise.
//!
//! Every name a worker understands is listed here with the range a worker can
//! build and run (the *admissible* range). An experiment's bounds must lie
//! inside it; anything else is refused when the file is read, long before a
//! worker sees it.

/// One parameter the trial models understand.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnownParam {
    /// Identifier exactly as in the paper and the experiment files.
    pub name: &'static str,
    /// Smallest admissible value (external units).
    pub min: f64,
    /// Largest admissible value (external units).
    pub max: f64,
    /// Unit of the value.
    pub unit: &'static str,
    /// Value of the league's standard robot or the paper's expert set.
    pub default: f64,
    /// What it means.
    pub doc: &'static str,
}

/// Every parameter naofarm's trial models accept.
pub const KNOWN: &[KnownParam] = &[
    KnownParam {
        name: "ThighRelHip2_Z",
        min: -0.12,
        max: -0.005,
        unit: "m",
        default: -0.04,
        doc: "thigh centre below the hip; thigh length = 0.08 - value",
    },
    KnownParam {
        name: "ratio_flexion",
        min: 0.40,
        max: 0.99,
        unit: "1",
        default: 0.73,
        doc: "walking hip height over stretched leg length",
    },
    KnownParam {
        name: "long_offset_MidAnkles_2_Torso_Init",
        min: -0.05,
        max: 0.06,
        unit: "m",
        default: 0.011,
        doc: "forward offset of the torso over the mid-ankles",
    },
    KnownParam {
        name: "height_lift",
        min: 0.0,
        max: 0.12,
        unit: "m",
        default: 0.042,
        doc: "maximal swing-foot lift",
    },
    KnownParam {
        name: "xlength_step_max",
        min: 0.0,
        max: 0.25,
        unit: "m",
        default: 0.08,
        doc: "step length (the first two steps are half as long)",
    },
    KnownParam {
        name: "Hip1RelTorso_X",
        min: 0.04,
        max: 0.09,
        unit: "m",
        default: 0.055,
        doc: "lateral hip offset from the torso centre",
    },
    KnownParam {
        name: "Hip1RelTorso_Z",
        min: -0.14,
        max: -0.09,
        unit: "m",
        default: -0.115,
        doc: "hip height below the torso centre",
    },
    KnownParam {
        name: "AnkleRelShank_Z",
        min: -0.11,
        max: -0.03,
        unit: "m",
        default: -0.055,
        doc: "ankle below the shank centre; tibia length = 0.045 - value",
    },
    KnownParam {
        name: "ElbowRelUpperArm_Y",
        min: 0.04,
        max: 0.15,
        unit: "m",
        default: 0.07,
        doc: "elbow forward of the upper-arm centre",
    },
];

/// Looks a parameter up by its exact name.
#[must_use]
pub fn find(name: &str) -> Option<&'static KnownParam> {
    KNOWN.iter().find(|p| p.name == name)
}

/// Checks one value against the admissible range of its parameter.
///
/// Returns a message naming the parameter and its range on failure.
pub fn check_value(name: &str, value: f64) -> Result<(), String> {
    let Some(p) = find(name) else {
        return Err(format!(
            "unknown parameter `{name}` (known: {})",
            KNOWN.iter().map(|p| p.name).collect::<Vec<_>>().join(", ")
        ));
    };
    if !value.is_finite() {
        return Err(format!(
            "parameter `{name}` is {value}, not a finite number"
        ));
    }
    if value < p.min || value > p.max {
        return Err(format!(
            "parameter `{name}` = {value} is outside its admissible range [{}, {}] {}",
            p.min, p.max, p.unit
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_bounds_are_admissible() {
        // Experiment 1 asks for ThighRelHip2_Z in [-0.10, -0.01].
        assert!(check_value("ThighRelHip2_Z", -0.10).is_ok());
        assert!(check_value("ThighRelHip2_Z", -0.01).is_ok());
        for p in KNOWN {
            assert!(p.min < p.max, "{}", p.name);
            assert!(check_value(p.name, p.default).is_ok(), "{}", p.name);
        }
    }

    #[test]
    fn refuses_unknown_and_nan() {
        assert!(check_value("Nope", 0.0)
            .unwrap_err()
            .contains("unknown parameter `Nope`"));
        assert!(check_value("height_lift", f64::NAN)
            .unwrap_err()
            .contains("height_lift"));
        assert!(check_value("height_lift", 1.0)
            .unwrap_err()
            .contains("[0, 0.12]"));
    }
}
