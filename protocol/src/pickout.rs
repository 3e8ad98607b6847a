//! pickOut (`docs/spec/evolve.md`, Algorithm 2) and what it works on: an iteration's
//! statistics over its trials' [`Measurement`]s, the constants of Table III,
//! the decision, ν′ ([`Incumbent`]) and the history H ([`HistoryPoint`]).
//! Pure functions: no I/O, no clock.

use serde::{Deserialize, Serialize};

pub use crate::experiment::PickOutConstants;
use crate::measurement::Measurement;
pub use crate::wire::{Decision, Stats};

/// ν′: the best-first parameter set so far (Optim.1), in external units (CLOP order).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Incumbent {
    /// The iteration that was accepted.
    pub iteration: u64,
    /// Its parameter set.
    pub params: Vec<f64>,
    /// Its statistics.
    pub stats: Stats,
}

/// One entry of H: a parameter set (external units, CLOP order) and pickOut's decision.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HistoryPoint {
    /// The parameter set p.
    pub params: Vec<f64>,
    /// Its decision h.
    pub decision: Decision,
}

/// Statistics of an iteration (`docs/spec/evolve.md` "(ours)": m and e over the successful
/// trials, my = mean |y|, sample standard deviation; e absent with < 2 successes).
#[must_use]
pub fn stats(trials: &[Measurement]) -> Stats {
    let ok: Vec<&Measurement> = trials.iter().filter(|t| !t.fell).collect();
    let mean = |v: &[f64]| {
        #[allow(clippy::cast_precision_loss)]
        let n = v.len() as f64;
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / n)
    };
    let sd = |v: &[f64]| {
        #[allow(clippy::cast_precision_loss)]
        let n = v.len() as f64;
        (v.len() >= 2).then(|| {
            let m = v.iter().sum::<f64>() / n;
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
        })
    };
    let xs: Vec<f64> = ok.iter().map(|t| t.x_m).collect();
    let ys: Vec<f64> = ok.iter().map(|t| t.y_m.abs()).collect();
    let all_x: Vec<f64> = trials.iter().map(|t| t.x_m).collect();
    let all_y: Vec<f64> = trials.iter().map(|t| t.y_m.abs()).collect();
    let n = u32::try_from(trials.len()).unwrap_or(u32::MAX);
    let k = u32::try_from(ok.len()).unwrap_or(u32::MAX);
    Stats {
        trials: n,
        successes: k,
        s: if n == 0 {
            0.0
        } else {
            f64::from(k) / f64::from(n)
        },
        mx: mean(&xs),
        my: mean(&ys),
        ex: sd(&xs),
        ey: sd(&ys),
        mx_all: mean(&all_x).unwrap_or(0.0),
        my_all: mean(&all_y).unwrap_or(0.0),
    }
}

