//! The run directory survives damage, bad resumes and extensions: each
//! scenario through the CLI, as real processes, with its exit code and message,
//! and the journal's bytes unchanged wherever nothing was torn.
#![allow(clippy::unwrap_used)]

mod util;

use std::path::{Path, PathBuf};

use util::{fails, naofarm, root, scratch, succeed};

fn synthetic() -> PathBuf {
    root().join("experiments/synthetic.toml")
}

/// `naofarm run` of the synthetic experiment with `iterations` into `out`.
fn run(out: &Path, iterations: u64) -> std::process::Command {
    let mut c = naofarm();
    c.args(["run", "--json", "--iterations"])
        .arg(iterations.to_string())
        .arg(synthetic())
        .arg("--out")
        .arg(out);
    c
}

/// An uninterrupted run of `iterations` in `dir/reference`: its directory and history.
fn reference_run(dir: &Path, iterations: u64) -> (PathBuf, Vec<u8>) {
    let reference = dir.join("reference");
    succeed(&mut run(&reference, iterations));
    let want = history(&reference);
    (reference, want)
}

/// `naofarm run` of the experiment file `exp` on the synthetic model with one worker.
fn run_synthetic(
    exp: impl AsRef<std::ffi::OsStr>,
    out: impl AsRef<std::ffi::OsStr>,
    iterations: u64,
) -> std::process::Command {
    let mut c = naofarm();
    c.args([
        "run",
        "--json",
        "--workers",
        "1",
        "--model",
        "synthetic",
        "--iterations",
    ])
    .arg(iterations.to_string())
    .arg(exp)
    .arg("--out")
    .arg(out);
    c
}

fn history(dir: &Path) -> Vec<u8> {
    succeed(naofarm().arg("history").arg(dir).arg("--csv")).stdout
}

fn journal(dir: &Path) -> PathBuf {
    dir.join("journal.nfj")
}

/// Offsets of the journal's frames (format 2: each starts with `NFR2`).
fn frames(bytes: &[u8]) -> Vec<usize> {
    (16..bytes.len().saturating_sub(4))
        .filter(|&i| &bytes[i..i + 4] == b"NFR2")
        .collect()
}

#[test]
fn a_flipped_length_bit_is_refused_everywhere_and_salvage_recovers_the_run() {
    let dir = scratch("flip");
    let (reference, want) = reference_run(&dir, 12);
    let bytes = std::fs::read(journal(&reference)).unwrap();
    let third = frames(&bytes)[2];
    let damaged_dir = dir.join("damaged");
    std::fs::create_dir_all(&damaged_dir).unwrap();
    let mut damaged = bytes.clone();
    damaged[third + 5] ^= 0x01; // the length field's second byte
    std::fs::write(journal(&damaged_dir), &damaged).unwrap();

    let err = fails(naofarm().arg("history").arg(&damaged_dir), 1);
    assert!(err.contains(&format!("byte offset {third}")), "{err}");
    let err = fails(naofarm().args(["journal", "check"]).arg(&damaged_dir), 1);
    assert!(err.contains(&format!("byte offset {third}")), "{err}");
    let err = fails(&mut run(&damaged_dir, 12), 1);
    assert!(
        err.contains(&format!("byte offset {third}"))
            && err.contains("valid record")
            && err.contains("journal salvage"),
        "{err}"
    );
    assert_eq!(
        std::fs::read(journal(&damaged_dir)).unwrap(),
        damaged,
        "nothing changed"
    );

    let salvaged = dir.join("salvaged");
    let salvage = || {
        let mut cmd = naofarm();
        cmd.args(["journal", "salvage"])
            .arg(&damaged_dir)
            .arg("--out")
            .arg(&salvaged);
        cmd
    };
    let out = succeed(&mut salvage());
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains(&format!("at offset {third}")), "{said}");
    assert_eq!(
        std::fs::read(journal(&damaged_dir)).unwrap(),
        damaged,
        "salvage only reads"
    );
    succeed(naofarm().args(["journal", "check"]).arg(&salvaged));
    // Salvaging onto a run is refused, the run kept as it was.
    let before = std::fs::read(journal(&salvaged)).unwrap();
    let err = fails(&mut salvage(), 2);
    assert!(err.contains("already holds a journal"), "{err}");
    assert_eq!(std::fs::read(journal(&salvaged)).unwrap(), before);
    succeed(&mut run(&salvaged, 12));
    assert_eq!(
        history(&salvaged),
        want,
        "the salvaged run resumes to the same history"
    );
}

