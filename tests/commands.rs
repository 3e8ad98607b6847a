//! End-to-end tests of the single-machine commands (check, run, history,
//! model, stand, trial, deploy configs): the `naofarm` binary as a real process.
#![allow(clippy::unwrap_used)]

mod util;

use util::{events, fails, naofarm, root, run_events, scratch, succeed};

#[test]
fn check_prints_the_five_parameters_with_the_papers_bounds() {
    let out = naofarm()
        .arg("check")
        .arg(root().join("experiments/physical-technical.toml"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for (name, lo, hi) in [
        ("ThighRelHip2_Z", "-0.08", "-0.03"),
        ("ratio_flexion", "0.6", "0.95"),
        ("long_offset_MidAnkles_2_Torso_Init", "0.001", "0.03"),
        ("height_lift", "0.025", "0.07"),
        ("xlength_step_max", "0.02", "0.15"),
    ] {
        let line = text
            .lines()
            .find(|l| l.contains(name))
            .unwrap_or_else(|| panic!("{name} missing:\n{text}"));
        assert!(line.contains(&format!("[{lo}, {hi}]")), "{line}");
    }
}

/// `check` says the physics a NAO experiment runs on: the one physics,
/// with the counts a `[physics]` section may change.
#[test]
fn check_prints_the_physics() {
    let out = succeed(
        naofarm()
            .arg("check")
            .arg(root().join("experiments/physical-technical.toml")),
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("physics: 4 x 5.000 ms steps per 20 ms cycle, 1 solver x 28 PGS iterations"),
        "{text}"
    );
    let dir = scratch("check-physics");
    let file = dir.join("fine.toml");
    let paper =
        std::fs::read_to_string(root().join("experiments/physical-technical.toml")).unwrap();
    std::fs::write(&file, format!("{paper}\n[physics]\nsubsteps = 10\n")).unwrap();
    let out = succeed(naofarm().arg("check").arg(&file));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("physics: 10 x 2.000 ms steps"), "{text}");
}

/// An experiment whose start replaces its robot type's own body says so, in
/// `check`, `run` and `trial --experiment`: the paper's files give
/// ThighRelHip2_Z −0.04 (type 0's), type 3's own thigh is −0.067868424.
/// No shipped file (all type 0) gets the note, nor a trial that gives the
/// type's own value with `--param`.
#[test]
fn a_start_that_replaces_the_robot_types_body_is_noted() {
    let note = "note: ThighRelHip2_Z's expert -0.04 replaces robot type 3's own -0.067868424";
    for f in std::fs::read_dir(root().join("experiments")).unwrap() {
        let f = f.unwrap().path();
        if f.extension().is_some_and(|e| e == "toml") {
            let out = succeed(naofarm().arg("check").arg(&f));
            let text = String::from_utf8_lossy(&out.stdout);
            assert!(!text.contains("note:"), "{}: {text}", f.display());
        }
    }
    let dir = scratch("type-note");
    let paper =
        std::fs::read_to_string(root().join("experiments/physical-technical.toml")).unwrap();
    let typed = paper.replace("robot_type = 0", "robot_type = 3");
    assert_ne!(typed, paper);
    let file = dir.join("type3.toml");
    std::fs::write(&file, typed).unwrap();
    let out = succeed(naofarm().arg("check").arg(&file));
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(text.matches("note:").count(), 1, "{text}");
    assert!(text.contains(note), "{text}");
    assert!(one_iteration_stderr(&file, &dir.join("run")).contains(note));
    let trial = |extra: &[&str]| {
        let out = succeed(
            naofarm()
                .args(["trial", "--trials", "1", "--type", "3", "--experiment"])
                .arg(root().join("experiments/physical-technical.toml"))
                .args(extra),
        );
        String::from_utf8_lossy(&out.stderr).to_string()
    };
    assert!(trial(&[]).contains(note));
    assert!(!trial(&["--param", "ThighRelHip2_Z=-0.067868424"]).contains("note:"));
}

/// What `naofarm run` prints on stderr for one iteration of `file` on one
/// worker, its journal in `out`.
fn one_iteration_stderr(file: &std::path::Path, out: &std::path::Path) -> String {
    let run = succeed(
        naofarm()
            .args(["run", "--workers", "1", "--iterations", "1", "--json"])
            .arg(file)
            .arg("--out")
            .arg(out),
    );
    String::from_utf8_lossy(&run.stderr).to_string()
}

/// `trial --experiment FILE` runs the file's physics, trial duration and
/// expert set: the same trials, bit for bit, as `trial` with no flags (the
/// shipped file is the defaults); `--param` overrides one value; a
/// synthetic experiment is refused (exit 2).
#[test]
fn a_trial_from_an_experiment_file_is_the_trial_its_flags_spell_out() {
    let json = |args: &[&str]| -> serde_json::Value {
        let out = succeed(
            naofarm()
                .args(["trial", "--trials", "2", "--seed", "777", "--json"])
                .args(args),
        );
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let file = root().join("experiments/physical-technical.toml");
    let file = file.to_str().unwrap();
    let from_file = json(&["--experiment", file]);
    let spelled = json(&[]);
    assert_eq!(from_file["feedback"], true);
    assert_eq!(from_file["physics"]["substeps"], 4);
    assert_eq!(from_file["params"]["xlength_step_max"], 0.08);
    for k in ["mx", "my", "ex", "ey", "s"] {
        assert_eq!(from_file[k], spelled[k], "{k}");
    }
    let other = json(&["--experiment", file, "--param", "double_support=0.05"]);
    assert_eq!(other["params"]["double_support"], 0.05);
    assert_ne!(other["mx"], from_file["mx"]);
    let coarse = json(&["--experiment", file, "--substeps", "2"]);
    assert_eq!(coarse["physics"]["substeps"], 2);
    assert_ne!(coarse["mx"], from_file["mx"]);
    let err = fails(
        naofarm()
            .args(["trial", "--experiment"])
            .arg(root().join("experiments/synthetic.toml")),
        2,
    );
    assert!(err.contains("synthetic"), "{err}");
}

#[test]
fn check_json_is_machine_readable() {
    let out = naofarm()
        .args(["check", "--json"])
        .arg(root().join("experiments/physical.toml"))
        .output()
        .unwrap();
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["parameter"][0]["name"], "ThighRelHip2_Z");
    assert_eq!(v["parameter"][0]["lower"], -0.10);
}

#[test]
fn malformed_experiments_exit_2_naming_the_problem() {
    let good = std::fs::read_to_string(root().join("experiments/physical-technical.toml")).unwrap();
    let dir = scratch("check");
    let cases = [
        ("seed = 1", "seed = 1\nspeed = 3", "speed"),
        ("lower = -0.08", "lower = -0.02", "parameter[0].lower"),
        ("expert = 0.730", "expert = 0.99", "parameter[1].expert"),
        ("beta = 1.0", "beta = 3.5", "pickout.beta"),
        (
            "trials_per_iteration = 10",
            "trials_per_iteration = 0",
            "trials_per_iteration",
        ),
        (
            "name = \"height_lift\"",
            "name = \"lift_height\"",
            "unknown parameter `lift_height`",
        ),
        ("lower = 0.60", "lower = nan", "parameter[1].lower"),
        ("seed = 1", "seed = ", "line"),
    ];
    for (i, (from, to, needle)) in cases.iter().enumerate() {
        let text = good.replacen(from, to, 1);
        assert_ne!(text, good, "{from}");
        let path = dir.join(format!("bad{i}.toml"));
        std::fs::write(&path, text).unwrap();
        let out = naofarm().arg("check").arg(&path).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{to}: {err}");
        assert!(err.contains(needle), "{to}: {err}");
    }
    std::fs::write(dir.join("binary.toml"), [0xff, 0xfe, 0x00, 0x80]).unwrap();
    for (path, needle) in [
        (dir.join("missing.toml"), "No such file"),
        (dir.to_path_buf(), "is a directory"),
        (dir.join("binary.toml"), "not UTF-8"),
        // Endless input is read no further than the bound.
        ("/dev/zero".into(), "more than 1048576 bytes"),
    ] {
        let out = naofarm().arg("check").arg(&path).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{}: {err}", path.display());
        assert!(err.contains(needle), "{}: {err}", path.display());
    }
}

#[test]
fn run_completes_a_synthetic_experiment_in_one_process() {
    let dir = scratch("run");
    let ev = run_events("synthetic.toml".as_ref(), 2, 8, &dir.join("run"));
    let lines = ev.decided;
    assert_eq!(lines.len(), 8);
    let status = ev.status.expect("status lines");
    assert_eq!(status["decided"], 8);
    assert_eq!(status["finished"], true);
    let finished = ev.finished.expect("a finished line with the optima");
    let best = &finished["status"]["best"];
    assert!(best["iteration"].is_u64(), "Optim.1: {finished}");
    assert_eq!(
        finished["status"]["optim2"].as_array().map(Vec::len),
        Some(5)
    );

    // `history` exports the same H, with ν′ flagged once.
    let h = succeed(naofarm().arg("history").arg(dir.join("run")).arg("--json"));
    let rows: Vec<serde_json::Value> = serde_json::from_slice(&h.stdout).unwrap();
    assert_eq!(rows.len(), 8);
    for (row, line) in rows.iter().zip(&lines) {
        assert_eq!(row["iteration"], line["iteration"]);
        assert_eq!(row["mx"], line["stats"]["mx"]);
        assert!(["ACCEPT", "EQUIVALENT", "REJECT"].contains(&row["decision"].as_str().unwrap()));
        assert_eq!(row["params"].as_object().map(|o| o.len()), Some(5));
    }
    let flagged: Vec<&serde_json::Value> = rows.iter().filter(|r| r["best"] == true).collect();
    assert_eq!(flagged.len(), 1);
    assert_eq!(flagged[0]["iteration"], best["iteration"]);
    let csv = succeed(naofarm().arg("history").arg(dir.join("run")).arg("--csv"));
    let csv = String::from_utf8_lossy(&csv.stdout);
    assert_eq!(csv.lines().count(), 9, "a header and 8 rows");
    assert!(csv.starts_with("iteration,ThighRelHip2_Z,"));
    let missing = naofarm()
        .arg("history")
        .arg(dir.join("nowhere"))
        .output()
        .unwrap();
    assert_eq!(missing.status.code(), Some(2));
    let err = String::from_utf8_lossy(&missing.stderr);
    assert!(
        err.contains(&format!(
            "{}: does not exist",
            dir.join("nowhere").display()
        )),
        "{err}"
    );
}

#[test]
fn a_torn_journal_resumes_and_a_corrupt_one_is_refused_with_its_offset() {
    let dir = scratch("journal-damage");
    let exp = root().join("experiments/synthetic.toml");
    let run = |out: &std::path::Path| {
        naofarm()
            .args(["run", "--json", "--workers", "1", "--iterations", "6"])
            .arg(&exp)
            .arg("--out")
            .arg(out)
            .output()
            .unwrap()
    };
    let reference = dir.join("reference");
    assert!(run(&reference).status.success());
    let want = succeed(naofarm().arg("history").arg(&reference).arg("--csv")).stdout;
    let journal = reference.join("journal.nfj");
    let bytes = std::fs::read(&journal).unwrap();

    // A torn tail (a crash mid-write): dropped with a warning, the run resumes.
    let torn = dir.join("torn");
    std::fs::create_dir_all(&torn).unwrap();
    std::fs::write(torn.join("journal.nfj"), &bytes[..bytes.len() * 2 / 3 - 3]).unwrap();
    let out = run(&torn);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let got = succeed(naofarm().arg("history").arg(&torn).arg("--csv")).stdout;
    assert_eq!(
        got, want,
        "the resumed history equals the uninterrupted one"
    );

    // A damaged byte in the middle: refused, naming the offset; the file is kept as it was.
    let corrupt = dir.join("corrupt");
    std::fs::create_dir_all(&corrupt).unwrap();
    let mut damaged = bytes.clone();
    let middle = damaged.len() / 2;
    damaged[middle] ^= 0x5a;
    std::fs::write(corrupt.join("journal.nfj"), &damaged).unwrap();
    let out = run(&corrupt);
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("damaged frame at byte offset") && err.contains("journal salvage"),
        "{err}"
    );
    assert_eq!(std::fs::read(corrupt.join("journal.nfj")).unwrap(), damaged);
}

