//! `naofarm clop`: CLOP tuning a real noisy program, its log and resume.
#![allow(clippy::unwrap_used)]

mod util;

use std::path::{Path, PathBuf};

use util::{naofarm, scratch, succeed};

/// A noisy evaluator speaking lines: wins most often near x = 0.3.
const EVALUATOR: &str = r#"#!/bin/sh
while read g s x; do
  awk -v s="$s" -v x="$x" 'BEGIN { srand(s % 1000003); p = 1 / (1 + exp(30 * (x - 0.3)^2 - 1)); if (rand() < p) print "W"; else print "L" }'
done
"#;

fn script(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    let ok = std::process::Command::new("chmod")
        .arg("+x")
        .arg(&p)
        .status()
        .unwrap();
    assert!(ok.success());
    p
}

fn tune(evaluator: &Path, budget: u64, log: Option<&Path>) -> std::process::Output {
    let mut c = clop_cmd(evaluator, budget);
    if let Some(l) = log {
        c.arg("--log").arg(l);
    }
    c.output().unwrap()
}

#[test]
fn clop_tunes_a_noisy_program_and_resumes_from_its_log() {
    let dir = scratch("clop-tune");
    let ev = script(&dir, "ev.sh", EVALUATOR);
    let straight = succeed(&mut clop_cmd(&ev, 300)).stdout;
    let v: serde_json::Value = serde_json::from_slice(&straight).unwrap();
    let x = v["mean"]["x"].as_f64().unwrap();
    assert!((0.15..0.45).contains(&x), "mean {x} far from 0.3: {v}");
    assert!(v["max"]["x"].as_f64().is_some());
    let games =
        v["wins"].as_u64().unwrap() + v["draws"].as_u64().unwrap() + v["losses"].as_u64().unwrap();
    assert_eq!(games, 300);

    // Stopped at 120 games, resumed to 300 from the log: the same answer, bit for bit.
    let log = dir.join("games.log");
    assert!(tune(&ev, 120, Some(&log)).status.success());
    let resumed = tune(&ev, 300, Some(&log));
    assert!(resumed.status.success());
    assert_eq!(resumed.stdout, straight);
    let lines = std::fs::read_to_string(&log).unwrap().lines().count();
    assert_eq!(lines, 301, "a header and one line per game");

    // A log of other parameters is refused.
    let other = naofarm()
        .args([
            "clop",
            "--param",
            "y:linear:0:2",
            "--budget",
            "10",
            "--evaluator",
        ])
        .arg(&ev)
        .arg("--log")
        .arg(&log)
        .output()
        .unwrap();
    assert_eq!(other.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&other.stderr).contains("other parameters"));
}

fn clop_cmd(ev: &Path, budget: u64) -> std::process::Command {
    let mut c = naofarm();
    c.args(["clop", "--param", "x:linear:0:1", "--seed", "3", "--json"])
        .args(["--budget", &budget.to_string()])
        .arg("--evaluator")
        .arg(ev);
    c
}

#[test]
fn clop_runs_a_classic_script_per_game() {
    let dir = scratch("clop-script");
    // CLOP's contract: <processor> <seed> <name> <value> …; the last line decides.
    let sc = script(
        &dir,
        "game.sh",
        "#!/bin/sh\necho \"processor $1 seed $2\"\n[ \"$3\" = x ] && [ \"$5\" = n ] || { echo bad-arguments; exit 1; }\n\
         awk -v v=\"$4\" 'BEGIN { print (v < 0.5) ? \"W\" : \"L\" }'\n",
    );
    let out = succeed(
        naofarm()
            .args([
                "clop",
                "--param",
                "x:linear:0:1",
                "--param",
                "n:integer:1:4",
            ])
            .args(["--budget", "40", "--json", "--script"])
            .arg(&sc),
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        v["wins"].as_u64().unwrap() + v["losses"].as_u64().unwrap(),
        40
    );
    let n = v["mean"]["n"].as_f64().unwrap();
    assert!(n.fract() == 0.0 && (1.0..=4.0).contains(&n), "{v}");
}

#[test]
fn a_failing_evaluator_is_a_clear_error_and_its_games_stay_in_the_log() {
    let dir = scratch("clop-bad");
    let cases = [
        (
            "wrong.sh",
            "#!/bin/sh\ni=0\nwhile read l; do i=$((i+1)); if [ $i -le 5 ]; then echo W; else echo maybe; fi; done\n",
            "answered `maybe` to game 5",
            5,
        ),
        (
            "dies.sh",
            "#!/bin/sh\nread l; echo L; read l; echo W; read l; exit 3\n",
            "the evaluator exited (exit status: 3) without answering game 2",
            2,
        ),
        ("hangs.sh", "#!/bin/sh\nread l; echo W; read l; sleep 60\n", "within 1 s", 1),
    ];
    for (name, text, message, kept) in cases {
        let ev = script(&dir, name, text);
        let log = dir.join(format!("{name}.log"));
        let out = naofarm()
            .args([
                "clop",
                "--param",
                "x:linear:0:1",
                "--budget",
                "50",
                "--timeout-s",
                "1",
            ])
            .arg("--evaluator")
            .arg(&ev)
            .arg("--log")
            .arg(&log)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(1), "{name}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(message), "{name}: {err}");
        // The error alone: no noise from ending an evaluator already gone.
        assert_eq!(err.trim().lines().count(), 1, "{name}: {err}");
        let lines = std::fs::read_to_string(&log).unwrap().lines().count();
        assert_eq!(lines, 1 + kept, "{name}: the games played are kept");
    }
    let bad = naofarm()
        .args([
            "clop",
            "--param",
            "x:cubic:0:1",
            "--budget",
            "5",
            "--evaluator",
            "true",
        ])
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("unknown kind `cubic`"));
}
