//! The web page, open during `bench fleet --web`: `naofarm web` serving it,
//! and a reader that does what the page does — it follows the feed and, as
//! the fleet changes, fetches a run's data and one of its figures (at most
//! once a second, as the page's figures redraw).

use std::{
    io::{BufRead, BufReader, Read, Write},
    net::TcpStream,
    process::{Command, Stdio},
    sync::{
        atomic::{AtomicBool, AtomicU64, Ordering},
        Arc,
    },
    time::{Duration, Instant},
};

use anyhow::{anyhow, Context};

use crate::crew::{Crew, Member};

/// What the page's server cost while the bench measured.
#[derive(Debug, serde::Serialize)]
pub struct PageRow {
    /// CPU of the page's server over the window, % of one core.
    pub cpu_percent: f64,
    /// Feed events the reader got.
    pub events: u64,
    /// Run data and figures it fetched.
    pub fetches: u64,
}

/// `naofarm web` and its reader.
pub struct Page {
    pid: u32,
    _member: Member,
    events: Arc<AtomicU64>,
    fetches: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
}

/// Linux's clock ticks per second for /proc's CPU times (USER_HZ, 100 on
/// every Linux ABI).
const TICKS_PER_S: f64 = 100.0;

impl Page {
    /// Starts `naofarm web` on the fleet at `ep` and a reader of its feed.
    pub fn open(exe: &std::path::Path, crew: &Crew, ep: &str) -> anyhow::Result<Self> {
        let mut member = crew.spawn(
            Command::new(exe)
                .args(["web", "--connect", ep, "--http", "127.0.0.1:0"])
                .env("RUST_LOG", "error")
                .stdout(Stdio::null())
                .stderr(Stdio::piped()),
        )?;
        let pid = crew.pid(&member).context("the web process")?;
        let err = member.stderr.take().context("web stderr")?;
        let mut lines = BufReader::new(err).lines();
        let addr = loop {
            let line = lines
                .next()
                .context("`naofarm web` ended without saying where it serves")??;
            if let Some(url) = line.strip_prefix("web page at http://") {
                break url.trim().trim_end_matches('/').to_string();
            }
        };
        std::thread::spawn(move || lines.for_each(drop));
        let (events, fetches, stop) = (
            Arc::new(AtomicU64::new(0)),
            Arc::new(AtomicU64::new(0)),
            Arc::new(AtomicBool::new(false)),
        );
        let (e, f, s) = (events.clone(), fetches.clone(), stop.clone());
        std::thread::spawn(move || {
            if let Err(err) = read_feed(&addr, &e, &f, &s) {
                eprintln!("the page's reader stopped: {err:#}");
            }
        });
        Ok(Self {
            pid,
            _member: member,
            events,
            fetches,
            stop,
        })
    }

    /// CPU seconds the page's server has used so far.
    pub fn cpu_s(&self) -> anyhow::Result<f64> {
        let stat = std::fs::read_to_string(format!("/proc/{}/stat", self.pid))?;
        // Fields after the command's closing parenthesis: utime is the 12th, stime the 13th.
        let rest = stat
            .rsplit_once(')')
            .map(|(_, r)| r)
            .context("/proc stat")?;
        let f: Vec<&str> = rest.split_whitespace().collect();
        let ticks = |i: usize| -> anyhow::Result<f64> {
            Ok(f.get(i).context("/proc stat field")?.parse::<f64>()?)
        };
        Ok((ticks(11)? + ticks(12)?) / TICKS_PER_S)
    }

    /// The page's row: `cpu_s` CPU seconds over `wall`.
    pub fn row(&self, cpu_s: f64, wall: Duration) -> PageRow {
        PageRow {
            cpu_percent: cpu_s / wall.as_secs_f64().max(1e-9) * 100.0,
            events: self.events.load(Ordering::Relaxed),
            fetches: self.fetches.load(Ordering::Relaxed),
        }
    }
}

impl Drop for Page {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// GET `path` from the page's server; the body.
fn get(addr: &str, path: &str) -> anyhow::Result<Vec<u8>> {
    let mut s = TcpStream::connect(addr)?;
    write!(s, "GET {path} HTTP/1.0\r\nHost: {addr}\r\n\r\n")?;
    let mut all = Vec::new();
    s.read_to_end(&mut all)?;
    let start = all
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .ok_or_else(|| anyhow!("{path}: no HTTP answer"))?;
    if !all.starts_with(b"HTTP/1.0 200") && !all.starts_with(b"HTTP/1.1 200") {
        return Err(anyhow!(
            "{path}: {}",
            String::from_utf8_lossy(&all[..start])
        ));
    }
    Ok(all[start + 4..].to_vec())
}

/// Follows the feed; on a change, at most once a second, fetches the first
/// run's data and its progress figure, as its open page would.
fn read_feed(
    addr: &str,
    events: &AtomicU64,
    fetches: &AtomicU64,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    let mut s = TcpStream::connect(addr)?;
    write!(
        s,
        "GET /events HTTP/1.1\r\nHost: {addr}\r\nAccept: text/event-stream\r\n\r\n"
    )?;
    let mut feed = BufReader::new(s);
    let mut line = String::new();
    let mut last = Instant::now() - Duration::from_secs(1);
    while !stop.load(Ordering::Relaxed) {
        line.clear();
        if feed.read_line(&mut line)? == 0 {
            return Ok(());
        }
        let Some(data) = line.strip_prefix("data: ") else {
            continue;
        };
        events.fetch_add(1, Ordering::Relaxed);
        if last.elapsed() < Duration::from_secs(1) {
            continue;
        }
        last = Instant::now();
        let v: serde_json::Value = serde_json::from_str(data).unwrap_or_default();
        if let Some(id) = v["runs"][0]["id"].as_str() {
            get(addr, &format!("/api/run/{id}"))?;
            get(addr, &format!("/api/run/{id}/figure/progress.svg"))?;
            fetches.fetch_add(2, Ordering::Relaxed);
        }
    }
    Ok(())
}
