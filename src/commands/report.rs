//! `naofarm report RUN_DIR`: what a run found, as the paper shows it — each
//! parameter against the iteration and each pair against each other coloured
//! by decision (Fig. 1, 3c, 5, 6), decisions per 50 iterations, s and mx with
//! ν′'s, Table IV (Expert, Optim.1, Optim.2 over N trials, Markdown and JSON)
//! and an `index.html` that shows it all. Only reads the run directory.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::anyhow;
use coordinator::evolve::DecidedIteration;
use plotters::prelude::*;
use protocol::{
    params::ParamValues, pickout::stats, Decision, Experiment, Stats, TrialModel, TrialRequest,
};
use worker::nao::{footwork::Footwork, sim::SimSettings, trial};
use worker::program::Programs;

use crate::common::{note_tail, usage_unless, Failure};
use crate::render;

pub(crate) mod figures;
use figures::{best_figure, decisions_figure, pair_figure, parameter_figure, progress_figure};

/// The first seed of Table IV's trials (the seed of the paper's table runs).
pub const TABLE_SEED: u64 = 777;
const SIZE: (u32, u32) = (720, 360);
const GREY: RGBColor = RGBColor(150, 150, 150);

/// One row (column in the paper) of Table IV.
struct Row {
    name: &'static str,
    params: Vec<f64>,
    stats: Stats,
    /// How far the set's walk plans to go in a trial, m (NAO runs).
    planned: Option<f64>,
    /// The full step its walk plans, m (NAO runs): `xlength_step_max`, or
    /// shorter where `step_reach` caps it.
    planned_step: Option<f64>,
    /// How the feet covered mx: the mean split of the trials that did not
    /// fall (NAO runs; none if every trial fell).
    footwork: Option<Footwork>,
}

/// What one run's report found, for the page over several runs.
struct Found {
    view: coordinator::run::RunView,
    rows: Vec<Row>,
    page: PathBuf,
}

/// Writes the report of each run in `dirs`: of one run into `out` (default
/// `DIR/report`); of several, each into `out/K-NAME/` and a page over all of
/// them into `out` (then required).
pub fn report(
    dirs: &[PathBuf],
    out: Option<&Path>,
    programs: &crate::args::ProgramArgs,
    trials: u32,
    threads: usize,
) -> Result<(), Failure> {
    let many = (1..=100_000).contains(&trials);
    usage_unless(many, || {
        format!("--trials {trials}: 1 to 100000 per Table IV row")
    })?;
    let programs = &tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| Failure::Job(e.into()))?
        .block_on(crate::common::register_programs(
            programs,
            u32::try_from(threads.max(1)).unwrap_or(1),
        ))?;
    match (dirs, out) {
        ([], _) => Err(Failure::Usage(anyhow!("give at least one run directory"))),
        ([dir], out) => one(dir, read(dir)?, out, programs, trials, threads).map(|_| ()),
        (_, None) => Err(Failure::Usage(anyhow!(
            "a report over {} runs needs --out DIR",
            dirs.len()
        ))),
        (_, Some(out)) => {
            report_dir(out)?;
            let mut found = Vec::new();
            for (k, dir) in dirs.iter().enumerate() {
                let view = read(dir)?;
                let sub = out.join(format!("{k}-{}", view.experiment.name));
                found.push(one(dir, view, Some(&sub), programs, trials, threads)?);
            }
            std::fs::write(
                out.join("best.svg"),
                best_figure(&found).map_err(Failure::Job)?,
            )
            .map_err(|e| Failure::Job(anyhow!("{}: {e}", out.display())))?;
            std::fs::write(out.join("index.html"), runs_html(&found, out, trials))
                .map_err(|e| Failure::Job(anyhow!("{}: {e}", out.display())))?;
            outln!("report over {} runs in {}", found.len(), out.display());
            Ok(())
        }
    }
}

/// The file that marks a directory as a report's, written first into it.
const MARK: &str = ".naofarm-report";

/// Makes `out` ready for a report: a new directory, an empty one, or an
/// earlier report's (its mark, or a page by an earlier naofarm), whose files
/// the report writes again. Any other directory is refused (exit 2) before a
/// byte is written, so that a report never overwrites files that are not
/// its own (say someone's `index.html`, or a run directory's).
fn report_dir(out: &Path) -> Result<(), Failure> {
    let usage = |why: String| Failure::Usage(anyhow!("--out {}: {why}", out.display()));
    let io = |e: std::io::Error| Failure::Job(anyhow!("--out {}: {e}", out.display()));
    if out.is_dir() {
        let mut names = Vec::new();
        for entry in std::fs::read_dir(out).map_err(io)? {
            names.push(entry.map_err(io)?.file_name());
        }
        names.sort();
        let earlier_page = || {
            use std::io::Read as _;
            let mut head = Vec::new();
            std::fs::File::open(out.join("index.html"))
                .and_then(|f| f.take(1024).read_to_end(&mut head))
                .is_ok_and(|_| String::from_utf8_lossy(&head).contains("<title>naofarm report"))
        };
        if !names.is_empty() && !names.iter().any(|n| n == MARK) && !earlier_page() {
            let names: Vec<_> = names.iter().map(|n| n.to_string_lossy()).collect();
            return Err(usage(format!(
                "holds files that are not a naofarm report's ({}); give a new or empty \
                 directory, or an earlier report's",
                coordinator::run::first_names(&names)
            )));
        }
    } else {
        crate::common::make_dir(out, "--out")?;
    }
    std::fs::write(
        out.join(MARK),
        "A report of naofarm's: `naofarm report` writes its files here again.\n",
    )
    .map_err(io)
}

