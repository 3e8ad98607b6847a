//! End-to-end tests of `naofarm report`: the files it writes read back (SVG
//! parsed, points counted, Table IV's columns and parameters), the run
//! directory left as it was, and the page opened in a real headless browser.
#![allow(clippy::unwrap_used)]

mod util;

use std::path::{Path, PathBuf};

use util::{fails, naofarm, root, run_events, scratch, succeed};

/// A finished 24-iteration synthetic run in `dir/run`; returns its `run
/// --json` finished line.
fn synthetic_run(dir: &Path) -> serde_json::Value {
    let ev = run_events("synthetic.toml".as_ref(), 2, 24, &dir.join("run"));
    ev.finished.expect("a finished line")
}

/// Two iterations of an experiment file of `experiments/`, in `dir/run`.
fn nao_run(dir: &Path, file: &str) {
    run_events(file.as_ref(), 2, 2, &dir.join("run"));
}

fn report(dir: &Path) -> PathBuf {
    let out = dir.join("report");
    succeed(
        naofarm()
            .arg("report")
            .arg(dir.join("run"))
            .arg("--out")
            .arg(&out)
            .args(["--trials", "8"]),
    );
    out
}

/// The circles of an SVG document (it must parse).
fn circles(path: &Path) -> usize {
    let text = std::fs::read_to_string(path).unwrap();
    let doc =
        roxmltree::Document::parse(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(doc.root_element().tag_name().name(), "svg");
    doc.descendants()
        .filter(|n| n.tag_name().name() == "circle")
        .count()
}

fn unix_ms() -> u64 {
    let d = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap();
    u64::try_from(d.as_millis()).unwrap()
}

fn tree_bytes(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let p = e.unwrap().path();
            let b = std::fs::read(&p).unwrap_or_default();
            (p, b)
        })
        .collect();
    v.sort();
    v
}