/// pickOut (Algorithm 2). `best` is ν′'s statistics (None while undefined).
///
/// Rules of ours: no successful trial or mx ≤ 0 is REJECT; an ex that is
/// absent (fewer than 2 successes) counts as 0.
#[must_use]
pub fn pick_out(nu: &Stats, best: Option<&Stats>, k: &PickOutConstants) -> Decision {
    let (Some(mx), Some(my)) = (nu.mx, nu.my) else {
        return Decision::Reject;
    };
    if nu.s < k.success_rate {
        return Decision::Reject; // line 1
    }
    if mx <= 0.0 {
        return Decision::Reject; // (ours)
    }
    if my / mx > k.xy_ratio {
        return Decision::Reject; // line 2
    }
    let Some(best) = best else {
        return Decision::Accept; // line 3
    };
    let bmx = best.mx.unwrap_or(0.0);
    let bex = best.ex.unwrap_or(0.0);
    let ex = nu.ex.unwrap_or(0.0);
    if mx < bmx - k.alpha * bex {
        Decision::Reject // line 4
    } else if mx < bmx - k.beta * bex {
        Decision::Equivalent // line 5
    } else if ex < k.gamma * bex {
        Decision::Accept // line 6
    } else if mx < bmx {
        Decision::Equivalent // line 7
    } else {
        Decision::Accept // line 8
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn st(s: f64, mx: Option<f64>, my: f64, ex: Option<f64>) -> Stats {
        Stats {
            trials: 10,
            successes: 10,
            s,
            mx,
            my: mx.map(|_| my),
            ex,
            ey: None,
            mx_all: mx.unwrap_or(0.0),
            my_all: my,
        }
    }

    #[test]
    fn pick_out_every_line_and_edge() {
        use Decision::{Accept as A, Equivalent as E, Reject as R};
        let k = PickOutConstants::default();
        let best = st(1.0, Some(2.0), 0.1, Some(0.1));
        let zero_e = st(1.0, Some(2.0), 0.1, Some(0.0));
        let cases: Vec<(&str, Stats, Option<&Stats>, Decision)> = vec![
            (
                "line 1: s below SUCCESS_RATE",
                st(0.7, Some(3.0), 0.1, Some(0.1)),
                Some(&best),
                R,
            ),
            (
                "line 1 edge: s exactly SUCCESS_RATE passes",
                st(0.75, Some(3.0), 0.1, Some(0.01)),
                Some(&best),
                A,
            ),
            ("ours: no success", st(0.0, None, 0.0, None), None, R),
            ("ours: mx <= 0", st(1.0, Some(0.0), 0.0, Some(0.1)), None, R),
            ("ours: mx < 0", st(1.0, Some(-1.0), 0.0, Some(0.1)), None, R),
            (
                "line 2: my/mx above XY_RATIO",
                st(1.0, Some(1.0), 0.26, Some(0.1)),
                None,
                R,
            ),
            (
                "line 2 edge: my/mx exactly XY_RATIO passes",
                st(1.0, Some(1.0), 0.25, Some(0.1)),
                None,
                A,
            ),
            (
                "line 3: no best yet",
                st(1.0, Some(0.5), 0.1, Some(0.1)),
                None,
                A,
            ),
            (
                "line 4: far below",
                st(1.0, Some(1.69), 0.1, Some(0.1)),
                Some(&best),
                R,
            ),
            (
                "line 5: below by more than beta e",
                st(1.0, Some(1.85), 0.1, Some(0.01)),
                Some(&best),
                E,
            ),
            (
                "line 6: within beta e and more precise",
                st(1.0, Some(1.95), 0.1, Some(0.05)),
                Some(&best),
                A,
            ),
            (
                "line 7: within beta e, less precise, below",
                st(1.0, Some(1.95), 0.1, Some(0.2)),
                Some(&best),
                E,
            ),
            (
                "line 8: above, less precise",
                st(1.0, Some(2.05), 0.1, Some(0.2)),
                Some(&best),
                A,
            ),
            (
                "e'x = 0: below is REJECT",
                st(1.0, Some(1.99), 0.1, Some(0.0)),
                Some(&zero_e),
                R,
            ),
            (
                "e'x = 0: equal is ACCEPT",
                st(1.0, Some(2.0), 0.1, Some(0.0)),
                Some(&zero_e),
                A,
            ),
            (
                "e'x = 0: above is ACCEPT",
                st(1.0, Some(2.1), 0.1, Some(0.3)),
                Some(&zero_e),
                A,
            ),
        ];
        for (name, nu, b, want) in cases {
            assert_eq!(pick_out(&nu, b, &k), want, "{name}");
        }
    }

    #[test]
    fn stats_over_successful_trials() {
        let t = |fell, x: f64, y: f64| Measurement {
            fell,
            x_m: x,
            y_m: y,
            fall_time_s: fell.then_some(1.0),
            sim_time_s: 10.0,
        };
        let s = stats(&[
            t(false, 1.0, -0.2),
            t(false, 3.0, 0.2),
            t(true, 0.1, 0.0),
            t(false, 2.0, 0.2),
        ]);
        assert_eq!(s.successes, 3);
        assert_eq!(s.s, 0.75);
        assert_eq!(s.mx, Some(2.0));
        assert!((s.my.unwrap() - 0.2).abs() < 1e-12, "my is the mean of |y|");
        assert_eq!(s.ex, Some(1.0), "sample sd (n - 1)");
        assert!((s.mx_all - 1.525).abs() < 1e-12);
        let one = stats(&[t(false, 1.0, 0.0)]);
        assert_eq!(one.ex, None);
    }
}
