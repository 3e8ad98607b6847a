//! The league's own server on the farm: programs/league/build.sh builds
//! SimSpark, rcssserver3d and UT Austin Villa's agent from the third-party
//! sources (into a cache outside the clone: a machine that keeps its files
//! builds once), and a farm run of the `league` program on the real server
//! is journaled, killed mid-run and resumed.
#![allow(clippy::unwrap_used)]

mod util;

use std::{
    path::{Path, PathBuf},
    process::Command,
    time::Duration,
};

use util::{naofarm, scratch, succeed};

/// The league build's trial program, building it if the cache lacks it.
/// The sources: `$NAOFARM_LEAGUE_SOURCE`, else ../shared/third-party.
fn league_program() -> PathBuf {
    util::set_up_program("league/build.sh", "NAOFARM_LEAGUE_SOURCE")
}

/// The league experiment cut to a test's size: 3 iterations of 4 walks of 4 s.
fn small_league(dir: &Path) -> PathBuf {
    util::small_experiment("league.toml", "iterations = 150", dir)
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

#[test]
fn a_league_run_on_the_real_server_is_journaled_killed_and_resumed() {
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
}