#[test]
fn report_writes_every_figure_and_table_iv_and_leaves_the_run_as_it_was() {
    let dir = scratch("report");
    let t0 = unix_ms();
    let finished = synthetic_run(&dir);
    let t1 = unix_ms();
    let before = tree_bytes(&dir.join("run"));
    let out = report(&dir);
    assert_eq!(tree_bytes(&dir.join("run")), before, "report only reads");

    let h = succeed(naofarm().arg("history").arg(dir.join("run")).arg("--json"));
    let rows: Vec<serde_json::Value> = serde_json::from_slice(&h.stdout).unwrap();
    assert_eq!(rows.len(), 24);
    let names: Vec<String> = rows[0]["params"]
        .as_object()
        .unwrap()
        .keys()
        .cloned()
        .collect();
    assert_eq!(names.len(), 5);
    // One point per decided iteration in every parameter, pair and progress figure.
    for n in &names {
        assert_eq!(circles(&out.join(format!("param-{n}.svg"))), 24, "{n}");
    }
    let mut pairs = 0;
    for e in std::fs::read_dir(&out).unwrap() {
        let p = e.unwrap().path();
        let f = p.file_name().unwrap().to_string_lossy().to_string();
        if f.starts_with("pair-") && f.ends_with(".svg") {
            assert_eq!(circles(&p), 24, "{f}");
            pairs += 1;
        }
    }
    assert_eq!(pairs, 10, "each pair of five parameters");
    assert_eq!(circles(&out.join("progress.svg")), 24);
    circles(&out.join("decisions.svg"));
    // One bar, with its edge, per decision taken in the (one) block of
    // 50 iterations; a decision not taken draws none, and no bar is empty.
    let taken = ["REJECT", "EQUIVALENT", "ACCEPT"]
        .iter()
        .filter(|d| rows.iter().any(|r| r["decision"] == **d))
        .count();
    let text = std::fs::read_to_string(out.join("decisions.svg")).unwrap();
    let doc = roxmltree::Document::parse(&text).unwrap();
    let edges: Vec<_> = doc
        .descendants()
        .filter(|n| {
            n.tag_name().name() == "rect"
                && n.attribute("fill") == Some("none")
                && n.attribute("stroke") == Some("#000000")
        })
        .collect();
    assert_eq!(edges.len(), taken, "one edged bar per decision taken");
    for r in &edges {
        let h: f64 = r.attribute("height").unwrap().parse().unwrap();
        assert!(h > 0.0, "an empty bar: {r:?}");
    }
    // Every figure also as a PNG of the SVG's size, not blank.
    let mut pngs = 0;
    for e in std::fs::read_dir(&out).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "png") {
            let (w, h, differing) = png_stats(&p);
            assert_eq!((w, h), (720, 360), "{}", p.display());
            assert!(differing > 1000, "{} is blank", p.display());
            pngs += 1;
        }
    }
    assert_eq!(pngs, 5 + 10 + 2);

    // Table IV: Expert, Optim.1 (ν′, the row `history` flags) and Optim.2
    // (CLOP's mean, as the run's finished line gave it), 8 trials each.
    let t: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("table4.json")).unwrap()).unwrap();
    let cols = t["columns"].as_array().unwrap();
    let col_names: Vec<&str> = cols.iter().map(|c| c["name"].as_str().unwrap()).collect();
    assert_eq!(col_names, ["Expert", "Optim.1", "Optim.2"]);
    for c in cols {
        assert_eq!(c["trials"], 8);
        assert!(c["s"].as_f64().is_some_and(|s| (0.0..=1.0).contains(&s)));
    }
    let best = rows.iter().find(|r| r["best"] == true).unwrap();
    assert_eq!(cols[1]["params"], best["params"]);
    let expert = serde_json::json!({
        "ThighRelHip2_Z": -0.04, "ratio_flexion": 0.73,
        "long_offset_MidAnkles_2_Torso_Init": 0.011, "height_lift": 0.042,
        "xlength_step_max": 0.08,
    });
    assert_eq!(cols[0]["params"], expert);
    assert_eq!(cols[0]["mx_over_expert"], 1.0);
    for pair in finished["status"]["optim2"].as_array().unwrap() {
        let (name, value) = (pair[0].as_str().unwrap(), &pair[1]);
        assert_eq!(&cols[2]["params"][name], value, "Optim.2 {name}");
    }
    let md = std::fs::read_to_string(out.join("table4.md")).unwrap();
    assert!(md.contains("| | Expert | Optim.1 | Optim.2 |"), "{md}");
    let page = std::fs::read_to_string(out.join("index.html")).unwrap();
    let imgs = page.matches("<img ").count();
    assert_eq!(imgs, 5 + 10 + 2, "every figure on the page");
    assert!(page.contains("Optim.1"));
    // The run's wall time, from the journal's clock marks: inside the span
    // the test measured around the run, in one session.
    let wall = coordinator::run::read_run(&dir.join("run"))
        .unwrap()
        .wall
        .expect("clock marks journaled");
    assert_eq!(wall.sessions, 1);
    assert!(
        t0 <= wall.first_ms && wall.last_ms <= t1,
        "{wall:?} in {t0}..{t1}"
    );
    assert_eq!(wall.served_ms, wall.last_ms - wall.first_ms);
    assert!(
        page.contains("<p class=\"wall\">Wall time ") && page.contains(" over 1 session: started "),
        "{page}"
    );

    // Over two runs (seeds 1 and 2): each run's report, and one page with both
    // rows. The second is made in two sessions (12 iterations, then extended to 24).
    for iterations in ["12", "24"] {
        succeed(
            naofarm()
                .args(["run", "--json", "--workers", "2", "--seed", "2"])
                .args(["--iterations", iterations])
                .arg(root().join("experiments/synthetic.toml"))
                .arg("--out")
                .arg(dir.join("run2")),
        );
    }
    let both = dir.join("both");
    succeed(
        naofarm()
            .arg("report")
            .arg(dir.join("run"))
            .arg(dir.join("run2"))
            .arg("--out")
            .arg(&both)
            .args(["--trials", "4"]),
    );
    let page = std::fs::read_to_string(both.join("index.html")).unwrap();
    for (k, seed) in [(0, 1), (1, 2)] {
        assert!(both.join(format!("{k}-synthetic/table4.json")).exists());
        assert!(
            page.contains(&format!(
                "<tr><td><a href=\"{k}-synthetic/index.html\">{k}</a></td><td>synthetic</td><td>{seed}</td>"
            )),
            "run {k} on the page: {page}"
        );
    }
    // A synthetic run has no physics and fixes nothing: its set-up is empty.
    assert!(page.contains("<th>type</th><th>set-up</th>"), "{page}");
    assert_eq!(page.matches("<td>0</td><td>–</td>").count(), 2, "{page}");
    circles(&both.join("best.svg"));
    let page2 = std::fs::read_to_string(both.join("1-synthetic/index.html")).unwrap();
    assert!(page2.contains(" over 2 sessions "), "{page2}");
    let wall2 = coordinator::run::read_run(&dir.join("run2")).unwrap().wall;
    assert_eq!(wall2.map(|w| w.sessions), Some(2));
    let e = fails(
        naofarm()
            .arg("report")
            .arg(dir.join("run"))
            .arg(dir.join("run2")),
        2,
    );
    assert!(e.contains("--out"), "{e}");

    // Bad input: no run there, no trials.
    let e = fails(naofarm().arg("report").arg(dir.join("nowhere")), 2);
    assert!(
        e.contains(&format!(
            "{}: does not exist",
            dir.join("nowhere").display()
        )),
        "{e}"
    );
    let e = fails(
        naofarm()
            .arg("report")
            .arg(dir.join("run"))
            .args(["--trials", "0"]),
        2,
    );
    assert!(e.contains("--trials"), "{e}");
    // A file where the report would go is named and kept.
    let notes = dir.join("notes.txt");
    std::fs::write(&notes, "someone's notes").unwrap();
    let e = fails(
        naofarm()
            .arg("report")
            .arg(dir.join("run"))
            .arg("--out")
            .arg(&notes),
        2,
    );
    assert!(e.contains("exists and is not a directory"), "{e}");
    assert_eq!(std::fs::read_to_string(&notes).unwrap(), "someone's notes");
    let e = fails(naofarm().arg("certs").arg(&notes).args(["--host", "x"]), 2);
    assert!(e.contains("exists and is not a directory"), "{e}");
    assert_eq!(std::fs::read_to_string(&notes).unwrap(), "someone's notes");
    // A directory of someone's files, or a run's, is refused before a byte
    // is written (one run's report and the page over several alike); a
    // report's own directory, the default's included, is written again.
    let site = dir.join("site");
    std::fs::create_dir(&site).unwrap();
    std::fs::write(site.join("index.html"), "someone's page").unwrap();
    for (out, held) in [(&site, "index.html"), (&dir.join("run2"), "journal.nfj")] {
        let before = tree_bytes(out);
        for runs in [&["run"][..], &["run", "run2"]] {
            let mut cmd = naofarm();
            cmd.arg("report");
            for r in runs {
                cmd.arg(dir.join(r));
            }
            let e = fails(cmd.arg("--out").arg(out).args(["--trials", "4"]), 2);
            assert!(
                e.contains("holds files that are not a naofarm report's") && e.contains(held),
                "{e}"
            );
            assert_eq!(tree_bytes(out), before, "{}", out.display());
        }
    }
    for out in [both.clone(), dir.join("run/report")] {
        let runs: &[&str] = if out == both {
            &["run", "run2"]
        } else {
            &["run"]
        };
        let mut cmd = naofarm();
        cmd.arg("report");
        for r in runs {
            cmd.arg(dir.join(r));
        }
        succeed(cmd.arg("--out").arg(&out).args(["--trials", "4"]));
    }
}

