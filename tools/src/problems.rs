//! The artificial test problems of `docs/spec/clop.md` §11: binary outcomes with
//! `P(Win | u) = σ(g(u))` on `u ∈ [-1, 1]^d`.

use serde::{Deserialize, Serialize};

/// A benchmark problem.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Problem {
    /// d = 1, smooth.
    Log,
    /// d = 1, nearly flat.
    Flat,
    /// d = 1, flat then a cliff.
    Power,
    /// d = 1, kink at the optimum.
    Angle,
    /// d = 1, discontinuous.
    Step,
    /// d = 2, curved valley.
    Rosenbrock,
    /// d = 2, ill-conditioned.
    Correlated,
    /// k copies of Log (strength averaged).
    LogX(usize),
    /// k copies of Rosenbrock.
    RosenbrockX(usize),
    /// k copies of Correlated.
    CorrelatedX(usize),
}

fn sigmoid(t: f64) -> f64 {
    1.0 / (1.0 + (-t).exp())
}

impl Problem {
    /// Parses `log`, `flat`, `power`, `angle`, `step`, `rosenbrock`, `correlated`,
    /// `log2`, `log5`, `rosenbrock2`, `rosenbrock5`, `correlated2` (also with `x`, e.g. `logx5`).
    pub fn parse(s: &str) -> Result<Self, String> {
        let l = s.to_ascii_lowercase().replace(['x', '×'], "");
        let (base, k) = match l.find(|c: char| c.is_ascii_digit()) {
            Some(i) => (
                &l[..i],
                l[i..].parse::<usize>().map_err(|e| format!("{s}: {e}"))?,
            ),
            None => (l.as_str(), 1),
        };
        let p = match (base, k) {
            ("log", 1) => Self::Log,
            ("flat", 1) => Self::Flat,
            ("power", 1) => Self::Power,
            ("angle", 1) => Self::Angle,
            ("step", 1) => Self::Step,
            ("rosenbrock", 1) => Self::Rosenbrock,
            ("correlated", 1) => Self::Correlated,
            ("log", k) if k > 1 => Self::LogX(k),
            ("rosenbrock", k) if k > 1 => Self::RosenbrockX(k),
            ("correlated", k) if k > 1 => Self::CorrelatedX(k),
            _ => return Err(format!("unknown problem `{s}` (log, flat, power, angle, step, rosenbrock, correlated, log2, log5, rosenbrock2, rosenbrock5, correlated2)")),
        };
        Ok(p)
    }

    /// All problems the benchmark knows, in the paper's order.
    #[must_use]
    pub fn all() -> Vec<Self> {
        vec![
            Self::Log,
            Self::Flat,
            Self::Power,
            Self::Angle,
            Self::Step,
            Self::Rosenbrock,
            Self::Correlated,
            Self::LogX(2),
            Self::LogX(5),
            Self::RosenbrockX(2),
            Self::RosenbrockX(5),
            Self::CorrelatedX(2),
        ]
    }

    /// Display name.
    #[must_use]
    pub fn name(&self) -> String {
        match self {
            Self::Log => "log".into(),
            Self::Flat => "flat".into(),
            Self::Power => "power".into(),
            Self::Angle => "angle".into(),
            Self::Step => "step".into(),
            Self::Rosenbrock => "rosenbrock".into(),
            Self::Correlated => "correlated".into(),
            Self::LogX(k) => format!("log{k}"),
            Self::RosenbrockX(k) => format!("rosenbrock{k}"),
            Self::CorrelatedX(k) => format!("correlated{k}"),
        }
    }

    /// Dimension d.
    #[must_use]
    pub fn dim(&self) -> usize {
        match self {
            Self::Log | Self::Flat | Self::Power | Self::Angle | Self::Step => 1,
            Self::Rosenbrock | Self::Correlated => 2,
            Self::LogX(k) => *k,
            Self::RosenbrockX(k) | Self::CorrelatedX(k) => 2 * k,
        }
    }