#[test]
fn the_main_job_runs_five_nao_iterations() {
    let dir = scratch("main-job");
    let file = "physical-technical.toml".as_ref();
    let ev = run_events(file, 2, 5, &dir.join("run"));
    let lines = ev.decided;
    assert_eq!(lines.len(), 5);
    assert_eq!(
        lines[0]["params"][0],
        serde_json::json!(["ThighRelHip2_Z", -0.04]),
        "the expert set first"
    );
    // CLOP's first five decisions on the shipped walk and physics, pinned:
    // the decision and the iteration's mx to the bit.
    let pinned = [
        ("ACCEPT", 4.617_454_624_176_025),
        ("REJECT", 3.357_956_504_821_777_4),
        ("ACCEPT", 4.657_531_023_025_513),
        ("EQUIVALENT", 4.649_825_334_548_95),
        ("REJECT", 0.962_445_807_456_970_2),
    ];
    for (line, (decision, mx)) in lines.iter().zip(pinned) {
        assert_eq!(line["decision"], decision, "{line}");
        let got = line["stats"]["mx"].as_f64().map(f64::to_bits);
        assert_eq!(got, Some(f64::to_bits(mx)), "{line}");
    }
    let finished = ev.finished.expect("finished line");
    assert_eq!(finished["status"]["decided"], 5);
    assert_eq!(finished["status"]["finished"], true);

    // A farm trial replayed locally gives the journaled x, y and fall time bit for bit.
    let run_dir = dir.join("run");
    let journaled = coordinator::journal::Journal::read(&run_dir)
        .unwrap()
        .records()
        .into_iter()
        .find_map(|r| match r {
            coordinator::journal::Record::Outcome {
                iteration: 4,
                trial: 7,
                measurement,
                ..
            } => Some(measurement),
            _ => None,
        })
        .expect("trial 4/7 journaled");
    let record = dir.join("replay.jsonl");
    let out = succeed(
        naofarm()
            .args([
                "trial",
                "--json",
                "--iteration",
                "4",
                "--trial",
                "7",
                "--run",
            ])
            .arg(&run_dir)
            .arg("--record")
            .arg(&record),
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["identical"], true, "{v}");
    let bits = |x: &serde_json::Value| x.as_f64().map(f64::to_bits);
    assert_eq!(bits(&v["replayed"]["x_m"]), Some(journaled.x_m.to_bits()));
    assert_eq!(bits(&v["replayed"]["y_m"]), Some(journaled.y_m.to_bits()));
    assert_eq!(
        v["replayed"]["fall_time_s"].as_f64().map(f64::to_bits),
        journaled.fall_time_s.map(f64::to_bits)
    );
    let header: serde_json::Value = serde_json::from_str(
        std::fs::read_to_string(&record)
            .unwrap()
            .lines()
            .next()
            .unwrap(),
    )
    .unwrap();
    assert_eq!(
        header["seed"], v["seed"],
        "the replay records the farm trial's seed"
    );
    let err = String::from_utf8_lossy(
        &naofarm()
            .args(["trial", "--iteration", "99", "--trial", "0", "--run"])
            .arg(&run_dir)
            .output()
            .unwrap()
            .stderr,
    )
    .to_string();
    assert!(err.contains("iteration 99 is not open"), "{err}");
}