/// A browser the test can drive: `$NAOFARM_CHROMIUM`, else Debian's.
fn chromium() -> Option<PathBuf> {
    std::env::var_os("NAOFARM_CHROMIUM")
        .map(PathBuf::from)
        .or_else(|| Some(PathBuf::from("/usr/bin/chromium")))
        .filter(|p| p.exists())
}

#[test]
fn the_report_page_loads_in_a_real_browser_with_every_image() {
    let Some(browser) = chromium() else {
        eprintln!(
            "SKIPPED: no Chromium at /usr/bin/chromium or $NAOFARM_CHROMIUM \
             (`.ci/run` installs Debian's `chromium` package; run it as root)"
        );
        return;
    };
    let dir = scratch("report-browser");
    nao_run(&dir, "physical-technical.toml");
    let out = report(&dir);
    let page = format!("file://{}", out.join("index.html").display());
    let headless = |extra: &[&str]| {
        let o = std::process::Command::new(&browser)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--enable-logging=stderr",
                "--v=0",
                "--allow-file-access-from-files",
                "--virtual-time-budget=10000",
                &format!("--user-data-dir={}", dir.join("profile").display()),
            ])
            .args(extra)
            .arg(&page)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        o
    };
    // The page's own script counts the images that decoded.
    let dom = headless(&["--dump-dom"]);
    let text = String::from_utf8_lossy(&dom.stdout);
    assert!(
        text.contains("data-images-loaded=\"20\"") && text.contains("data-images-failed=\"0\""),
        "{}",
        &text[..text.len().min(400)]
    );
    let log = String::from_utf8_lossy(&dom.stderr);
    assert!(
        !log.lines().any(|l| l.contains(":CONSOLE(")),
        "console messages: {log}"
    );
    let shot = dir.join("shot.png");
    headless(&[
        &format!("--screenshot={}", shot.display()),
        "--window-size=1400,1200",
    ]);
    let (w, h, differing) = png_stats(&shot);
    assert!(
        differing > (w * h) as usize / 200,
        "the screenshot is blank"
    );
}

