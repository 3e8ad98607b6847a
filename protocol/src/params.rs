//! The one registry of the robot's parameters: each name an experiment may
//! optimise or fix, its role (morphology or walk), unit, admissible range,
//! expert value and meaning.
//!
//! Every name a worker understands is listed here with the range a worker can
//! build and run (the *admissible* range). An experiment's bounds must lie
//! inside it; anything else is refused when the file is read, long before a
//! worker sees it. Named values are decoded once, by [`ParamValues::from_named`],
//! into values addressed by [`Param`]; the NAO model, the walk and the
//! synthetic model read those, never a name. Must not: spell a parameter's
//! name anywhere but in [`KNOWN`].

/// Which part of the robot a parameter shapes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// A body dimension (the league's heterogeneous-type quantities).
    Morphology,
    /// A setting of the walk.
    Walk,
}

/// A known parameter, by identity (the order of [`KNOWN`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Param {
    /// `ThighRelHip2_Z`.
    ThighRelHip2Z,
    /// `ratio_flexion`.
    RatioFlexion,
    /// `long_offset_MidAnkles_2_Torso_Init`.
    LongOffset,
    /// `height_lift`.
    HeightLift,
    /// `xlength_step_max`.
    StepLength,
    /// `Hip1RelTorso_X`.
    Hip1RelTorsoX,
    /// `Hip1RelTorso_Z`.
    Hip1RelTorsoZ,
    /// `AnkleRelShank_Z`.
    AnkleRelShankZ,
    /// `ElbowRelUpperArm_Y`.
    ElbowRelUpperArmY,
    /// `step_period`.
    StepPeriod,
    /// `double_support`.
    DoubleSupport,
    /// `com_above_hip`.
    ComAboveHip,
}

impl Param {
    /// Its registry entry.
    #[must_use]
    pub const fn spec(self) -> &'static KnownParam {
        &KNOWN[self as usize]
    }

    /// Its name, as in the paper and the experiment files.
    #[must_use]
    pub const fn name(self) -> &'static str {
        self.spec().name
    }
}

/// One parameter the trial models understand.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnownParam {
    /// Its identity.
    pub param: Param,
    /// Identifier exactly as in the paper and the experiment files.
    pub name: &'static str,
    /// Morphology or walk.
    pub role: Role,
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
        param: Param::ThighRelHip2Z,
        name: "ThighRelHip2_Z",
        role: Role::Morphology,
        min: -0.12,
        max: -0.005,
        unit: "m",
        default: -0.04,
        doc: "thigh centre below the hip; thigh length = 0.08 - value",
    },
    KnownParam {
        param: Param::RatioFlexion,
        name: "ratio_flexion",
        role: Role::Walk,
        min: 0.40,
        max: 0.99,
        unit: "1",
        default: 0.73,
        doc: "walking hip height over stretched leg length",
    },
    KnownParam {
        param: Param::LongOffset,
        name: "long_offset_MidAnkles_2_Torso_Init",
        role: Role::Walk,
        min: -0.05,
        max: 0.06,
        unit: "m",
        default: 0.011,
        doc: "forward offset of the torso over the mid-ankles",
    },
    KnownParam {
        param: Param::HeightLift,
        name: "height_lift",
        role: Role::Walk,
        min: 0.0,
        max: 0.12,
        unit: "m",
        default: 0.042,
        doc: "maximal swing-foot lift",
    },
    KnownParam {
        param: Param::StepLength,
        name: "xlength_step_max",
        role: Role::Walk,
        min: 0.0,
        max: 0.25,
        unit: "m",
        default: 0.08,
        doc: "step length (the first two steps are half as long)",
    },
    KnownParam {
        param: Param::Hip1RelTorsoX,
        name: "Hip1RelTorso_X",
        role: Role::Morphology,
        min: 0.04,
        max: 0.09,
        unit: "m",
        default: 0.055,
        doc: "lateral hip offset from the torso centre",
    },
    KnownParam {
        param: Param::Hip1RelTorsoZ,
        name: "Hip1RelTorso_Z",
        role: Role::Morphology,
        min: -0.14,
        max: -0.09,
        unit: "m",
        default: -0.115,
        doc: "hip height below the torso centre",
    },
    KnownParam {
        param: Param::AnkleRelShankZ,
        name: "AnkleRelShank_Z",
        role: Role::Morphology,
        min: -0.11,
        max: -0.03,
        unit: "m",
        default: -0.055,
        doc: "ankle below the shank centre; tibia length = 0.045 - value",
    },
    KnownParam {
        param: Param::ElbowRelUpperArmY,
        name: "ElbowRelUpperArm_Y",
        role: Role::Morphology,
        min: 0.04,
        max: 0.15,
        unit: "m",
        default: 0.07,
        doc: "elbow forward of the upper-arm centre",
    },
    // The walk engine's plan constants a user may tune: the defaults are the
    // engine's own (docs/walk.md, "The plan").
    KnownParam {
        param: Param::StepPeriod,
        name: "step_period",
        role: Role::Walk,
        min: 0.10,
        max: 0.60,
        unit: "s",
        default: 0.16,
        doc: "step period (one step of one foot)",
    },
    KnownParam {
        param: Param::DoubleSupport,
        name: "double_support",
        role: Role::Walk,
        min: 0.0,
        max: 0.5,
        unit: "1",
        default: 0.0,
        doc: "double-support share of a step",
    },
    KnownParam {
        param: Param::ComAboveHip,
        name: "com_above_hip",
        role: Role::Walk,
        min: -0.05,
        max: 0.15,
        unit: "m",
        default: 0.025,
        doc: "the plan's centre of mass above the hip centre (the pendulum's height)",
    },
];