#[test]
fn a_zero_filled_tail_is_saved_aside_and_the_run_resumes() {
    let dir = scratch("zeros");
    let (reference, want) = reference_run(&dir, 10);
    let bytes = std::fs::read(journal(&reference)).unwrap();
    // A crash after 5 decisions' worth of records, leaving zeros where the next append was.
    let cut = frames(&bytes)[bytes.len() / 2 % frames(&bytes).len()];
    let zeros = dir.join("zeros");
    std::fs::create_dir_all(&zeros).unwrap();
    let mut b = bytes[..cut].to_vec();
    b.extend(std::iter::repeat_n(0u8, 4096));
    std::fs::write(journal(&zeros), &b).unwrap();
    let check = succeed(naofarm().args(["journal", "check"]).arg(&zeros));
    assert!(String::from_utf8_lossy(&check.stdout).contains("torn"));
    succeed(&mut run(&zeros, 10));
    assert_eq!(history(&zeros), want);
    let side = std::fs::read(zeros.join(format!("journal.nfj.torn-{cut}"))).unwrap();
    assert_eq!(
        side,
        vec![0u8; 4096],
        "the cut bytes are kept beside the journal"
    );
}

#[test]
fn a_full_disk_stops_the_run_with_nothing_half_applied_and_it_resumes() {
    let dir = scratch("full");
    let (reference, want) = reference_run(&dir, 8);
    let out = dir.join("run");
    let limit = std::fs::metadata(journal(&reference)).unwrap().len() / 2;
    let err = fails(
        run(&out, 8).env("NAOFARM_FAULT_JOURNAL_FULL_AFTER", limit.to_string()),
        1,
    );
    assert!(err.contains("no space left"), "{err}");
    let check = succeed(naofarm().args(["journal", "check", "--json"]).arg(&out));
    let v: serde_json::Value = serde_json::from_slice(&check.stdout).unwrap();
    assert_eq!(v["tail"], "clean", "no partial frame left: {v}");
    assert!(
        v["decided"].as_u64().unwrap() < 8,
        "the run stopped part-way: {v}"
    );
    succeed(&mut run(&out, 8));
    assert_eq!(history(&out), want);
}

#[test]
fn extending_a_finished_run_gives_the_longer_runs_history() {
    let dir = scratch("extend");
    let long = dir.join("long");
    succeed(&mut run(&long, 80));
    let short = dir.join("short");
    succeed(&mut run(&short, 60));
    let out = succeed(&mut run(&short, 80));
    assert!(String::from_utf8_lossy(&out.stderr).contains("extending"));
    assert_eq!(history(&short), history(&long), "60 + 20 = 80, bit for bit");
    let check = succeed(naofarm().args(["journal", "check", "--json"]).arg(&short));
    let v: serde_json::Value = serde_json::from_slice(&check.stdout).unwrap();
    assert_eq!(v["extensions"], serde_json::json!([80]));
    assert_eq!(v["decided"], 80);
    // Shorter, or another seed: refused, naming each field; nothing written.
    let before = std::fs::read(journal(&short)).unwrap();
    let err = fails(&mut run(&short, 70), 2);
    assert!(
        err.contains("iterations") && err.contains("extended, not shortened"),
        "{err}"
    );
    let err = fails(run(&short, 80).args(["--seed", "9", "--model", "nao"]), 2);
    assert!(err.contains("seed") && err.contains("model"), "{err}");
    assert_eq!(std::fs::read(journal(&short)).unwrap(), before);
}

#[test]
fn from_a_run_with_other_parameters_or_from_no_run_is_refused_by_name() {
    let dir = scratch("from");
    let one = dir.join("physical");
    succeed(&mut run_synthetic(
        root().join("experiments/physical.toml"),
        &one,
        3,
    ));
    let err = fails(
        run_synthetic(
            root().join("experiments/physical-technical.toml"),
            dir.join("five"),
            2,
        )
        .arg("--from")
        .arg(&one),
        2,
    );
    assert!(
        err.contains("ThighRelHip2_Z") && err.contains("xlength_step_max"),
        "{err}"
    );
    assert!(!dir.join("five").join("journal.nfj").exists());
    // Same names, narrower bounds: only the points inside are used, and it says how many.
    let text = std::fs::read_to_string(root().join("experiments/physical.toml"))
        .unwrap()
        .replace("lower = -0.10", "lower = -0.05");
    let narrow = dir.join("narrow.toml");
    std::fs::write(&narrow, text).unwrap();
    let out = succeed(
        run_synthetic(&narrow, dir.join("narrow"), 2)
            .arg("--from")
            .arg(&one),
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("of its 3 points lie inside"));
    // Something that is no run: a file, a directory without a journal, nothing.
    let file = dir.join("notes.txt");
    std::fs::write(&file, "not a run").unwrap();
    let empty = dir.join("empty");
    std::fs::create_dir(&empty).unwrap();
    for (from, why) in [
        (&file, "is a file, not a run directory"),
        (&empty, "holds no journal.nfj"),
        (&dir.join("nowhere"), "does not exist"),
    ] {
        let out = dir.join("not-from");
        let err = fails(
            run_synthetic(root().join("experiments/physical.toml"), &out, 2)
                .arg("--from")
                .arg(from),
            2,
        );
        assert!(
            err.contains(&format!("--from {}: ", from.display())) && err.contains(why),
            "{err}"
        );
        assert!(!out.exists(), "{err}");
    }
    assert_eq!(std::fs::read(&file).unwrap(), b"not a run");
    assert_eq!(std::fs::read_dir(&empty).unwrap().count(), 0);
}