/// A PNG's width, height and how many pixels differ from the first one.
fn png_stats(path: &Path) -> (u32, u32, usize) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let px = &buf[..info.buffer_size()];
    let n = info.color_type.samples();
    let first = &px[..n.min(3)];
    let differing = px.chunks(n).filter(|p| &p[..n.min(3)] != first).count();
    (info.width, info.height, differing)
}

#[test]
fn a_nao_report_has_an_animated_replay_of_expert_optim1_and_optim2() {
    let dir = scratch("report-nao");
    // Experiment 2 with a `[physics]` count and a `[fixed]` walk setting of
    // its own, so that the set-up must travel.
    let text = std::fs::read_to_string(root().join("experiments/physical-technical.toml"))
        .unwrap()
        .replace("[pickout]", "[fixed]\ndouble_support = 0.02\n\n[pickout]");
    let file = dir.join("set-up.toml");
    std::fs::write(&file, format!("{text}\n[physics]\npgs_iterations = 30\n")).unwrap();
    nao_run(&dir, file.to_str().unwrap());
    let out = report(&dir);
    let page = std::fs::read_to_string(out.join("index.html")).unwrap();
    let table: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("table4.json")).unwrap()).unwrap();
    // The run's set-up is on the page and in both tables.
    assert!(
        page.contains("physics 4 x 5.000 ms steps per 20 ms cycle, 1 solver x 30 PGS iterations")
            && page.contains("fixed: double_support = 0.02"),
        "the set-up on the page"
    );
    assert_eq!(table["physics"]["pgs_iterations"], 30);
    assert_eq!(table["fixed"]["double_support"], 0.02);
    let md = std::fs::read_to_string(out.join("table4.md")).unwrap();
    assert!(md.contains("1 solver x 30 PGS iterations"), "{md}");
    assert!(
        md.contains("| double_support (fixed) | 0.0200 | 0.0200 | 0.0200 |"),
        "{md}"
    );
    for (k, name) in [
        "replay-expert.svg",
        "replay-optim1.svg",
        "replay-optim2.svg",
    ]
    .into_iter()
    .enumerate()
    {
        assert!(
            page.contains(&format!("src=\"{name}\"")),
            "{name} on the page"
        );
        let text = std::fs::read_to_string(out.join(name)).unwrap();
        let doc = roxmltree::Document::parse(&text).unwrap();
        let lines: Vec<_> = doc
            .descendants()
            .filter(|n| n.tag_name().name() == "line")
            .collect();
        let moving = lines
            .iter()
            .filter(|l| {
                l.children()
                    .filter(|c| c.tag_name().name() == "animate")
                    .count()
                    == 4
            })
            .count();
        // Every body but the torso, in the side and the top view.
        assert!(moving >= 2 * 20, "{name}: {moving} moving segments");
        let frames = doc
            .descendants()
            .find(|n| n.tag_name().name() == "animate")
            .and_then(|a| a.attribute("values"))
            .map(|v| v.split(';').count())
            .unwrap();
        // 12.5 frames per simulated second, up to the fall if the trial fell:
        // the same trial run by `naofarm trial` says how long it lasted.
        let column = &table["columns"][k];
        let mut trial = naofarm();
        trial.args(["trial", "--trials", "1", "--seed", "777", "--json"]);
        // Table IV's JSON says everything the trial needs: the column's
        // parameters, the run's fixed values and its physics.
        for (p, v) in column["params"]
            .as_object()
            .unwrap()
            .iter()
            .chain(table["fixed"].as_object().unwrap())
        {
            trial.arg("--param").arg(format!("{p}={v}"));
        }
        let physics = &table["physics"];
        for (flag, key) in [
            ("--substeps", "substeps"),
            ("--solver-iterations", "solver_iterations"),
            ("--pgs-iterations", "pgs_iterations"),
        ] {
            trial.arg(flag).arg(physics[key].to_string());
        }
        let t: serde_json::Value = serde_json::from_slice(&succeed(&mut trial).stdout).unwrap();
        // The plan's travel, the same from both, and mx over it: how far
        // the set walks as planned (no sliding or lunging passed off).
        let planned = column["planned_m"].as_f64().unwrap();
        assert_eq!(t["planned_m"].as_f64(), Some(planned), "{name}");
        // And its step, the one the walk takes (capped or not).
        let step = column["planned_step_m"].as_f64();
        assert!(step.is_some_and(|s| s > 0.0), "{column}");
        assert_eq!(t["planned_step_m"].as_f64(), step, "{name}");
        let over = column["mx_over_planned"].as_f64().unwrap();
        assert_eq!(over, column["mx"].as_f64().unwrap() / planned, "{name}");
        // The feet's split of mx sums back to it, and the trial's own
        // split of its distance is the column's first trial's.
        let w = &column["footwork"];
        let split = |w: &serde_json::Value| -> f64 {
            ["stepping_m", "sliding_m", "lean_m"]
                .iter()
                .map(|f| w[f].as_f64().unwrap())
                .sum()
        };
        let mx = column["mx"].as_f64().unwrap();
        assert!((split(w) - mx).abs() < 1e-9, "{name}: {w} against mx {mx}");
        let x0 = t["trials"][0]["x"].as_f64().unwrap();
        assert!(
            (split(&t["trials"][0]["footwork"]) - x0).abs() < 1e-9,
            "{t}"
        );
        if k == 0 {
            assert!(
                (0.9..=1.1).contains(&over),
                "the expert walks as planned: {over}"
            );
            assert!(md.contains("| mx / planned |"), "{md}");
            assert!(md.contains("| planned step (m) |"), "{md}");
            assert!(md.contains("| mx by sliding (m) |"), "{md}");
            // Where its feet land against the legs' aim, over its touchdowns.
            assert!(md.contains("| landed beyond aim per step (mm) |"), "{md}");
            // The step each touchdown takes in the world, and how far the
            // foot that landed before has moved on by then.
            let row = md
                .lines()
                .find(|l| l.starts_with("| step at touchdown (m) / moved on after (mm) |"))
                .unwrap_or_else(|| panic!("{md}"));
            let (spacing, settle) = (
                w["spacing_m"].as_f64().unwrap(),
                w["settle_m"].as_f64().unwrap(),
            );
            assert!(
                row.contains(&format!("| {spacing:.4} / {:+.1} |", settle * 1000.0)),
                "{row}"
            );
            // The expert's steps are about its plan's 0.08 m, and a planted
            // foot stays within a centimetre of where it landed.
            assert!(
                (0.06..0.10).contains(&spacing) && settle.abs() < 0.01,
                "{w}"
            );
            // How it carries its torso: the cell is the column's mean pitch.
            let pitch = w["torso_pitch_deg"].as_f64().unwrap();
            assert!(pitch.abs() < 45.0, "{w}");
            let row = md
                .lines()
                .find(|l| l.starts_with("| torso pitch (°, − leans back) |"))
                .unwrap_or_else(|| panic!("{md}"));
            assert!(
                row.contains(&format!("| {pitch:+.1} |")),
                "{row} against {pitch}"
            );
            assert!(w["touchdowns"].as_u64().unwrap() > 0, "{w}");
            assert!(w["overreach_m"].as_f64().unwrap().is_finite(), "{w}");
            // The expert's distance is steps: it neither slides nor lunges.
            assert!(
                w["sliding_m"].as_f64().unwrap().abs() < 0.05 * mx
                    && w["lean_m"].as_f64().unwrap().abs() < 0.05 * mx,
                "{w}"
            );
        }
        let sim_s = t["trials"][0]["sim_time_s"].as_f64().unwrap();
        let want = sim_s * 12.5;
        assert!(
            (frames as f64 - want).abs() <= 1.0,
            "{name}: {frames} frames for {sim_s} s at 12.5 frames/s"
        );
    }
}