#[test]
fn a_closed_pipe_ends_output_quietly() {
    // `naofarm model | head -1`, and a run whose JSON events (over 100 kB,
    // more than a pipe holds) lose their reader after one line: each ends
    // with 0 and no panic, and the run goes on to its end.
    let dir = scratch("pipe");
    let run_dir = dir.join("run").display().to_string();
    let exp = root()
        .join("experiments/synthetic.toml")
        .display()
        .to_string();
    for args in [
        vec!["model".to_string()],
        vec!["model".into(), "--json".into()],
        vec![
            "run".into(),
            "--json".into(),
            exp,
            "--out".into(),
            run_dir.clone(),
        ],
    ] {
        use std::io::BufRead;
        let mut child = naofarm()
            .args(&args)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let mut first = String::new();
        std::io::BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut first)
            .unwrap();
        assert!(!first.is_empty());
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    let h = succeed(naofarm().args(["history", "--csv", &run_dir]));
    assert_eq!(
        String::from_utf8_lossy(&h.stdout).lines().count(),
        61,
        "the run went on"
    );
}

#[test]
fn model_prints_the_robot_and_refuses_an_impossible_thigh() {
    let out = naofarm()
        .args(["model", "--json", "--param", "ThighRelHip2_Z=-0.079"])
        .output()
        .unwrap();
    assert!(out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!((v["total_mass_kg"].as_f64().unwrap() - 4.6071).abs() < 1e-9);
    assert!((v["hip_to_sole_m"].as_f64().unwrap() - 0.309).abs() < 1e-9);
    let joints = v["joints"].as_array().unwrap();
    assert_eq!(joints.len(), 22);
    for f in ["name", "lower_rad", "upper_rad", "max_speed_rad_s"] {
        assert!(joints.iter().all(|j| !j[f].is_null()), "{f}");
    }
    let out = naofarm()
        .args(["model", "--param", "ThighRelHip2_Z=0.2"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("ThighRelHip2_Z") && err.contains("[-0.12, -0.005]"),
        "{err}"
    );
    let out = naofarm()
        .args(["model", "--param", "Bogus=1"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let out = naofarm().args(["model", "--type", "7"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn stand_holds_and_reports_its_fields() {
    let out = succeed(naofarm().args(["stand", "--json", "--seconds", "3"]));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["fell"], false);
    let lo = v["torso_height_min_m"].as_f64().unwrap();
    let hi = v["torso_height_max_m"].as_f64().unwrap();
    assert!(lo > 0.3 && hi - lo < 0.01, "{lo} {hi}");
    let out = naofarm()
        .args(["stand", "--param", "ThighRelHip2_Z=-0.3"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn trial_prints_the_table_iv_row_and_refuses_bad_parameters() {
    let run = |seed: &str| {
        let out = succeed(naofarm().args([
            "trial",
            "--json",
            "--trials",
            "3",
            "--duration",
            "3",
            "--seed",
            seed,
        ]));
        serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()
    };
    let a = run("5");
    for f in ["s", "mx", "my", "ex", "ey"] {
        assert!(a[f].is_number(), "{f}: {a}");
    }
    let trials = a["trials"].as_array().unwrap();
    assert_eq!(trials.len(), 3);
    for f in ["seed", "fell", "x", "y", "fall_time_s"] {
        assert!(trials.iter().all(|t| t.get(f).is_some()), "{f}");
    }
    // Each trial's distance, split by its feet, sums back to it.
    for t in trials {
        let w = &t["footwork"];
        let sum: f64 = ["stepping_m", "sliding_m", "lean_m"]
            .iter()
            .map(|f| w[f].as_f64().unwrap())
            .sum();
        assert!((sum - t["x"].as_f64().unwrap()).abs() < 1e-9, "{t}");
        assert!(w["plants"].as_u64().is_some(), "{t}");
    }
    assert!(a["planned_m"].as_f64().is_some_and(|p| p > 0.0), "{a}");
    assert_eq!(a["planned_step_m"].as_f64(), Some(0.08), "{a}");
    // A step the swing hip cannot turn within its speed cap is capped at
    // the legs' reach, and said so.
    let long = |json: bool| {
        let mut c = naofarm();
        c.args(["trial", "--trials", "1", "--duration", "1"]);
        c.args(["--param", "xlength_step_max=0.15"]);
        if json {
            c.arg("--json");
        }
        succeed(&mut c).stdout
    };
    let v: serde_json::Value = serde_json::from_slice(&long(true)).unwrap();
    let capped = v["planned_step_m"].as_f64().unwrap();
    assert!(capped > 0.02 && capped < 0.15, "{capped}");
    assert_eq!(v["reach_step_m"].as_f64(), Some(capped), "{v}");
    let text = String::from_utf8(long(false)).unwrap();
    assert!(text.contains("capped at the legs' reach"), "{text}");
    // The expert's step is within its reach.
    assert!(a["reach_step_m"].as_f64().is_some_and(|r| r > 0.08), "{a}");
    // The touchdowns: the step each took and how far the foot landed
    // before it moved on, in the text and the JSON.
    assert!(text.contains("at touchdown the feet are"), "{text}");
    for f in ["spacing_m", "settle_m"] {
        assert!(
            v["footwork"][f].as_f64().is_some_and(f64::is_finite),
            "{f}: {v}"
        );
    }
    let b = run("5");
    assert_eq!(a["mx"], b["mx"]);
    assert_eq!(a["trials"], b["trials"]);
    // Out of range, unknown (a feedback gain is the engine's own, no
    // parameter), not a number.
    for bad in [
        "ratio_flexion=7",
        "Bogus=1",
        "height_lift=nan",
        "step_period=0.01",
        "hip_pitch_gain=0.3",
        "step_aim=0.3",
    ] {
        let out = naofarm()
            .args(["trial", "--trials", "1", "--param", bad])
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "{bad}");
        assert!(!out.stderr.is_empty());
    }
    let out = naofarm()
        .args(["trial", "--trials", "1", "--pgs-iterations", "500"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--pgs-iterations"));
    // The physics' variants are gone: their flags are unknown (exit 2).
    for gone in ["--firm-stops", "--walk", "--substeps-max", "--contact-hz"] {
        fails(naofarm().args(["trial", "--trials", "1", gone, "1"]), 2);
    }
}

#[test]
fn trial_records_a_replay_of_its_first_trial() {
    let dir = scratch("record");
    let f = dir.join("replay.jsonl");
    let out = succeed(
        naofarm()
            .args([
                "trial",
                "--json",
                "--trials",
                "2",
                "--duration",
                "1",
                "--seed",
                "4",
            ])
            .arg("--record")
            .arg(&f),
    );
    let row: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let text = std::fs::read_to_string(&f).unwrap();
    let lines: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let bodies = lines[0]["bodies"].as_array().unwrap().len();
    assert_eq!(lines[0]["seed"], 4);
    assert_eq!(bodies, 23, "type 0 has 23 bodies");
    // One line per 20 ms cycle of the 1 s trial, every body's pose in each.
    assert_eq!(lines.len(), 1 + 50);
    let joints: Vec<&str> = lines[0]["joints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| j.as_str().unwrap())
        .collect();
    assert!(
        joints.contains(&"lle3") && joints.contains(&"rle4"),
        "{joints:?}"
    );
    let knee = joints.iter().position(|j| *j == "lle4").unwrap();
    assert_eq!(lines[0]["planted_n"], 10.0, "footwork's PLANTED_N");
    for l in &lines[1..] {
        let poses = l["poses"].as_array().unwrap();
        assert_eq!(poses.len(), bodies);
        assert!(poses
            .iter()
            .flat_map(|p| p.as_array().unwrap())
            .all(|x| x.as_f64().unwrap().is_finite()));
        // Each joint's angle beside its target, and both feet's loads.
        let angles = l["angles"].as_array().unwrap();
        let targets = l["targets"].as_array().unwrap();
        assert_eq!((angles.len(), targets.len()), (joints.len(), joints.len()));
        let (a, t) = (
            angles[knee].as_f64().unwrap(),
            targets[knee].as_f64().unwrap(),
        );
        assert!(
            (a - t).abs() < 0.5,
            "the left knee at {a} rad, steered to {t}"
        );
        assert_eq!(l["load"].as_array().unwrap().len(), 2);
    }
    // The robot stands on its feet: once it has settled, their loads carry
    // its weight (4.607 kg, 45.2 N) on average.
    let carried: f64 = lines[10..26]
        .iter()
        .map(|l| l["load"][0].as_f64().unwrap() + l["load"][1].as_f64().unwrap())
        .sum::<f64>()
        / 16.0;
    assert!(
        (carried / 45.2 - 1.0).abs() < 0.2,
        "the feet carry {carried} N"
    );
    // The recorded trial is the first of the row: same end of the torso.
    let last = &lines[50]["poses"][0];
    let first = &lines[1]["poses"][0];
    let dx = last[0].as_f64().unwrap() - first[0].as_f64().unwrap();
    let x = row["trials"][0]["x"].as_f64().unwrap();
    assert!((dx - x).abs() < 0.05, "{dx} vs {x}");
    let z = last[2].as_f64().unwrap();
    assert!(z > 0.25 && z < 0.45, "torso at {z} m");
    let out = naofarm()
        .args([
            "trial",
            "--trials",
            "1",
            "--record",
            "/nonexistent-dir/x.jsonl",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));

    // --render: the same trial as an animated SVG, 2 s at 12.5 frames/s.
    let dir = scratch("render");
    let svg = dir.join("walk.svg");
    succeed(
        naofarm()
            .args(["trial", "--trials", "1", "--duration", "2", "--seed", "4"])
            .arg("--render")
            .arg(&svg),
    );
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<svg"), "{}", &text[..text.len().min(200)]);
    let frames = text
        .split("values=\"")
        .nth(1)
        .and_then(|v| v.split('"').next())
        .map(|v| v.split(';').count());
    assert_eq!(frames, Some(25));
    // A segment per body but the torso, in two views, each with 4 moving ends.
    assert_eq!(text.matches("<animate ").count(), 22 * 2 * 4);

    // An earlier replay or animation is written again (seed 5 now); any
    // other file, a run's journal say, is refused (exit 2) and kept.
    let again = |flag: &str, path: &std::path::Path| {
        let mut cmd = naofarm();
        cmd.args(["trial", "--trials", "1", "--duration", "1", "--seed", "5"])
            .arg(flag)
            .arg(path);
        cmd
    };
    succeed(&mut again("--render", &svg));
    assert!(std::fs::read_to_string(&svg).unwrap().contains("seed 5"));
    succeed(&mut again("--record", &f));
    let header: serde_json::Value =
        serde_json::from_str(std::fs::read_to_string(&f).unwrap().lines().next().unwrap()).unwrap();
    assert_eq!(header["seed"], 5);
    let journal = dir.join("journal.nfj");
    std::fs::write(&journal, b"NAOFARMJ\x02\x00\x00\x00 someone's run").unwrap();
    let page = dir.join("page.svg");
    std::fs::write(
        &page,
        "<svg xmlns=\"http://www.w3.org/2000/svg\">mine</svg>",
    )
    .unwrap();
    for (flag, path, what) in [
        ("--record", &journal, "a naofarm replay"),
        ("--render", &page, "a naofarm trial animation"),
        ("--record", &svg, "a naofarm replay"),
        ("--render", &f, "a naofarm trial animation"),
    ] {
        let before = std::fs::read(path).unwrap();
        let err = fails(&mut again(flag, path), 2);
        assert!(
            err.contains(&format!(
                "{flag} {}: exists and is not {what}; give a new path",
                path.display()
            )),
            "{err}"
        );
        assert_eq!(
            std::fs::read(path).unwrap(),
            before,
            "{flag} {}",
            path.display()
        );
    }
    let err = fails(&mut again("--record", &dir), 2);
    assert!(err.contains("exists and is not a file"), "{err}");
}

#[test]
fn the_nao_farm_gives_the_same_history_with_one_or_two_workers() {
    let dir = scratch("nao-farm");
    let exp = dir.join("nao.toml");
    std::fs::write(
        &exp,
        "name = \"nao-small\"\nseed = 3\niterations = 3\ntrials_per_iteration = 3\n\
         trial_duration_s = 2.0\npipeline_depth = 2\nmodel = \"nao\"\nstart = \"expert\"\n\n\
         [[parameter]]\nname = \"ratio_flexion\"\nkind = \"linear\"\nlower = 0.6\nupper = 0.95\nexpert = 0.73\n\n\
         [[parameter]]\nname = \"xlength_step_max\"\nkind = \"linear\"\nlower = 0.02\nupper = 0.15\nexpert = 0.08\n",
    )
    .unwrap();
    let run = |workers: &str| {
        let out_dir = dir.join(format!("run-{workers}"));
        let out = succeed(
            naofarm()
                .args(["run", "--json", "--workers", workers])
                .arg(&exp)
                .arg("--out")
                .arg(&out_dir),
        );
        events(&out.stdout)
            .decided
            .into_iter()
            .map(|v| {
                (
                    v["iteration"].clone(),
                    v["decision"].clone(),
                    v["stats"]["mx"].clone(),
                    v["params"].clone(),
                )
            })
            .collect::<Vec<_>>()
    };
    let one = run("1");
    assert_eq!(one.len(), 3);
    assert_eq!(one, run("2"));
}

#[test]
fn deploy_configs_are_valid_zenoh_configs() {
    for f in [
        "router",
        "coordinator",
        "worker",
        "tls/router",
        "tls/worker",
    ] {
        let path = root().join(format!("deploy/{f}.json5"));
        if let Err(e) = zenoh::Config::from_file(&path) {
            panic!("{}: {e}", path.display());
        }
    }
}

/// Every deploy recipe runs the fleet over mutual TLS: each naofarm command
/// it starts that talks to the network passes `--tls`, every endpoint is
/// `tls/…`, the certificates are made by `naofarm certs`, and the SLURM job
/// is valid bash.
#[test]
fn deploy_recipes_run_over_tls() {
    let recipes = [
        "compose.yaml",
        "slurm/farm.sbatch",
        "systemd/naofarm-router.service",
        "systemd/naofarm-coordinator.service",
        "systemd/naofarm-worker.service",
    ];
    let mut commands = 0;
    for r in recipes {
        let text = std::fs::read_to_string(root().join("deploy").join(r)).unwrap();
        assert!(!text.contains("tcp/"), "{r} names a plain TCP endpoint");
        // A command: from `naofarm ROLE` to the line's end, or a compose
        // `command: ["ROLE", …]` to its closing bracket.
        for w in ["router", "worker", "coordinator", "watch"] {
            for (shell, start) in [
                (true, format!("naofarm {w} ")),
                (false, format!("[\"{w}\"")),
            ] {
                for (at, _) in text.match_indices(&start) {
                    let line_start = text[..at].rfind('\n').map_or(0, |i| i + 1);
                    let before = &text[line_start..at];
                    if before.trim_start().starts_with('#')
                        || before.starts_with("Description=")
                        || (!shell && !before.contains("command:"))
                    {
                        continue;
                    }
                    let end = if shell { '\n' } else { ']' };
                    let cmd = text[at..].split(end).next().unwrap();
                    commands += 1;
                    assert!(cmd.contains("--tls"), "{r}: without --tls: {cmd}");
                }
            }
        }
    }
    assert!(commands >= 9, "only {commands} commands found");
    let sbatch = std::fs::read_to_string(root().join("deploy/slurm/farm.sbatch")).unwrap();
    assert!(sbatch.contains("naofarm certs"));
    let compose = std::fs::read_to_string(root().join("deploy/compose.yaml")).unwrap();
    assert!(compose.contains("[\"certs\""));
    let certs_unit =
        std::fs::read_to_string(root().join("deploy/systemd/naofarm-certs.service")).unwrap();
    assert!(certs_unit.contains("naofarm certs"));
    let syntax = std::process::Command::new("bash")
        .arg("-n")
        .arg(root().join("deploy/slurm/farm.sbatch"))
        .output()
        .unwrap();
    assert!(
        syntax.status.success(),
        "{}",
        String::from_utf8_lossy(&syntax.stderr)
    );
}

/// `bench sim` measures the shipped physics standing and walking, and the
/// walk at the other step and solver counts, in rounds, each measurement in
/// turn; its headline is the shipped walk's row; the rounds are bounded.
#[test]
fn bench_sim_measures_the_shipped_physics_over_rounds() {
    let out =
        succeed(naofarm().args(["bench", "sim", "--json", "--seconds", "1", "--rounds", "3"]));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["rounds"], 3, "{v}");
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 5, "{v}");
    let walk = &rows[1];
    assert_eq!(walk["motion"], "walk", "{v}");
    assert_eq!(
        (&walk["substeps"], &walk["pgs_iterations"]),
        (&serde_json::json!(4), &serde_json::json!(28)),
        "{v}"
    );
    assert_eq!(v["realtime_factor"], walk["realtime_factor"], "{v}");
    assert_eq!(walk["fell"], false, "{v}");
    for r in rows {
        let rtf = r["cpu_realtime_factor"].as_f64().unwrap();
        let sps = r["steps_per_second"].as_f64().unwrap();
        assert!(rtf > 0.0 && sps > 0.0, "{r}");
        // Steps per simulated second: the row's substeps per 20 ms cycle.
        let per_sim_s = sps / rtf;
        let substeps = r["substeps"].as_f64().unwrap();
        assert!(
            (per_sim_s - substeps / 0.02).abs() < 1e-6 * per_sim_s,
            "{per_sim_s}: {r}"
        );
    }
    for bad in ["0", "101", "x"] {
        let out = naofarm()
            .args(["bench", "sim", "--seconds", "1", "--rounds", bad])
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(2), "--rounds {bad}");
    }
}