/// Looks a parameter up by its exact name.
#[must_use]
pub fn find(name: &str) -> Option<&'static KnownParam> {
    KNOWN.iter().find(|p| p.name == name)
}

/// A number as an error message shows it: as Rust writes it, except that
/// one of ten million or more, or below a hundred-thousandth, is written
/// with an exponent (`1e300`, not 301 digits).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shown(pub f64);

impl std::fmt::Display for Shown {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let a = self.0.abs();
        if a.is_finite() && a != 0.0 && !(1e-5..1e7).contains(&a) {
            write!(f, "{:e}", self.0)
        } else {
            write!(f, "{}", self.0)
        }
    }
}

/// Why a named value was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamError {
    /// Not a known name.
    #[error("unknown parameter `{0}` (known: {known})", known = KNOWN.iter().map(|p| p.name).collect::<Vec<_>>().join(", "))]
    Unknown(String),
    /// NaN or infinite.
    #[error("parameter `{name}` is {value}, not a finite number")]
    NotFinite {
        /// The parameter.
        name: &'static str,
        /// The value.
        value: f64,
    },
    /// Outside the admissible range.
    #[error("parameter `{name}` = {} is outside its admissible range [{min}, {max}] {unit}", Shown(*.value))]
    Range {
        /// The parameter.
        name: &'static str,
        /// The value.
        value: f64,
        /// Lower bound.
        min: f64,
        /// Upper bound.
        max: f64,
        /// Unit.
        unit: &'static str,
    },
}

/// Checks one value against its parameter's admissible range.
pub fn check(p: Param, value: f64) -> Result<(), ParamError> {
    let s = p.spec();
    if !value.is_finite() {
        return Err(ParamError::NotFinite {
            name: s.name,
            value,
        });
    }
    if value < s.min || value > s.max {
        return Err(ParamError::Range {
            name: s.name,
            value,
            min: s.min,
            max: s.max,
            unit: s.unit,
        });
    }
    Ok(())
}

/// Checks a parameter of a trial program (`model = "program"`): the program
/// owns its names and ranges, so the name only has to be one word of
/// letters, digits and `_` (at most 64 bytes) and the value finite.
pub fn check_program_value(name: &str, value: f64) -> Result<(), String> {
    if name.is_empty() || name.len() > 64 {
        return Err(format!(
            "a program's parameter name must be 1 to 64 bytes, not {}",
            name.len()
        ));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '_'))
    {
        return Err(format!(
            "parameter name `{name}` contains `{c}`; use letters, digits and `_`"
        ));
    }
    if !value.is_finite() {
        return Err(format!("`{name}` = {value} is not a finite number"));
    }
    Ok(())
}