/// Reads a run for its report (noting a torn tail).
fn read(dir: &Path) -> Result<coordinator::run::RunView, Failure> {
    let view = crate::common::read_run(dir)?;
    note_tail(dir, &view);
    Ok(view)
}

/// Writes the report of the run in `dir` (read as `view`) into `out` (default `DIR/report`).
fn one(
    dir: &Path,
    view: coordinator::run::RunView,
    out: Option<&Path>,
    programs: &Programs,
    trials: u32,
    threads: usize,
) -> Result<Found, Failure> {
    let exp = view.experiment.clone();
    let decided = &view.decided;
    let out = out.map_or_else(|| dir.join("report"), Path::to_path_buf);
    report_dir(&out)?;
    let write = |name: &str, text: &str| {
        std::fs::write(out.join(name), text)
            .map_err(|e| Failure::Job(anyhow!("{}: {e}", out.join(name).display())))
    };
    let fonts = png_fonts();
    // A figure as SVG and, beside it, as PNG.
    let figure = |name: &str, text: &str| {
        write(name, text)?;
        let png = name.replace(".svg", ".png");
        let bytes = to_png(text, &fonts).map_err(|e| Failure::Job(anyhow!("{png}: {e}")))?;
        std::fs::write(out.join(&png), bytes)
            .map_err(|e| Failure::Job(anyhow!("{}: {e}", out.join(&png).display())))
    };
    let job = |e: anyhow::Error| Failure::Job(e);
    let rows = table_iv(dir, &exp, programs, trials, threads)?;
    let optim2 = rows
        .iter()
        .find(|r| r.name == coordinator::evolve::TABLE_SETS[2])
        .map(|r| r.params.clone());
    let mut figures = Vec::new();
    for (i, p) in exp.parameter.iter().enumerate() {
        let name = format!("param-{}.svg", p.name);
        let o2 = optim2.as_ref().and_then(|o| o.get(i).copied());
        figure(&name, &parameter_figure(&exp, decided, i, o2).map_err(job)?)?;
        figures.push((name, format!("{} against the iteration", p.name)));
    }
    for i in 0..exp.parameter.len() {
        for j in i + 1..exp.parameter.len() {
            let (a, b) = (&exp.parameter[i].name, &exp.parameter[j].name);
            let name = format!("pair-{a}-{b}.svg");
            figure(&name, &pair_figure(&exp, decided, i, j).map_err(job)?)?;
            figures.push((name, format!("{b} against {a}")));
        }
    }
    figure("decisions.svg", &decisions_figure(decided).map_err(job)?)?;
    figures.push(("decisions.svg".into(), "decisions per 50 iterations".into()));
    figure("progress.svg", &progress_figure(decided).map_err(job)?)?;
    figures.push((
        "progress.svg".into(),
        "s and mx of every iteration, ν′'s mx".into(),
    ));

    let mut replays = Vec::new();
    if exp.model == TrialModel::Nao {
        for r in &rows {
            let file = format!("replay-{}.svg", crate::common::set_key(r.name));
            write(&file, &replay_svg(&exp, &r.params, r.name)?)?;
            replays.push((file, format!("{}: trial seed {TABLE_SEED}", r.name)));
        }
    }
    let (md, json) = table_text(&exp, &rows, trials);
    write("table4.md", &md)?;
    write("table4.json", &json)?;
    if exp.model == TrialModel::Nao {
        write(SIMSPARK_TYPES, &simspark_types(&exp, &rows)?)?;
    }
    write(
        "index.html",
        &index_html(dir, &exp, &view, &rows, trials, &figures, &replays),
    )?;
    outln!("report of {} in {}", dir.display(), out.display());
    outln!("{md}");
    Ok(Found {
        view,
        rows,
        page: out.join("index.html"),
    })
}

/// The file of Table IV's bodies as SimSpark robot types.
const SIMSPARK_TYPES: &str = "simspark-types.rb";

