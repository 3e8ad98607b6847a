//! The league's own server on the farm: programs/league/build.sh builds
//! SimSpark, rcssserver3d and UT Austin Villa's agent from the third-party
//! sources (into a cache outside the clone: a machine that keeps its files
//! builds once; without sources it fetches the pinned upstream ones and
//! checks them), and a farm run of the `league` program on the real server
//! is journaled, killed mid-run and resumed.
#![allow(clippy::unwrap_used)]

mod util;

use std::{
    path::{Path, PathBuf},
    process::Command,
    time::Duration,
};

use util::{naofarm, root, scratch, succeed};

/// The league build's trial program, building it if the cache lacks it.
/// The sources: `$NAOFARM_LEAGUE_SOURCE`, else ../shared/third-party.
fn league_program() -> PathBuf {
    util::set_up_program("league/build.sh", "NAOFARM_LEAGUE_SOURCE")
}

/// The league experiment cut to a test's size: 3 iterations of 4 walks of 4 s.
fn small_league(dir: &Path) -> PathBuf {
    util::small_experiment("league.toml", "iterations = 500", dir)
}

fn run(exp: &Path, out: &Path, program: &Path) -> Command {
    util::program_run(exp, out, "league", program)
}

/// Every live (not zombie) process: (pid, parent pid, name).
fn processes() -> Vec<(u32, u32, String)> {
    let mut found = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Ok(pid) = e.file_name().to_string_lossy().parse::<u32>() else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(e.path().join("stat")) else {
            continue;
        };
        // pid (comm) state ppid ...: the name may hold spaces, not `)`.
        let Some((head, rest)) = stat.rsplit_once(')') else {
            continue;
        };
        let name = head.split_once('(').map_or("", |(_, n)| n).to_string();
        let mut fields = rest.split_whitespace();
        let state = fields.next().unwrap_or("");
        let ppid = fields.next().and_then(|p| p.parse().ok()).unwrap_or(0);
        if state != "Z" {
            found.push((pid, ppid, name));
        }
    }
    found
}

/// The processes descended from `root` (not itself).
fn descendants(root: u32) -> Vec<(u32, String)> {
    let all = processes();
    let mut tree = vec![root];
    let mut found = Vec::new();
    while let Some(p) = tree.pop() {
        for (pid, ppid, name) in &all {
            if *ppid == p {
                tree.push(*pid);
                found.push((*pid, name.clone()));
            }
        }
    }
    found
}

/// The local addresses (as /proc/net/tcp writes them) of the TCP sockets
/// process `pid` listens on.
fn listeners_of(pid: u32) -> Vec<String> {
    let mut inodes = std::collections::BTreeSet::new();
    if let Ok(fds) = std::fs::read_dir(format!("/proc/{pid}/fd")) {
        for fd in fds.flatten() {
            if let Ok(link) = std::fs::read_link(fd.path()) {
                let link = link.to_string_lossy().into_owned();
                if let Some(i) = link
                    .strip_prefix("socket:[")
                    .and_then(|l| l.strip_suffix(']'))
                {
                    inodes.insert(i.to_string());
                }
            }
        }
    }
    let mut found = Vec::new();
    for table in ["/proc/net/tcp", "/proc/net/tcp6"] {
        let text = std::fs::read_to_string(table).unwrap_or_default();
        for line in text.lines().skip(1) {
            let f: Vec<&str> = line.split_whitespace().collect();
            if f.len() > 9 && f[3] == "0A" && inodes.contains(f[9]) {
                found.push(f[1].to_string());
            }
        }
    }
    found
}

