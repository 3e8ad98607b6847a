//! The report's figures, as SVG: each parameter against the iteration
//! coloured by decision, pairs of parameters, decisions per 50 iterations,
//! progress, and ν′'s mx over several runs.

use super::*;

/// The colour and fill of a decision's points: ACCEPT white with a dark
/// edge, EQUIVALENT grey, REJECT black (the paper's Fig. 1).
pub(super) fn style(d: Decision) -> ShapeStyle {
    match d {
        Decision::Accept => BLACK.stroke_width(1),
        Decision::Equivalent => GREY.filled(),
        Decision::Reject => BLACK.filled(),
    }
}

pub(super) fn range(lo: f64, hi: f64) -> std::ops::Range<f64> {
    if hi > lo {
        lo..hi
    } else {
        lo - 1.0..lo + 1.0
    }
}

/// One SVG document from a drawing closure.
pub(super) fn svg(
    draw: impl FnOnce(&DrawingArea<SVGBackend<'_>, plotters::coord::Shift>) -> anyhow::Result<()>,
) -> anyhow::Result<String> {
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("{e}"))?;
        draw(&root)?;
        root.present().map_err(|e| anyhow!("{e}"))?;
    }
    Ok(text)
}

pub(super) fn e<E: std::fmt::Display>(err: E) -> anyhow::Error {
    anyhow!("drawing: {err}")
}

/// Parameter `i` against the iteration, one point per decided iteration,
/// ν′'s value as a line (blue) and, when known, CLOP's mean Optim.2 (red).
pub(crate) fn parameter_figure(
    exp: &Experiment,
    decided: &[DecidedIteration],
    i: usize,
    optim2: Option<f64>,
) -> anyhow::Result<String> {
    let p = &exp.parameter[i];
    let n = decided.last().map_or(1, |d| d.iteration + 1) as f64;
    let caption = if optim2.is_some() {
        format!("{} (blue: ν′, red: Optim.2)", p.name)
    } else {
        format!("{} (blue: ν′)", p.name)
    };
    svg(|root| {
        let mut chart = ChartBuilder::on(root)
            .caption(caption, ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..n, range(p.lower, p.upper))
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("iteration")
            .y_desc(&p.name)
            .draw()
            .map_err(e)?;
        let best: Vec<(f64, f64)> = decided
            .iter()
            .filter_map(|d| d.best.as_ref().map(|b| (d.iteration as f64, b.params[i])))
            .collect();
        chart
            .draw_series(LineSeries::new(best, BLUE.stroke_width(2)))
            .map_err(e)?;
        if let Some(v) = optim2 {
            chart
                .draw_series(LineSeries::new([(0.0, v), (n, v)], RED.stroke_width(1)))
                .map_err(e)?;
        }
        chart
            .draw_series(
                decided
                    .iter()
                    .map(|d| Circle::new((d.iteration as f64, d.params[i]), 3, style(d.decision))),
            )
            .map_err(e)?;
        Ok(())
    })
}