/// Table IV's bodies as entries of SimSpark's `naorobottypes.rb`, each under
/// a comment naming its row and its values, to try them on the league's
/// server. Only the body travels: the walk is naofarm's own engine.
fn simspark_types(exp: &Experiment, rows: &[Row]) -> Result<String, Failure> {
    let mut text = format!(
        "# The bodies of Table IV of run {name} (naofarm report), as SimSpark robot types.\n\
         # Each entry has the keys of an entry of the NaoType array in rcssserver3d's\n\
         # naorobottypes.rb (release 0.6.8 on): put one in that array, in place of a type\n\
         # or beside them, to try the body on the league's server. Robot type {ty} is the\n\
         # base; the walk parameters stay with naofarm's walk and are listed for reference.\n",
        name = exp.name,
        ty = exp.robot_type,
    );
    for r in rows {
        let named = exp.full_params(&r.params);
        let values = ParamValues::from_named(&named)
            .map_err(|e| Failure::Job(anyhow!("{}'s parameters: {e}", r.name)))?;
        let body = worker::nao::model::NaoModel::with_params(exp.robot_type, &values)
            .map_err(|e| Failure::Job(anyhow!("{}'s body: {e}", r.name)))?
            .morphology;
        let values: Vec<String> = named.iter().map(|(k, v)| format!("{k} = {v}")).collect();
        let _ = write!(
            text,
            "\n# {}: {}\n{},\n",
            r.name,
            values.join(", "),
            body.simspark_type()
        );
    }
    Ok(text)
}

/// Expert, Optim.1 (ν′) and Optim.2 (CLOP's mean), each over the same
/// `trials` seeds from [`TABLE_SEED`], each trial exactly as a farm worker
/// runs it.
fn table_iv(
    dir: &Path,
    exp: &Experiment,
    programs: &Programs,
    trials: u32,
    threads: usize,
) -> Result<Vec<Row>, Failure> {
    rows_of(
        exp,
        crate::common::replay_run(dir)?.table_sets(),
        programs,
        trials,
        threads,
    )
}