/// `naofarm trial --experiment RUN_DIR --set NAME` runs a Table IV set of a
/// run by its name, exactly as the report ran it: over the same seeds, every
/// column's s, mx, my, ex and ey to the bit. A set the run has not got
/// (ν′ before any ACCEPT) or a run's set asked of an experiment file is a
/// usage error that says so.
#[test]
fn trial_runs_a_runs_table_iv_sets_by_name_as_the_report_does() {
    let dir = scratch("report-sets");
    nao_run(&dir, "physical-technical.toml");
    let out = report(&dir);
    let table: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("table4.json")).unwrap()).unwrap();
    // The page says how.
    let page = std::fs::read_to_string(out.join("index.html")).unwrap();
    let how = format!(
        "naofarm trial --experiment {} --set optim1 --trials 8 --seed 777",
        dir.join("run").display()
    );
    assert!(page.contains(&how), "{how} on the page");
    let columns = table["columns"].as_array().unwrap();
    let names: Vec<_> = columns
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["Expert", "Optim.1", "Optim.2"]);
    let trial = |set: &str| -> std::process::Command {
        let mut c = naofarm();
        c.args([
            "trial", "--trials", "8", "--seed", "777", "--json", "--set", set,
        ])
        .arg("--experiment")
        .arg(dir.join("run"));
        c
    };
    for (column, set) in columns.iter().zip(["expert", "optim1", "Optim.2"]) {
        let t: serde_json::Value =
            serde_json::from_slice(&succeed(&mut trial(set)).stdout).unwrap();
        for key in ["s", "mx", "my", "ex", "ey", "planned_m"] {
            assert_eq!(
                t[key].as_f64().map(f64::to_bits),
                column[key].as_f64().map(f64::to_bits),
                "{set}: {key}"
            );
        }
        for (name, v) in column["params"].as_object().unwrap() {
            assert_eq!(t["params"][name], *v, "{set}: {name}");
        }
    }
    // A run whose every iteration is rejected (no walk is that straight) has
    // no ν′, but has CLOP's mean.
    let text = std::fs::read_to_string(root().join("experiments/physical-technical.toml"))
        .unwrap()
        .replace("xy_ratio = 0.25", "xy_ratio = 0.0")
        .replace("trial_duration_s = 10.0", "trial_duration_s = 1.0");
    let file = dir.join("straight.toml");
    std::fs::write(&file, text).unwrap();
    run_events(&file, 2, 1, &dir.join("straight"));
    let sets = |set: &str| {
        let mut c = naofarm();
        c.args(["trial", "--trials", "1", "--set", set, "--experiment"])
            .arg(dir.join("straight"));
        c
    };
    let e = fails(&mut sets("optim1"), 2);
    assert!(e.contains("no ν′ yet"), "{e}");
    succeed(&mut sets("optim2"));
    let e = fails(
        naofarm()
            .args(["trial", "--trials", "1", "--set", "optim1", "--experiment"])
            .arg(&file),
        2,
    );
    assert!(e.contains("is an experiment file"), "{e}");
    let e = fails(naofarm().args(["trial", "--set", "best"]), 2);
    assert!(e.contains("--set `best`"), "{e}");
}

