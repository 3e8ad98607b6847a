//! A walk you can watch: one NAO trial's recorded body poses as an animated
//! SVG (SMIL), a side view (x, z) above a top view (x, y), drawn to scale
//! over the whole path, each body a segment from its parent's centre to its
//! own. Plays in any browser, also inside an `<img>`.

use std::fmt::Write as _;

use worker::nao::{model::NaoModel, replay::Replayed, trial};

/// Pixels per metre.
const SCALE: f64 = 180.0;
/// The caption every animation has after its title, in its first line: how
/// `trial --render` knows an earlier animation of its own to write again.
pub const TRIAL_SVG_CAPTION: &str = "side view above, top view below;";
/// Record every this many 20 ms cycles (12.5 frames per second).
pub const EVERY: usize = 4;

/// Body centres (x, y, z) of every recorded frame.
pub type Frames = Vec<Vec<[f64; 3]>>;

/// The animated SVG of `frames` (recorded every [`EVERY`] cycles) of `model`.
#[must_use]
pub fn animated_svg(model: &NaoModel, frames: &Frames, title: &str) -> String {
    let all = frames.iter().flatten();
    let (mut x0, mut x1, mut y0, mut y1, mut z1) = (0.0f64, 0.5f64, -0.3f64, 0.3f64, 0.6f64);
    for p in all {
        x0 = x0.min(p[0] - 0.15);
        x1 = x1.max(p[0] + 0.15);
        y0 = y0.min(p[1] - 0.1);
        y1 = y1.max(p[1] + 0.1);
        z1 = z1.max(p[2] + 0.05);
    }
    let w = (x1 - x0) * SCALE;
    let side_h = z1 * SCALE;
    let top_h = (y1 - y0) * SCALE;
    let gap = 30.0;
    let height = 24.0 + side_h + gap + top_h;
    let dur = frames.len() as f64 * EVERY as f64 * 0.02;
    let mut s = String::new();
    let _ = write!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w:.0}\" height=\"{height:.0}\" \
         viewBox=\"0 0 {w:.0} {height:.0}\"><rect width=\"100%\" height=\"100%\" fill=\"white\"/>\
         <text x=\"4\" y=\"16\" font-family=\"sans-serif\" font-size=\"14\">{title} \
         ({TRIAL_SVG_CAPTION} {dur:.0} s)</text>"
    );
    // Side view: ground at z = 0; top view: y up.
    let side = |p: &[f64; 3]| ((p[0] - x0) * SCALE, 24.0 + side_h - p[2] * SCALE);
    let top = |p: &[f64; 3]| {
        (
            (p[0] - x0) * SCALE,
            24.0 + side_h + gap + (y1 - p[1]) * SCALE,
        )
    };
    let ground = 24.0 + side_h;
    let _ = write!(
        s,
        "<line x1=\"0\" y1=\"{ground:.1}\" x2=\"{w:.0}\" y2=\"{ground:.1}\" stroke=\"#888\"/>"
    );
    for m in (x0.ceil() as i64)..=(x1.floor() as i64) {
        let x = (m as f64 - x0) * SCALE;
        let _ = write!(
            s,
            "<text x=\"{x:.0}\" y=\"{:.0}\" font-family=\"sans-serif\" font-size=\"10\" \
             fill=\"#888\">{m} m</text>",
            ground + 12.0
        );
    }
    let links: Vec<(usize, usize)> = model
        .bodies
        .iter()
        .enumerate()
        .filter_map(|(i, b)| b.parent.map(|p| (p, i)))
        .collect();
    for view in [&side as &dyn Fn(&[f64; 3]) -> (f64, f64), &top] {
        for &(a, b) in &links {
            let coords = |k: usize| -> Vec<f64> {
                frames
                    .iter()
                    .map(|f| {
                        let (pa, pb) = (view(&f[a]), view(&f[b]));
                        [pa.0, pa.1, pb.0, pb.1][k]
                    })
                    .collect()
            };
            let (xa, ya, xb, yb) = (coords(0), coords(1), coords(2), coords(3));
            let (Some(&ax), Some(&ay), Some(&bx), Some(&by)) =
                (xa.first(), ya.first(), xb.first(), yb.first())
            else {
                continue;
            };
            let _ = write!(
                s,
                "<line x1=\"{ax:.1}\" y1=\"{ay:.1}\" x2=\"{bx:.1}\" y2=\"{by:.1}\" \
                 stroke=\"#234\" stroke-width=\"3\" stroke-linecap=\"round\">"
            );
            for (attr, v) in [("x1", xa), ("y1", ya), ("x2", xb), ("y2", yb)] {
                let values: Vec<String> = v.iter().map(|x| format!("{x:.1}")).collect();
                let _ = write!(
                    s,
                    "<animate attributeName=\"{attr}\" dur=\"{dur:.2}s\" repeatCount=\"indefinite\" \
                     calcMode=\"discrete\" values=\"{}\"/>",
                    values.join(";")
                );
            }
            s += "</line>";
        }
    }
    s += "</svg>\n";
    s
}

/// Re-simulates the trial `what` and returns its animated SVG.
pub fn trial_svg(what: &Replayed<'_>, title: &str) -> anyhow::Result<String> {
    let model = NaoModel::with_params(what.robot_type, what.values)?;
    let mut frames = Frames::new();
    let mut cycle = 0;
    trial::run_observed(
        what.robot_type,
        what.values,
        what.seed,
        what.duration_s,
        what.settings,
        what.engine,
        &mut |sim, _, _| {
            if cycle % EVERY == 0 {
                frames.push(
                    sim.body_poses()
                        .iter()
                        .map(|p| [p[0], p[1], p[2]])
                        .collect(),
                );
            }
            cycle += 1;
        },
    )?;
    Ok(animated_svg(&model, &frames, title))
}