/// Table IV of `sets` (Expert, Optim.1, Optim.2 as far as known) as
/// Markdown: what the report writes, for the web page of a run that is over.
pub(crate) fn table_markdown(
    exp: &Experiment,
    sets: Vec<(&'static str, Vec<f64>)>,
    trials: u32,
    threads: usize,
) -> Result<String, Failure> {
    let rows = rows_of(exp, sets, &Programs::default(), trials, threads)?;
    Ok(table_text(exp, &rows, trials).0)
}

fn rows_of(
    exp: &Experiment,
    sets: Vec<(&'static str, Vec<f64>)>,
    programs: &Programs,
    trials: u32,
    threads: usize,
) -> Result<Vec<Row>, Failure> {
    sets.into_iter()
        .map(|(name, params)| {
            let runs = run_trials(exp, &params, programs, trials, threads)?;
            let first = table_request(exp, &params, 0);
            let planned = worker::planned_x_m(&first)
                .map_err(|e| Failure::Job(anyhow!("Table IV plan of {name}: {e}")))?;
            let planned_step = worker::planned_step_m(&first)
                .map_err(|e| Failure::Job(anyhow!("Table IV step of {name}: {e}")))?;
            let ms: Vec<_> = runs.iter().map(|(m, _)| *m).collect();
            let footwork = Footwork::mean(
                runs.iter()
                    .filter(|(m, _)| !m.fell)
                    .filter_map(|(_, w)| w.as_ref()),
            );
            Ok(Row {
                name,
                stats: stats(&ms),
                params,
                planned,
                planned_step,
                footwork,
            })
        })
        .collect()
}

/// Table IV's trial `k` of one parameter set, exactly as a farm worker gets it.
fn table_request(exp: &Experiment, params: &[f64], k: u32) -> TrialRequest {
    TrialRequest {
        run: String::new(),
        iteration: 0,
        trial: k,
        seed: TABLE_SEED + u64::from(k),
        model: exp.model,
        program: exp.program.clone(),
        robot_type: exp.robot_type,
        duration_s: exp.trial_duration_s,
        params: exp.full_params(params),
        dispatch: 0,
        physics: exp.physics,
    }
}

/// The torso's mean pitch over the cycles, degrees (negative: leaning
/// back): a fast walk that leans far back stands on its heels, and its
/// distance swings with the physics step (docs/walk.md).
fn torso_pitch(r: &Row) -> String {
    r.footwork
        .map_or("–".into(), |w| format!("{:+.1}", w.torso_pitch_deg))
}

/// How far a set's feet land beyond the legs' aim per step, mm, as a cell.
/// The step at touchdown in the world, and how far the foot landed before
/// has moved on by then: a foot that skids on after it lands carries the
/// torso beyond its steps.
fn step_at_touchdown(r: &Row) -> String {
    r.footwork
        .filter(|w| w.touchdowns > 0)
        .map_or("–".into(), |w| {
            format!("{:.4} / {:+.1}", w.spacing_m, w.settle_m * 1000.0)
        })
}

fn landed_beyond_aim(r: &Row) -> String {
    r.footwork
        .filter(|w| w.touchdowns > 0)
        .map_or("–".into(), |w| format!("{:+.1}", w.overreach_m * 1000.0))
}

/// mx over the plan's travel: near 1 for a set that walks as planned, well
/// above it for one that slides or lunges.
fn over_plan(r: &Row) -> Option<f64> {
    match (r.stats.mx, r.planned) {
        (Some(mx), Some(p)) if p > 0.0 => Some(mx / p),
        _ => None,
    }
}

/// `trials` trials of one parameter set, in parallel, in seed order, each
/// with how the feet covered its distance (NAO runs).
fn run_trials(
    exp: &Experiment,
    params: &[f64],
    programs: &Programs,
    trials: u32,
    threads: usize,
) -> Result<Vec<(protocol::measurement::Measurement, Option<Footwork>)>, Failure> {
    if let Some(name) = &exp.program {
        let program = programs.get(name).ok_or_else(|| {
            Failure::Usage(anyhow!(
                "run `{}` runs the program `{name}`: its Table IV needs it, --program {name}=PATH",
                exp.name
            ))
        })?;
        return program_trials(exp, params, program, &programs.settings, trials, threads);
    }
    trial::in_parallel(u64::from(trials), threads, |k| {
        let k = k as u32;
        worker::run_trial_with_footwork(&table_request(exp, params, k))
            .map_err(|e| Failure::Job(anyhow!("Table IV trial {k}: {e}")))
    })
    .map_err(|e| Failure::Job(anyhow!("Table IV trials: {e}")))?
    .into_iter()
    .collect()
}

/// Table IV's trials of a program's set, `threads` at once (each in a slot
/// of the host's, in a scratch directory of the report's own), each as a
/// worker runs it. Ctrl-C (or SIGTERM) stops the programs as a stopping
/// worker does, and the report with them.
fn program_trials(
    exp: &Experiment,
    params: &[f64],
    program: &worker::program::Program,
    settings: &worker::program::Settings,
    trials: u32,
    threads: usize,
) -> Result<Vec<(protocol::measurement::Measurement, Option<Footwork>)>, Failure> {
    let scratch = worker::job::Scratch::create("report", &uuid::Uuid::new_v4().to_string())
        .map_err(|e| Failure::Job(anyhow!("the programs' scratch space: {e}")))?;
    let lanes = u32::try_from(threads.max(1))
        .unwrap_or(1)
        .min(trials.max(1));
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| Failure::Job(e.into()))?;
    let stop = tokio_util::sync::CancellationToken::new();
    let pool = worker::served::Pool::default();
    let found = rt.block_on(async {
        let lane = |lane: u32| {
            let stop = stop.clone();
            let pool = &pool;
            let root = scratch.path().to_path_buf();
            async move {
                let slot = worker::job::Slot::claim()
                    .map_err(|e| Failure::Job(anyhow!("no slot for the program: {e}")))?;
                let dir = root.join(format!("slot-{}", slot.n));
                let mut got = Vec::new();
                for k in (lane..trials).step_by(lanes as usize) {
                    let req = table_request(exp, params, k);
                    let m =
                        worker::program::run(program, &req, slot.n, &dir, settings, &stop, pool)
                            .await
                            .map_err(|e| Failure::Job(anyhow!("Table IV trial {k}: {e}")))?;
                    got.push((k, m));
                }
                Ok::<_, Failure>(got)
            }
        };
        let all = futures_util::future::join_all((0..lanes).map(lane));
        tokio::pin!(all);
        let found = tokio::select! {
            found = &mut all => found,
            why = crate::serve::interrupted() => {
                stop.cancel();
                let _ = all.await;
                vec![Err(Failure::Job(anyhow!("interrupted by {why}: the programs were stopped")))]
            }
        };
        pool.stop_all(settings.grace).await;
        found
    });
    drop(scratch);
    let mut all = Vec::new();
    for lane in found {
        all.extend(lane?);
    }
    all.sort_by_key(|(k, _)| *k);
    Ok(all.into_iter().map(|(_, m)| (m, None)).collect())
}

fn cell(v: Option<f64>) -> String {
    v.map_or("–".into(), |v| format!("{v:.3}"))
}

/// Table IV's rows that say each column's set, as (label, one cell per
/// column): the optimised parameters, then the run's fixed values.
fn set_rows(exp: &Experiment, rows: &[Row]) -> Vec<(String, Vec<String>)> {
    let mut out: Vec<(String, Vec<String>)> = exp
        .parameter
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let cells = rows.iter().map(|r| format!("{:.4}", r.params[i])).collect();
            (p.name.clone(), cells)
        })
        .collect();
    out.extend(exp.fixed.iter().map(|(name, v)| {
        (
            format!("{name} (fixed)"),
            vec![format!("{v:.4}"); rows.len()],
        )
    }));
    out
}