/// Parameter `j` against parameter `i`, coloured by decision.
pub(super) fn pair_figure(
    exp: &Experiment,
    decided: &[DecidedIteration],
    i: usize,
    j: usize,
) -> anyhow::Result<String> {
    let (a, b) = (&exp.parameter[i], &exp.parameter[j]);
    svg(|root| {
        let mut chart = ChartBuilder::on(root)
            .caption(format!("{} against {}", b.name, a.name), ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(range(a.lower, a.upper), range(b.lower, b.upper))
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc(&a.name)
            .y_desc(&b.name)
            .draw()
            .map_err(e)?;
        chart
            .draw_series(
                decided
                    .iter()
                    .map(|d| Circle::new((d.params[i], d.params[j]), 3, style(d.decision))),
            )
            .map_err(e)?;
        Ok(())
    })
}

/// Decisions per 50 iterations, stacked: REJECT (black) at the bottom, then
/// EQUIVALENT (grey), then ACCEPT (white, dark edge).
pub(crate) fn decisions_figure(decided: &[DecidedIteration]) -> anyhow::Result<String> {
    let blocks = decided.chunks(50).collect::<Vec<_>>();
    let counts: Vec<[u32; 3]> = blocks
        .iter()
        .map(|b| {
            let c = |d| b.iter().filter(|x| x.decision == d).count() as u32;
            [
                c(Decision::Reject),
                c(Decision::Equivalent),
                c(Decision::Accept),
            ]
        })
        .collect();
    svg(|root| {
        let mut chart = ChartBuilder::on(root)
            .caption("decisions per 50 iterations", ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(40)
            .build_cartesian_2d(0.0..(blocks.len().max(1) * 50) as f64, 0.0..50.0)
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("iteration (REJECT black, EQUIVALENT grey, ACCEPT white)")
            .y_desc("decisions")
            .draw()
            .map_err(e)?;
        for (k, c) in counts.iter().enumerate() {
            let x0 = (k * 50) as f64 + 4.0;
            let x1 = x0 + 42.0;
            let mut y = 0.0;
            // A decision not taken in a block draws no bar (a bar of no
            // height is invalid SVG to a renderer).
            for (n, fill) in c.iter().zip([BLACK, GREY, WHITE]) {
                if *n == 0 {
                    continue;
                }
                let top = y + f64::from(*n);
                let edge = Rectangle::new([(x0, y), (x1, top)], BLACK.stroke_width(1));
                chart
                    .draw_series([Rectangle::new([(x0, y), (x1, top)], fill.filled()), edge])
                    .map_err(e)?;
                y = top;
            }
        }
        Ok(())
    })
}

type Chart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// Metres (0..top) against the iteration (0..n), with its mesh.
pub(super) fn metres_chart<'a, 'b>(
    root: &'a DrawingArea<SVGBackend<'b>, plotters::coord::Shift>,
    caption: &str,
    n: f64,
    top: f64,
) -> anyhow::Result<Chart<'a, 'b>> {
    let mut chart = ChartBuilder::on(root)
        .caption(caption, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..n, 0.0..top)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("iteration")
        .y_desc("m")
        .draw()
        .map_err(e)?;
    Ok(chart)
}

/// mx of every iteration (points by decision; a fallen-only iteration at 0),
/// s (green line, right scale ×5 m) and ν′'s mx (blue line).
pub(crate) fn progress_figure(decided: &[DecidedIteration]) -> anyhow::Result<String> {
    let n = decided.last().map_or(1, |d| d.iteration + 1) as f64;
    let top = decided
        .iter()
        .filter_map(|d| d.stats.mx)
        .fold(1.0f64, f64::max)
        * 1.1;
    svg(|root| {
        let mut chart = metres_chart(root, "mx (points), s × max (green), ν′'s mx (blue)", n, top)?;
        chart
            .draw_series(LineSeries::new(
                decided
                    .iter()
                    .map(|d| (d.iteration as f64, d.stats.s * top)),
                GREEN.stroke_width(1),
            ))
            .map_err(e)?;
        chart
            .draw_series(LineSeries::new(
                decided.iter().filter_map(|d| {
                    d.best
                        .as_ref()
                        .and_then(|b| b.stats.mx)
                        .map(|mx| (d.iteration as f64, mx))
                }),
                BLUE.stroke_width(2),
            ))
            .map_err(e)?;
        chart
            .draw_series(decided.iter().map(|d| {
                Circle::new(
                    (d.iteration as f64, d.stats.mx.unwrap_or(0.0)),
                    2,
                    style(d.decision),
                )
            }))
            .map_err(e)?;
        Ok(())
    })
}

/// ν′'s mx over the iterations, one line per run.
pub(super) fn best_figure(found: &[Found]) -> anyhow::Result<String> {
    let n = found
        .iter()
        .filter_map(|f| f.view.decided.last().map(|d| d.iteration + 1))
        .max()
        .unwrap_or(1) as f64;
    let top = found
        .iter()
        .flat_map(|f| f.view.decided.iter())
        .filter_map(|d| d.best.as_ref().and_then(|b| b.stats.mx))
        .fold(1.0f64, f64::max)
        * 1.1;
    svg(|root| {
        let mut chart = metres_chart(root, "ν′'s mx over the iterations", n, top)?;
        for (k, f) in found.iter().enumerate() {
            let colour = Palette99::pick(k).to_rgba();
            let label = format!(
                "{k}: {} seed {}",
                f.view.experiment.name, f.view.experiment.seed
            );
            chart
                .draw_series(LineSeries::new(
                    f.view.decided.iter().filter_map(|d| {
                        d.best
                            .as_ref()
                            .and_then(|b| b.stats.mx)
                            .map(|mx| (d.iteration as f64, mx))
                    }),
                    colour.stroke_width(2),
                ))
                .map_err(e)?
                .label(label)
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 16, y)], colour.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(e)?;
        Ok(())
    })
}