/// The entries of a `simspark-types.rb`: each row's name and its keys' texts.
fn simspark_entries(text: &str) -> Vec<(String, Vec<(String, String)>)> {
    let mut out: Vec<(String, Vec<(String, String)>)> = Vec::new();
    for line in text.lines() {
        if let Some(name) = line.strip_prefix("# ").and_then(|l| l.split_once(": ")) {
            if !name.0.contains(' ') {
                out.push((name.0.to_string(), Vec::new()));
            }
        } else if let Some((k, v)) = line.trim().split_once(" => ") {
            let entry = out.last_mut().expect("a key inside an entry");
            entry.1.push((
                k.trim_matches('\'').to_string(),
                v.trim_end_matches(',').to_string(),
            ));
        }
    }
    out
}

#[test]
fn a_nao_report_gives_its_bodies_as_simspark_robot_types() {
    let dir = scratch("report-simspark");
    nao_run(&dir, "physical-technical.toml");
    let out = report(&dir);
    let page = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(
        page.contains("href=\"simspark-types.rb\""),
        "linked from the page"
    );
    let table: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("table4.json")).unwrap()).unwrap();
    let text = std::fs::read_to_string(out.join("simspark-types.rb")).unwrap();
    let entries = simspark_entries(&text);
    let columns = table["columns"].as_array().unwrap();
    assert_eq!(
        entries.len(),
        columns.len(),
        "one entry per Table IV column: {text}"
    );
    for ((name, keys), column) in entries.iter().zip(columns) {
        assert_eq!(Some(name.as_str()), column["name"].as_str(), "{text}");
        let thigh = column["params"]["ThighRelHip2_Z"].as_f64().unwrap();
        let given: Vec<&str> = keys.iter().map(|(k, _)| k.as_str()).collect();
        assert_eq!(
            given,
            [
                "Hip1RelTorso_X",
                "Hip1RelTorso_Z",
                "ThighRelHip2_Z",
                "AnkleRelShank_Z",
                "lj5_max_abs_speed",
                "lj6_max_abs_speed",
                "ElbowRelUpperArm_Y",
                "UseToe"
            ],
            "the keys of naorobottypes.rb, in its order"
        );
        // The found thigh, to the bit; the rest of the body is type 0's.
        let read: f64 = keys[2].1.parse().unwrap();
        assert_eq!(read.to_bits(), thigh.to_bits(), "{name}: {text}");
        // `naofarm model --simspark` prints the same entry for that body.
        let model = succeed(
            naofarm()
                .args(["model", "--simspark", "--param"])
                .arg(format!("ThighRelHip2_Z={thigh}")),
        );
        let entry = String::from_utf8(model.stdout).unwrap();
        assert!(
            text.contains(&format!("{},\n", entry.trim_end())),
            "{name}: `model --simspark` printed {entry} and the report {text}"
        );
        assert!(
            entry.contains("'AnkleRelShank_Z' => -0.055,") && entry.contains("'UseToe' => 'false'")
        );
    }
    assert_eq!(entries[0].0, "Expert");
    assert!(
        entries[0]
            .1
            .contains(&("ThighRelHip2_Z".into(), "-0.04".into())),
        "the expert's thigh is type 0's"
    );
}