/// Table IV as Markdown and as JSON.
fn table_text(exp: &Experiment, rows: &[Row], trials: u32) -> (String, String) {
    let expert_mx = rows.first().and_then(|r| r.stats.mx);
    let ratio = |r: &Row| match (r.stats.mx, expert_mx) {
        (Some(a), Some(b)) if b > 0.0 => Some(a / b),
        _ => None,
    };
    let nao = exp.model == TrialModel::Nao;
    let physics = if nao {
        format!(", physics {}", exp.physics)
    } else {
        String::new()
    };
    let mut md = format!(
        "Table IV of {} ({} trials each, seeds {}–{}{physics})\n\n| | {} |\n|---|{}\n",
        exp.name,
        trials,
        TABLE_SEED,
        TABLE_SEED + u64::from(trials) - 1,
        rows.iter().map(|r| r.name).collect::<Vec<_>>().join(" | "),
        "---|".repeat(rows.len())
    );
    for (label, cells) in set_rows(exp, rows) {
        let _ = writeln!(md, "| {label} | {} |", cells.join(" | "));
    }
    let mut line = |label: &str, f: &dyn Fn(&Row) -> String| {
        let cells: Vec<String> = rows.iter().map(f).collect();
        let _ = writeln!(md, "| {label} | {} |", cells.join(" | "));
    };
    line("s", &|r| format!("{:.2}", r.stats.s));
    line("mx (m)", &|r| cell(r.stats.mx));
    line("my (m)", &|r| cell(r.stats.my));
    line("ex (m)", &|r| cell(r.stats.ex));
    line("ey (m)", &|r| cell(r.stats.ey));
    line("mx / Expert", &|r| {
        ratio(r).map_or("–".into(), |v| format!("{v:.2}×"))
    });
    if nao {
        line("planned (m)", &|r| cell(r.planned));
        line("planned step (m)", &|r| {
            r.planned_step.map_or("–".into(), |v| format!("{v:.4}"))
        });
        line("mx / planned", &|r| {
            over_plan(r).map_or("–".into(), |v| format!("{v:.2}"))
        });
        line("mx by stepping (m)", &|r| {
            cell(r.footwork.map(|w| w.stepping_m))
        });
        line("mx by sliding (m)", &|r| {
            cell(r.footwork.map(|w| w.sliding_m))
        });
        line("mx by lean (m)", &|r| cell(r.footwork.map(|w| w.lean_m)));
        line("landed beyond aim per step (mm)", &landed_beyond_aim);
        line(
            "step at touchdown (m) / moved on after (mm)",
            &step_at_touchdown,
        );
        line("torso pitch (°, − leans back)", &torso_pitch);
    }
    let json: Vec<serde_json::Value> = rows
        .iter()
        .map(|r| {
            let params: serde_json::Map<String, serde_json::Value> = exp
                .parameter
                .iter()
                .zip(&r.params)
                .map(|(p, v)| (p.name.clone(), serde_json::json!(v)))
                .collect();
            serde_json::json!({
                "name": r.name,
                "params": params,
                "trials": r.stats.trials,
                "s": r.stats.s,
                "mx": r.stats.mx,
                "my": r.stats.my,
                "ex": r.stats.ex,
                "ey": r.stats.ey,
                "mx_over_expert": ratio(r),
                "planned_m": r.planned,
                "planned_step_m": r.planned_step,
                "mx_over_planned": over_plan(r),
                "footwork": r.footwork,
            })
        })
        .collect();
    let json = serde_json::json!({
        "experiment": exp.name,
        "seed0": TABLE_SEED,
        "trials": trials,
        "physics": nao.then_some(exp.physics),
        "fixed": exp.fixed,
        "columns": json,
    });
    (md, format!("{json:#}\n"))
}

/// The run's physics (NAO runs) and fixed values, or nothing to say.
fn setup_text(exp: &Experiment) -> Option<String> {
    let mut parts = Vec::new();
    if exp.model == TrialModel::Nao {
        parts.push(format!("physics {}", exp.physics));
    }
    if !exp.fixed.is_empty() {
        let fixed: Vec<String> = exp
            .fixed
            .iter()
            .map(|(k, v)| format!("{k} = {v}"))
            .collect();
        parts.push(format!("fixed: {}", fixed.join(", ")));
    }
    (!parts.is_empty()).then(|| parts.join("; "))
}