#[test]
fn absurd_numbers_are_usage_errors_never_panics() {
    let dir = scratch("numbers");
    for (flag, value) in [
        ("--lease-s", "1e20"),
        ("--lease-s", "1e300"),
        ("--lease-s", "1e-9"),
        ("--lease-s", "nan"),
        ("--lease-s", "-0"),
        ("--lease-s", "inf"),
        ("--seed", "18446744073709551616"),
        ("--iterations", "1e300"),
        ("--workers", "0"),
        ("--workers", "100000"),
    ] {
        let err = fails(
            naofarm()
                .arg("run")
                .arg(synthetic())
                .arg("--out")
                .arg(dir.join("r"))
                .args([flag, value]),
            2,
        );
        assert!(
            err.contains(flag.trim_start_matches("--")) || err.contains(value),
            "{flag} {value}: {err}"
        );
        assert!(!dir.join("r").join("journal.nfj").exists());
        if value == "1e300" && flag == "--lease-s" {
            // named in a line, not spelt out in 301 digits
            assert!(err.contains("--lease-s 1e300: must be in"), "{err}");
        }
    }
    for value in ["1e20", "0", "nan"] {
        fails(naofarm().args(["watch", "x", "--timeout-s", value]), 2);
    }
    // A tunable walk setting: refused by name with its range, before any
    // trial runs.
    for (kv, says) in [
        (
            "step_period=1e300",
            "`step_period` = 1e300 is outside its admissible range",
        ),
        (
            "double_support=nan",
            "--param `double_support=nan`: not a finite number",
        ),
    ] {
        let err = fails(naofarm().args(["trial", "--trials", "1", "--param", kv]), 2);
        assert!(err.contains(says), "{kv}: {err}");
    }
    for (field, value) in [("n_mcmc", "20000"), ("refresh_rate", "2.0")] {
        let text = std::fs::read_to_string(synthetic())
            .unwrap()
            .replace("[clop]", &format!("[clop]\n{field} = {value}"));
        let p = dir.join(format!("{field}.toml"));
        std::fs::write(&p, text).unwrap();
        let err = fails(naofarm().arg("check").arg(&p), 2);
        assert!(err.contains(field), "{err}");
    }
}

#[test]
fn a_trial_that_fails_on_every_worker_stops_the_run_with_the_reasons() {
    let dir = scratch("fails");
    let (_, want) = reference_run(&dir, 8);
    for (mode, says) in [
        ("fail", "fails"),
        ("panic", "panic: fault hook"),
        ("nan", "non-finite result"),
    ] {
        let out = dir.join(mode);
        let err = fails(
            run(&out, 8)
                .args(["--workers", "3"])
                .env("NAOFARM_FAULT_TRIAL", format!("{mode}@2/3")),
            1,
        );
        assert!(
            err.contains("trial 3 of iteration 2 failed 3 times on 3 distinct workers")
                && err.contains("ThighRelHip2_Z=")
                && err.matches(says).count() >= 3,
            "{mode}: {err}"
        );
        // A resumed run keeps the counts: it stops again at once, naming the trial…
        let again = fails(&mut run(&out, 8), 1);
        assert!(again.contains("trial 3 of iteration 2"), "{again}");
        // …unless it is allowed more workers; then the trial runs and the history is the run's.
        succeed(run(&out, 8).args(["--max-trial-failures", "4"]));
        assert_eq!(history(&out), want, "{mode}");
    }
}