/// Checks one value against the admissible range of its parameter.
///
/// Returns a message naming the parameter and its range on failure.
pub fn check_value(name: &str, value: f64) -> Result<(), String> {
    let p = find(name).ok_or_else(|| ParamError::Unknown(name.to_string()).to_string())?;
    check(p.param, value).map_err(|e| e.to_string())
}

/// The walk's parameters (experiment 2's L minus the morphology).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WalkParams {
    /// `ratio_flexion`.
    pub ratio_flexion: f64,
    /// `long_offset_MidAnkles_2_Torso_Init`, m.
    pub long_offset: f64,
    /// `height_lift`, m.
    pub height_lift: f64,
    /// `xlength_step_max`, m.
    pub step_length: f64,
}

impl WalkParams {
    /// The paper's expert values (the registry's defaults).
    pub const EXPERT: Self = Self {
        ratio_flexion: Param::RatioFlexion.spec().default,
        long_offset: Param::LongOffset.spec().default,
        height_lift: Param::HeightLift.spec().default,
        step_length: Param::StepLength.spec().default,
    };
}

/// A parameter set decoded once from names: each known parameter's value, if given.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ParamValues {
    given: [Option<f64>; KNOWN.len()],
}

impl ParamValues {
    /// Decodes named values (unknown names, non-finite or out-of-range values are errors).
    pub fn from_named(params: &[(String, f64)]) -> Result<Self, ParamError> {
        let mut out = Self::default();
        for (name, value) in params {
            let p = find(name).ok_or_else(|| ParamError::Unknown(name.clone()))?;
            out.set(p.param, *value)?;
        }
        Ok(out)
    }

    /// Sets one value (checked against its range).
    pub fn set(&mut self, p: Param, value: f64) -> Result<(), ParamError> {
        check(p, value)?;
        self.given[p as usize] = Some(value);
        Ok(())
    }

    /// The value given for `p`, if any.
    #[must_use]
    pub fn given(&self, p: Param) -> Option<f64> {
        self.given[p as usize]
    }

    /// The value of `p`: given, or the registry's default.
    #[must_use]
    pub fn value(&self, p: Param) -> f64 {
        self.given(p).unwrap_or(p.spec().default)
    }

    /// The walk's parameters (unset ones at expert).
    #[must_use]
    pub fn walk(&self) -> WalkParams {
        WalkParams {
            ratio_flexion: self.value(Param::RatioFlexion),
            long_offset: self.value(Param::LongOffset),
            height_lift: self.value(Param::HeightLift),
            step_length: self.value(Param::StepLength),
        }
    }

    /// The given values, by name, in registry order.
    #[must_use]
    pub fn named(&self) -> Vec<(String, f64)> {
        KNOWN
            .iter()
            .filter_map(|k| self.given(k.param).map(|v| (k.name.to_string(), v)))
            .collect()
    }
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
    fn the_registry_is_in_identity_order() {
        for (i, k) in KNOWN.iter().enumerate() {
            assert_eq!(k.param as usize, i, "{}", k.name);
        }
        let v = ParamValues::from_named(&[("height_lift".into(), 0.05)]).unwrap();
        assert_eq!(v.walk().height_lift, 0.05);
        assert_eq!(v.walk().step_length, WalkParams::EXPERT.step_length);
        assert_eq!(v.given(Param::ThighRelHip2Z), None);
        assert!(ParamValues::from_named(&[("nope".into(), 0.0)]).is_err());
        assert!(ParamValues::from_named(&[("height_lift".into(), 0.5)]).is_err());
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

    /// An absurd number is named in a line, not spelt out digit by digit.
    #[test]
    fn errors_write_absurd_numbers_with_an_exponent() {
        assert_eq!(
            check_value("height_lift", 1e300).unwrap_err(),
            "parameter `height_lift` = 1e300 is outside its admissible range [0, 0.12] m"
        );
        let shown = |v: f64| Shown(v).to_string();
        assert_eq!(shown(-2.5e-9), "-2.5e-9");
        assert_eq!(shown(12_345_678.0), "1.2345678e7");
        assert_eq!(shown(0.042), "0.042");
        assert_eq!(shown(-9_999_999.0), "-9999999");
        assert_eq!(shown(0.0), "0");
        assert_eq!(shown(f64::NAN), "NaN");
        assert_eq!(shown(f64::NEG_INFINITY), "-inf");
    }
}