/// A league run on the real server with 2 workers, killed (SIGKILL) with
/// trials in flight and resumed: nothing of the killed run left running,
/// every trial journaled once, and the history one worker alone decides.
#[test]
fn a_league_run_killed_and_resumed_decides_what_one_worker_alone_decides() {
    let program = league_program();
    let dir = scratch("league");
    let exp = small_league(&dir);
    let out = dir.join("run");

    // The first run: killed (SIGKILL) once it has decided an iteration.
    let (mut first, stats) = util::until_first_decision(&mut run(&exp, &out, &program));
    // Its trials in flight: the programs, their servers and agents (the
    // pipeline keeps trials going; wait until a server runs).
    let pid = first.id();
    let in_flight = util::wait_for(
        "a server among the run's trials",
        Duration::from_secs(60),
        || {
            let d = descendants(pid);
            d.iter().any(|(_, n)| n == "rcssserver3d").then_some(d)
        },
    );
    // The server listens on loopback only.
    let servers: Vec<u32> = in_flight
        .iter()
        .filter(|(_, n)| n == "rcssserver3d")
        .map(|(p, _)| *p)
        .collect();
    let listens = util::wait_for("the server's listeners", Duration::from_secs(30), || {
        let l: Vec<String> = servers.iter().flat_map(|p| listeners_of(*p)).collect();
        (l.len() >= 2).then_some(l)
    });
    assert!(
        listens.iter().all(|a| a.starts_with("0100007F:")),
        "the server listens beyond loopback: {listens:?}"
    );
    first.kill().unwrap();
    first.wait().unwrap();
    // The expert (UT's type-0 walk on the NAO's body) walks, on the real server.
    assert_eq!(stats["s"], 1.0, "{stats}");
    assert!(stats["mx"].as_f64().unwrap() > 1.0, "{stats}");
    // The killed run's programs, servers and agents do not outlive it.
    util::wait_for(
        &format!("the killed run's trials {in_flight:?} to end"),
        Duration::from_secs(20),
        || {
            let live: Vec<u32> = processes().iter().map(|(p, _, _)| *p).collect();
            in_flight
                .iter()
                .all(|(p, _)| !live.contains(p))
                .then_some(())
        },
    );

    // Resumed: the same directory, the same command.
    succeed(&mut run(&exp, &out, &program));
    let trials = util::journaled_once(&out);
    assert_eq!(
        trials.len(),
        3 * 4,
        "every trial of the 3 iterations journaled once"
    );
    let check = succeed(naofarm().args(["journal", "check", "--json"]).arg(&out));
    let v: serde_json::Value = serde_json::from_slice(&check.stdout).unwrap();
    assert_eq!(v["decided"], 3);
    // The first decision is the journal's, unchanged by the resume.
    let history = succeed(naofarm().args(["history", "--json"]).arg(&out));
    let rows: serde_json::Value = serde_json::from_slice(&history.stdout).unwrap();
    assert_eq!(rows.as_array().unwrap().len(), 3);
    for k in ["s", "mx", "my"] {
        assert_eq!(rows[0][k], stats[k], "{k} of iteration 0");
    }

    // A league trial is a function of the trial: the same experiment run
    // uninterrupted by one worker decides the same history, bit for bit.
    let alone = dir.join("alone");
    succeed(
        naofarm()
            .args(["run", "--json", "--workers", "1"])
            .arg(&exp)
            .arg("--out")
            .arg(&alone)
            .arg("--program")
            .arg(format!("league={}", program.display())),
    );
    let history_alone = succeed(naofarm().args(["history", "--json"]).arg(&alone));
    assert_eq!(
        String::from_utf8_lossy(&history.stdout),
        String::from_utf8_lossy(&history_alone.stdout),
        "killed and resumed on 2 workers against 1 worker alone"
    );
}

/// A web server on loopback (python's http.server) serving `dir`; killed
/// when dropped.
struct Mirror {
    child: std::process::Child,
    url: String,
}

impl Mirror {
    fn serve(dir: &Path) -> Self {
        let mut child = Command::new("python3")
            .args([
                "-u",
                "-m",
                "http.server",
                "0",
                "--bind",
                "127.0.0.1",
                "--directory",
            ])
            .arg(dir)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let mut line = String::new();
        std::io::BufRead::read_line(
            &mut std::io::BufReader::new(child.stdout.take().unwrap()),
            &mut line,
        )
        .unwrap();
        // "Serving HTTP on 127.0.0.1 port 40123 (http://127.0.0.1:40123/) ..."
        let port = line
            .split_whitespace()
            .skip_while(|w| *w != "port")
            .nth(1)
            .unwrap_or_else(|| panic!("no port in {line:?}"));
        Self {
            child,
            url: format!("http://127.0.0.1:{port}"),
        }
    }
}

impl Drop for Mirror {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The pinned sources as build.sh names them and fetches them from a mirror.
const UPSTREAM: [(&str, &str); 2] = [
    (
        "simspark-0.3.2-rcssserver3d-0.7.3.tar.gz",
        "zzufootball/SIMSPARK/archive/f6934a6.tar.gz",
    ),
    (
        "utaustinvilla3d.tar.gz",
        "LARG/utaustinvilla3d/archive/dbb2fb3.tar.gz",
    ),
];

/// build.sh without SOURCE, in `cache`, fetching from `mirror`.
fn build_fetching(cache: &Path, mirror: &str) -> std::process::Output {
    Command::new(root().join("programs/league/build.sh"))
        .env("NAOFARM_LEAGUE_CACHE", cache)
        .env("NAOFARM_LEAGUE_MIRROR", mirror)
        .output()
        .unwrap()
}

/// Without SOURCE, build.sh fetches the pinned upstream sources (here from
/// a mirror on loopback serving the third-party ones), checks their files'
/// sha256 and builds from them — here it finds the build of the same
/// sources, as a machine that built them keeps it. Fetched once, they serve
/// offline. A mirror serving other sources is refused before anything is
/// built, and what it served is not kept.
#[test]
fn without_sources_the_build_fetches_the_pinned_ones_and_refuses_others() {
    let program = league_program();
    let built = program.parent().unwrap().parent().unwrap();
    let key = built.file_name().unwrap();
    let source = util::third_party("NAOFARM_LEAGUE_SOURCE");
    let dir = scratch("league-fetch");
    let site = dir.join("site");
    for (file, path) in UPSTREAM {
        let to = site.join(path);
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::copy(source.join(file), to).unwrap();
    }
    let cache = dir.join("cache");
    std::fs::create_dir_all(&cache).unwrap();
    std::os::unix::fs::symlink(built, cache.join(key)).unwrap();

    let mirror = Mirror::serve(&site);
    let out = build_fetching(&cache, &mirror.url);
    let (said, err) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "{said}{err}");
    assert_eq!(said.matches("fetching").count(), 2, "{said}");
    assert_eq!(
        PathBuf::from(said.lines().last().unwrap()),
        cache.join(key).join("bin/league-trial"),
        "{said}"
    );
    drop(mirror);
    let offline = build_fetching(&cache, "http://127.0.0.1:9");
    let said = String::from_utf8_lossy(&offline.stdout);
    assert!(offline.status.success(), "{said}");
    assert!(!said.contains("fetching"), "{said}");