/// The three commands that begin a run in `out`: `run`, `coordinator` and
/// `journal salvage` of `reference`. `run` and `coordinator` listen on
/// `held`, a port someone else holds: a refusal that waited for the network
/// would fail there instead (exit 1, "zenoh: …"), so what they say shows
/// they refused first.
fn starts(
    out: &Path,
    reference: &Path,
    held: &std::net::TcpListener,
) -> [std::process::Command; 3] {
    let ep = format!("tcp/127.0.0.1:{}", held.local_addr().unwrap().port());
    let mut coordinator = naofarm();
    coordinator
        .args(["coordinator", "--listen", &ep])
        .arg(synthetic())
        .arg("--out")
        .arg(out);
    let mut salvage = naofarm();
    salvage
        .args(["journal", "salvage"])
        .arg(reference)
        .arg("--out")
        .arg(out);
    let mut run = run(out, 3);
    run.args(["--listen", &ep]);
    [run, coordinator, salvage]
}

/// Every file of `dir` (not recursing) with its bytes, by name.
fn files_of(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap_or_default(),
            )
        })
        .collect();
    v.sort();
    v
}

/// A run begins only in a new or empty directory (or one where a start
/// failed before its journal, holding a coordinator's lock alone): `run`,
/// `coordinator` and `journal salvage` refuse a directory of someone's
/// files (exit 2, naming them; before they touch the network) and leave it
/// as it was, with no lock or
/// journal of theirs in it. A file of someone's named `lock` used to be
/// overwritten with the coordinator's pid.
#[test]
fn a_run_never_begins_among_someone_elses_files() {
    let dir = scratch("foreign");
    let (reference, want) = reference_run(&dir, 3);
    let held = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    for (name, text) in [
        ("notes.txt", "someone's notes"),
        ("lock", "my lock notes\n"),
    ] {
        let theirs = dir.join(format!("theirs-{name}"));
        std::fs::create_dir(&theirs).unwrap();
        std::fs::write(theirs.join(name), text).unwrap();
        let before = files_of(&theirs);
        for cmd in &mut starts(&theirs, &reference, &held) {
            let err = fails(cmd, 2);
            let named = if name == "lock" {
                "(lock, not a coordinator's)"
            } else {
                "(notes.txt)"
            };
            assert!(
                err.contains(&format!(
                    "{} holds files but no run {named}; a run begins in a new or empty directory",
                    theirs.display()
                )),
                "{err}"
            );
            assert_eq!(files_of(&theirs), before, "{cmd:?}");
        }
    }
    // A start that failed before its journal left a coordinator's lock
    // alone: the run begins there, and it is the run anywhere else.
    let failed = dir.join("failed");
    std::fs::create_dir(&failed).unwrap();
    std::fs::write(failed.join("lock"), "pid 12 on a host\n").unwrap();
    succeed(&mut run(&failed, 3));
    assert_eq!(history(&failed), want);
}

/// A new run is never made inside another run's directory, where removing
/// that run (say once `journal salvage` has copied it, which says it is
/// unchanged) would remove the new one with it: `run`, `coordinator` and
/// `journal salvage` refuse it (exit 2, naming the run), through `..` too,
/// before they touch the network, and make nothing there. A run already
/// inside one is resumed.
#[test]
fn a_new_run_is_never_made_inside_another_run() {
    let dir = scratch("nested");
    let (reference, want) = reference_run(&dir, 3);
    let held = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let before = files_of(&reference);
    let real = reference.canonicalize().unwrap();
    for inner in [
        reference.join("salvaged"),
        reference.join("a").join("b"),
        reference.join("a").join("..").join("c"),
    ] {
        for cmd in &mut starts(&inner, &reference, &held) {
            let err = fails(cmd, 2);
            assert!(
                err.contains(&format!(
                    "{} is inside the run directory {}; a new run goes beside another run",
                    inner.display(),
                    real.display()
                )),
                "{err}"
            );
            assert_eq!(files_of(&reference), before, "{cmd:?}");
        }
    }
    // Beside it, salvage makes the run; and a run that is inside another
    // already (a copy put there by hand) is resumed, as it is.
    let beside = dir.join("salvaged");
    succeed(
        naofarm()
            .args(["journal", "salvage"])
            .arg(&reference)
            .arg("--out")
            .arg(&beside),
    );
    assert_eq!(history(&beside), want);
    let copy = reference.join("copy");
    std::fs::create_dir(&copy).unwrap();
    std::fs::copy(journal(&beside), journal(&copy)).unwrap();
    succeed(&mut run(&copy, 3));
    assert_eq!(history(&copy), want);
}