/// [`setup_text`] as a paragraph of the run's page, or nothing.
fn setup_html(exp: &Experiment) -> String {
    setup_text(exp).map_or_else(String::new, |t| {
        format!("<p class=\"setup\">{}.</p>\n", escape(&t))
    })
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The run's wall time as the page says it: served time over its sessions,
/// when it started, and whether it is still being served.
fn wall_text(view: &coordinator::run::RunView) -> String {
    let Some(w) = view.wall else {
        return "Wall time: not journaled (a journal written before naofarm journaled its clock)."
            .into();
    };
    let sessions = match w.sessions {
        1 => "1 session".to_string(),
        n => format!("{n} sessions (a resume's downtime not counted)"),
    };
    let live = if view.live {
        "; still being served, so far"
    } else {
        ""
    };
    format!(
        "Wall time {} over {sessions}{live}: started {} UTC, last decision {} UTC.",
        duration_text(w.served_ms),
        utc_text(w.first_ms),
        utc_text(w.last_ms)
    )
}

/// `1 h 02 min 03 s`, `6 min 11 s`, `4.2 s`.
fn duration_text(ms: u64) -> String {
    let s = ms / 1000;
    match s {
        0..=59 => format!("{:.1} s", ms as f64 / 1000.0),
        60..=3599 => format!("{} min {:02} s", s / 60, s % 60),
        _ => format!("{} h {:02} min {:02} s", s / 3600, s / 60 % 60, s % 60),
    }
}

/// `2026-11-23 18:04:05` from milliseconds since the Unix epoch.
fn utc_text(ms: u64) -> String {
    let t = i64::try_from(ms / 1000)
        .ok()
        .and_then(|s| time::OffsetDateTime::from_unix_timestamp(s).ok());
    t.map_or_else(
        || format!("{ms} ms after the epoch"),
        |t| {
            format!(
                "{:04}-{:02}-{:02} {:02}:{:02}:{:02}",
                t.year(),
                u8::from(t.month()),
                t.day(),
                t.hour(),
                t.minute(),
                t.second()
            )
        },
    )
}

/// One self-contained page: the run's facts, Table IV and every figure.
fn index_html(
    dir: &Path,
    exp: &Experiment,
    view: &coordinator::run::RunView,
    rows: &[Row],
    trials: u32,
    figures: &[(String, String)],
    replays: &[(String, String)],
) -> String {
    let c = |d| view.decided.iter().filter(|x| x.decision == d).count();
    let mut h = String::new();
    let _ = write!(
        h,
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>naofarm report: {name}</title>\
         <style>body{{font-family:sans-serif;max-width:1500px;margin:1em auto}}\
         table{{border-collapse:collapse}}td,th{{border:1px solid #aaa;padding:2px 8px;text-align:right}}\
         figure{{display:inline-block;margin:4px;vertical-align:top}}img{{width:720px;height:360px}}img.replay{{width:auto;height:auto;max-width:1400px}}</style>\
         </head><body>\n<h1>{name}</h1>\n<p>run id {id}, seed {seed}, robot type {ty}, \
         model {model:?}; {n} of {planned} iterations decided × {tpi} trials of {dur} s: \
         {a} ACCEPT, {q} EQUIVALENT, {r} REJECT.</p>\n{setup}<p class=\"wall\">{wall}</p>\n",
        name = escape(&exp.name),
        id = escape(view.id.as_deref().unwrap_or("–")),
        seed = exp.seed,
        ty = exp.robot_type,
        model = exp.model,
        n = view.decided.len(),
        planned = exp.iterations,
        tpi = exp.trials_per_iteration,
        dur = exp.trial_duration_s,
        a = c(Decision::Accept),
        q = c(Decision::Equivalent),
        r = c(Decision::Reject),
        wall = escape(&wall_text(view)),
        setup = setup_html(exp),
    );
    let _ = write!(
        h,
        "<h2>Table IV</h2>\n<p>{trials} trials each from seed {TABLE_SEED}.</p>\n<table>\n<tr><th></th>"
    );
    for r in rows {
        let _ = write!(h, "<th>{}</th>", r.name);
    }
    h += "</tr>\n";
    let expert_mx = rows.first().and_then(|r| r.stats.mx);
    for (label, cells) in set_rows(exp, rows) {
        let _ = write!(h, "<tr><th>{}</th>", escape(&label));
        for c in cells {
            let _ = write!(h, "<td>{c}</td>");
        }
        h += "</tr>\n";
    }
    let mut line = |label: &str, f: &dyn Fn(&Row) -> String| {
        let _ = write!(h, "<tr><th>{}</th>", escape(label));
        for r in rows {
            let _ = write!(h, "<td>{}</td>", f(r));
        }
        h += "</tr>\n";
    };
    line("s", &|r| format!("{:.2}", r.stats.s));
    line("mx (m)", &|r| cell(r.stats.mx));
    line("my (m)", &|r| cell(r.stats.my));
    line("mx / Expert", &|r| match (r.stats.mx, expert_mx) {
        (Some(a), Some(b)) if b > 0.0 => format!("{:.2}×", a / b),
        _ => "–".into(),
    });
    if exp.model == TrialModel::Nao {
        line("mx / planned", &|r| {
            over_plan(r).map_or("–".into(), |v| format!("{v:.2}"))
        });
        line("mx by stepping / sliding / lean (m)", &|r| {
            r.footwork.map_or("–".into(), |w| {
                format!("{:.3} / {:.3} / {:.3}", w.stepping_m, w.sliding_m, w.lean_m)
            })
        });
        line("landed beyond aim per step (mm)", &landed_beyond_aim);
        line(
            "step at touchdown (m) / moved on after (mm)",
            &step_at_touchdown,
        );
        line("torso pitch (°, − leans back)", &torso_pitch);
    }
    h += "</table>\n";
    if exp.model == TrialModel::Nao {
        let _ = writeln!(
            h,
            "<p>A column again, on more or other seeds, or recorded (<code>--record</code>, \
             <code>--render</code>): <code>naofarm trial --experiment {d} --set optim1 \
             --trials {trials} --seed {TABLE_SEED}</code> (<code>--set</code> \
             <code>expert</code>, <code>optim1</code> or <code>optim2</code>).</p>",
            d = escape(&dir.display().to_string())
        );
        let _ = writeln!(
            h,
            "<p>These bodies as SimSpark robot types, to try them on the league's server: \
             <a href=\"{SIMSPARK_TYPES}\">{SIMSPARK_TYPES}</a>.</p>"
        );
    }
    if !replays.is_empty() {
        h += "<h2>Watch them walk</h2>\n<p>The first Table IV trial of each set, re-simulated \
              bit for bit; bodies as segments from their parent's centre, to scale.</p>\n";
        for (file, caption) in replays {
            let _ = writeln!(
                h,
                "<figure><img class=\"replay\" src=\"{f}\" alt=\"{c}\"><figcaption>{c}</figcaption></figure>",
                f = escape(file),
                c = escape(caption)
            );
        }
    }
    h += "<h2>Figures</h2>\n";
    for (file, caption) in figures {
        let _ = writeln!(
            h,
            "<figure><img src=\"{f}\" alt=\"{c}\"><figcaption>{c}</figcaption></figure>",
            f = escape(file),
            c = escape(caption)
        );
    }
    // For a reader's tools (and the browser test): how many images decoded.
    h += "<script>window.addEventListener('load', () => {\
          const imgs = [...document.images];\
          const ok = imgs.filter(i => i.complete && i.naturalWidth > 0).length;\
          document.body.dataset.imagesLoaded = ok;\
          document.body.dataset.imagesFailed = imgs.length - ok;\
          });</script>\n</body></html>\n";
    h
}

/// The animated replay of trial seed [`TABLE_SEED`] of one parameter set.
pub(crate) fn replay_svg(exp: &Experiment, params: &[f64], title: &str) -> Result<String, Failure> {
    let named = exp.full_params(params);
    let values =
        ParamValues::from_named(&named).map_err(|e| Failure::Job(anyhow!("{title}: {e}")))?;
    let what = worker::nao::replay::Replayed {
        robot_type: exp.robot_type,
        seed: TABLE_SEED,
        duration_s: exp.trial_duration_s,
        params: &named,
        values: &values,
        settings: SimSettings::with_physics(&exp.physics),
        engine: trial::Engine::WALK,
    };
    render::trial_svg(&what, title).map_err(|e| Failure::Job(anyhow!("{title}'s replay: {e}")))
}

/// The page over several runs: each run's facts, Table IV row, converged
/// parameters (CLOP's mean, and the spread of the last 100 samples).
fn runs_html(found: &[Found], out: &Path, trials: u32) -> String {
    let mut h = String::from(
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>naofarm report over runs</title><style>body{font-family:sans-serif;\
         max-width:1500px;margin:1em auto}table{border-collapse:collapse}td,th{border:1px \
         solid #aaa;padding:2px 8px;text-align:right}</style></head><body>\n\
         <h1>Runs side by side</h1>\n<img src=\"best.svg\" alt=\"best mx over iterations\">\n",
    );
    let _ = writeln!(
        h,
        "<h2>Table IV rows</h2><p>{trials} trials per column from seed {TABLE_SEED}.</p>\
         <table><tr><th>run</th><th>experiment</th><th>seed</th><th>type</th><th>set-up</th>\
         <th>decided</th><th>wall time</th><th>Expert s / mx</th><th>Optim.1 s / mx</th><th>Optim.2 s / mx</th>\
         <th>Optim.1 / Expert</th><th>Optim.2 / Expert</th></tr>"
    );
    for (k, f) in found.iter().enumerate() {
        let exp = &f.view.experiment;
        let col = |name: &str| f.rows.iter().find(|r| r.name == name);
        let sm = |name: &str| {
            col(name).map_or("–".into(), |r| {
                format!("{:.2} / {}", r.stats.s, cell(r.stats.mx))
            })
        };
        let ratio = |name: &str| match (
            col(name).and_then(|r| r.stats.mx),
            col("Expert").and_then(|r| r.stats.mx),
        ) {
            (Some(a), Some(b)) if b > 0.0 => format!("{:.2}×", a / b),
            _ => "–".into(),
        };
        let link = f.page.strip_prefix(out).map_or_else(
            |_| f.page.display().to_string(),
            |p| p.display().to_string(),
        );
        let _ = writeln!(
            h,
            "<tr><td><a href=\"{link}\">{k}</a></td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>\
             <td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(&exp.name),
            exp.seed,
            exp.robot_type,
            escape(&setup_text(exp).unwrap_or_else(|| "–".into())),
            f.view.decided.len(),
            f.view
                .wall
                .map_or_else(|| "–".into(), |w| duration_text(w.served_ms)),
            sm("Expert"),
            sm("Optim.1"),
            sm("Optim.2"),
            ratio("Optim.1"),
            ratio("Optim.2"),
        );
    }
    h += "</table>\n<h2>Converged parameters</h2><p>CLOP's mean (Optim.2) ± the standard \
          deviation of the last 100 iterations' samples.</p><table><tr><th>run</th><th>parameter</th>\
          <th>Optim.2</th><th>sd (last 100)</th></tr>\n";
    for (k, f) in found.iter().enumerate() {
        let tail: Vec<&DecidedIteration> = f.view.decided.iter().rev().take(100).collect();
        for (i, p) in f.view.experiment.parameter.iter().enumerate() {
            let v: Vec<f64> = tail.iter().map(|d| d.params[i]).collect();
            let n = v.len() as f64;
            let mean = v.iter().sum::<f64>() / n.max(1.0);
            let sd =
                (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0)).sqrt();
            let o2 = f
                .rows
                .iter()
                .find(|r| r.name == "Optim.2")
                .map_or("–".into(), |r| format!("{:.4}", r.params[i]));
            let _ = writeln!(
                h,
                "<tr><td>{k}</td><td>{}</td><td>{o2}</td><td>{sd:.4}</td></tr>",
                escape(&p.name)
            );
        }
    }
    h += "</table>\n</body></html>\n";
    h
}

/// The system's fonts for the PNGs, with a sans-serif family that exists
/// here as the figures' `sans-serif` (without one, the PNGs have no text and
/// a note says so; the SVGs always do).
fn png_fonts() -> resvg::usvg::Options<'static> {
    let mut opt = resvg::usvg::Options::default();
    let db = opt.fontdb_mut();
    db.load_system_fonts();
    let family = [
        "DejaVu Sans",
        "Liberation Sans",
        "Noto Sans",
        "FreeSans",
        "Arial",
    ]
    .into_iter()
    .find(|f| db.faces().any(|x| x.families.iter().any(|(n, _)| n == f)));
    match family {
        Some(f) => db.set_sans_serif_family(f),
        None => eprintln!("note: no sans-serif font found; the PNG figures have no text"),
    }
    opt
}

/// One SVG figure rasterised.
fn to_png(svg: &str, opt: &resvg::usvg::Options<'_>) -> anyhow::Result<Vec<u8>> {
    let tree = resvg::usvg::Tree::from_str(svg, opt)?;
    let size = tree.size().to_int_size();
    let mut pixmap = resvg::tiny_skia::Pixmap::new(size.width(), size.height())
        .ok_or_else(|| anyhow!("an empty figure"))?;
    resvg::render(
        &tree,
        resvg::tiny_skia::Transform::default(),
        &mut pixmap.as_mut(),
    );
    Ok(pixmap.encode_png()?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decided(iteration: u64, decision: Decision) -> DecidedIteration {
        DecidedIteration {
            iteration,
            params: vec![-0.04],
            stats: Stats {
                trials: 10,
                successes: 10,
                s: 1.0,
                mx: Some(4.0),
                my: Some(0.1),
                ex: Some(0.2),
                ey: Some(0.1),
                mx_all: 4.0,
                my_all: 0.1,
            },
            decision,
            best: None,
        }
    }

    /// The edged bars of a decisions figure: (x, height) of each.
    fn bars(svg: &str) -> Vec<(f64, f64)> {
        let doc = roxmltree::Document::parse(svg).expect("the figure parses");
        doc.descendants()
            .filter(|n| {
                n.tag_name().name() == "rect"
                    && n.attribute("fill") == Some("none")
                    && n.attribute("stroke") == Some("#000000")
            })
            .map(|n| {
                let a = |k| n.attribute(k).and_then(|v| v.parse().ok()).unwrap_or(-1.0);
                (a("x"), a("height"))
            })
            .collect()
    }

    #[test]
    fn a_decision_not_taken_in_a_block_draws_no_bar() {
        // Block one: 30 REJECT and 20 EQUIVALENT, no ACCEPT; block two: 10
        // ACCEPT alone.
        let mut d: Vec<_> = (0..50)
            .map(|i| {
                decided(
                    i,
                    if i < 30 {
                        Decision::Reject
                    } else {
                        Decision::Equivalent
                    },
                )
            })
            .collect();
        d.extend((50..60).map(|i| decided(i, Decision::Accept)));
        let svg = decisions_figure(&d).expect("the figure draws");
        let b = bars(&svg);
        assert_eq!(b.len(), 3, "{b:?}");
        assert!(b.iter().all(|&(_, h)| h > 0.0), "an empty bar: {b:?}");
        // Heights in proportion to the counts: 30, 20 and 10.
        let (h30, h20, h10) = (b[0].1, b[1].1, b[2].1);
        assert!(
            (h30 / h10 - 3.0).abs() < 0.1 && (h20 / h10 - 2.0).abs() < 0.1,
            "{b:?}"
        );
        assert!(b[2].0 > b[0].0, "the ACCEPT bar is in the second block");
        // And it renders as a PNG.
        let png = to_png(&svg, &png_fonts()).expect("renders");
        assert!(png.len() > 1000);
    }
}