    // Another UT tree where the pinned one should be.
    let other = dir.join("other/utaustinvilla3d");
    std::fs::create_dir_all(&other).unwrap();
    std::fs::write(other.join("README.md"), "not UT's code\n").unwrap();
    succeed(
        Command::new("tar")
            .arg("-czf")
            .arg(site.join(UPSTREAM[1].1))
            .arg("-C")
            .arg(dir.join("other"))
            .arg("utaustinvilla3d"),
    );
    let mirror = Mirror::serve(&site);
    let cache = dir.join("cache-2");
    let out = build_fetching(&cache, &mirror.url);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains(&format!(
            "{}/{} is not the pinned source",
            mirror.url, UPSTREAM[1].1
        )),
        "{err}"
    );
    let kept: Vec<_> = std::fs::read_dir(cache.join("sources"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(kept, [UPSTREAM[0].0], "only the pinned source is kept");
    assert!(
        !std::fs::read_dir(&cache)
            .unwrap()
            .flatten()
            .any(|e| e.file_name().to_string_lossy().starts_with(".work")),
        "nothing was built"
    );
}

/// The same trials of the league program, each on a fresh server (cold)
/// and one after another on one kept server (`league-trial --serve`, as a
/// worker keeps it): their measurements.
fn cold_and_kept(
    program: &Path,
    trials: &[serde_json::Value],
) -> (Vec<serde_json::Value>, Vec<serde_json::Value>) {
    let dir = scratch("league-kept");
    let doc = |t: &serde_json::Value| {
        let mut t = t.clone();
        t["scratch"] = serde_json::json!(dir.to_path_buf());
        t.to_string()
    };
    let measured = |line: &str| -> serde_json::Value {
        let m: serde_json::Value = serde_json::from_str(line).unwrap();
        assert_eq!(m["fell"], false, "{m}");
        m
    };
    let fed = |args: &[&str], input: String| {
        let mut child = Command::new(program)
            .args(args)
            .current_dir(&*dir)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        std::io::Write::write_all(&mut child.stdin.take().unwrap(), input.as_bytes()).unwrap();
        let out = child.wait_with_output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8(out.stdout).unwrap()
    };
    let cold = trials
        .iter()
        .map(|t| measured(fed(&[], doc(t)).lines().last().unwrap()))
        .collect();
    let lines: String = trials.iter().map(|t| doc(t) + "\n").collect();
    let kept = fed(&["--serve"], lines).lines().map(measured).collect();
    (cold, kept)
}

/// A league trial is a function of the trial alone: the same trial walks
/// the same walk (to the server's centimetre) on a fresh server and on a
/// kept one, whatever walked on it before; the body is the trial's.
#[test]
fn a_kept_league_server_walks_the_trials_a_fresh_one_walks() {
    let program = league_program();
    let trial = |thigh: f64, step: f64, seed: u64| {
        serde_json::json!({
            "run": "r", "iteration": 0, "trial": 0, "seed": seed, "duration_s": 10.0,
            "robot_type": 0, "slot": 0,
            "params": {"ThighRelHip2_Z": thigh, "utwalk_max_step_size_x": step},
        })
    };
    // A longer thigh with longer steps (a walk that tells small
    // differences apart), the expert, the longer thigh again and with
    // another seed.
    let trials = [
        trial(-0.05, 115.0, 1),
        trial(-0.04, 97.34, 1),
        trial(-0.05, 115.0, 1),
        trial(-0.05, 115.0, 2),
    ];
    let (cold, kept) = cold_and_kept(&program, &trials);
    assert_eq!(cold, kept, "fresh servers against a kept one");
    assert_eq!(cold[0], cold[2], "one trial twice");
    assert_ne!(
        cold[0]["x_m"], cold[1]["x_m"],
        "the body and walk are the trial's: {cold:?}"
    );
}