    /// Strength g(u).
    #[must_use]
    pub fn g(&self, u: &[f64]) -> f64 {
        match self {
            Self::Log => {
                let t = 2.0 * u[0] + 1.0;
                2.0 * (2.0 * t + 2.1).ln() - 2.0 * t - 1.0
            }
            Self::Flat => {
                let e = u[0] + 0.6;
                0.2 / (1.0 + 6.0 * e * e + e * e * e)
            }
            Self::Power => {
                let t = (u[0] + 1.0) / 2.0;
                0.2 * t * t - t.powi(20)
            }
            Self::Angle => {
                let e = u[0] + 0.2;
                let s2 = std::f64::consts::SQRT_2;
                if e > 0.0 {
                    1.0 - ((e + 2.0).sqrt() - s2)
                } else {
                    1.0 - (2.0 * (0.5 - e).sqrt() - s2)
                }
            }
            Self::Step => {
                let x = u[0];
                if x < -0.8 {
                    -2.0
                } else if x <= -0.3 {
                    -2.0 + 6.0 * (x + 0.8)
                } else if x < 0.8 {
                    -(x + 0.3) / 1.1
                } else {
                    -2.0
                }
            }
            Self::Rosenbrock => {
                let a = 4.0 * u[0];
                let b = 10.0 * u[1] + 4.0;
                1.0 - 0.1 * ((1.0 - a).powi(2) + (b - a * a).powi(2))
            }
            Self::Correlated => {
                let h = |t: f64| t * t * (t * (1.0 - t) - 1.0);
                let a = u[0] + u[1] + 0.1;
                let b = u[0] - u[1] + 0.9;
                0.2 * (h(10.0 * a) + h(b)) + 0.1
            }
            Self::LogX(k) => avg(*k, 1, u, Self::Log),
            Self::RosenbrockX(k) => avg(*k, 2, u, Self::Rosenbrock),
            Self::CorrelatedX(k) => avg(*k, 2, u, Self::Correlated),
        }
    }

    /// Win probability f(u) = σ(g(u)).
    #[must_use]
    pub fn f(&self, u: &[f64]) -> f64 {
        sigmoid(self.g(u))
    }

    /// The maximum f* = σ(g*).
    #[must_use]
    pub fn f_star(&self) -> f64 {
        let g = match self {
            Self::Log | Self::LogX(_) => 0.486_294,
            Self::Flat => 0.2,
            Self::Power => 0.116_546,
            Self::Angle | Self::Step | Self::Rosenbrock | Self::RosenbrockX(_) => 1.0,
            Self::Correlated | Self::CorrelatedX(_) => 0.1,
        };
        // The tabled g* of Log and Power are rounded; evaluate at the optimum instead.
        match self {
            Self::Log => self.f(&[-0.525]),
            Self::LogX(k) => self.f(&vec![-0.525; *k]),
            Self::Power => self.f(&[2.0 * 0.02_f64.powf(1.0 / 18.0) - 1.0]),
            _ => sigmoid(g),
        }
    }
}

#[allow(clippy::cast_precision_loss)]
fn avg(k: usize, d: usize, u: &[f64], p: Problem) -> f64 {
    (0..k).map(|i| p.g(&u[i * d..(i + 1) * d])).sum::<f64>() / k as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sanity_values_of_the_spec() {
        let close = |a: f64, b: f64| (a - b).abs() < 1e-5;
        assert!(close(Problem::Log.g(&[0.0]), -0.178_026));
        assert!(close(Problem::Flat.g(&[0.0]), 0.059_242));
        assert!(close(Problem::Power.g(&[0.0]), 0.049_999));
        assert!(close(Problem::Angle.g(&[0.0]), 0.930_974));
        assert!(close(Problem::Step.g(&[0.0]), -0.272_727));
        assert!(close(Problem::Rosenbrock.g(&[0.0, 0.0]), -0.7));
        assert!(close(Problem::Correlated.g(&[0.0, 0.0]), -0.247_420));
        assert!(close(Problem::Log.g(&[-1.0]), -3.605_170));
        assert!(close(Problem::Flat.g(&[-1.0]), 0.105_485));
        assert!(close(Problem::Power.g(&[-1.0]), 0.0));
        assert!(close(Problem::Log.g(&[1.0]), -2.816_272));
        assert!(close(Problem::Flat.g(&[1.0]), 0.009_777));
        assert!(close(Problem::Power.g(&[1.0]), -0.8));
        assert!(close(Problem::Angle.g(&[1.0]), 0.625_359));
        assert!(close(Problem::Log.f_star(), 0.619_233));
        assert!(close(Problem::Rosenbrock.g(&[0.25, -0.3]), 1.0));
        assert!(close(Problem::Correlated.g(&[-0.5, 0.4]), 0.1));
        assert!(close(Problem::LogX(5).f_star(), 0.619_233));
    }

    #[test]
    fn parse_names() {
        assert_eq!(Problem::parse("log5"), Ok(Problem::LogX(5)));
        assert_eq!(Problem::parse("Rosenbrock×2"), Ok(Problem::RosenbrockX(2)));
        assert!(Problem::parse("nope").is_err());
    }
}
