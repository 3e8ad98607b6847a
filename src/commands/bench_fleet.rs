//! `naofarm bench fleet`: R runs × W worker processes × S slots through one
//! `naofarm router` on loopback, synthetic trials of a fixed wall time. It
//! prints the fleet's utilisation, trials/s, each run's share against its
//! priority, the coordinators' CPU per trial (their own CPU clocks) and the
//! dispatch latency (ready → handed to a worker).
//!
//! The shares and the utilisation are measured while every run still has
//! trials ready: from when the last coordinator started (plus a warm-up of
//! two trial times) until the first run finishes.

use std::{
    io::{BufRead, BufReader},
    process::{Command, Stdio},
    sync::{mpsc, Arc, Mutex},
    time::{Duration, Instant},
};

use anyhow::{anyhow, Context};
use zenoh::Wait;

mod page;

use crate::{
    args::FleetBenchArgs,
    common::{flag_in, Failure},
    crew::Crew,
};

fn experiment(i: usize, a: &FleetBenchArgs) -> String {
    format!(
        "name = \"fleet-{i}\"\nseed = {}\niterations = {}\ntrials_per_iteration = {}\n\
         pipeline_depth = {}\nmodel = \"synthetic\"\nstart = \"expert\"\n\n\
         [[parameter]]\nname = \"ThighRelHip2_Z\"\nlower = -0.08\nupper = -0.03\nexpert = -0.04\n\n\
         [[parameter]]\nname = \"xlength_step_max\"\nlower = 0.02\nupper = 0.15\nexpert = 0.08\n\n\
         [clop]\nn_mcmc = 100\n",
        i + 1,
        a.iterations,
        a.trials,
        a.depth
    )
}

/// Starts `naofarm router` on a free loopback port; its endpoint as it reports it.
fn router(exe: &std::path::Path, crew: &Crew) -> anyhow::Result<String> {
    let mut router = crew.spawn(
        Command::new(exe)
            .args(["router", "--listen", "tcp/127.0.0.1:0"])
            .stdout(Stdio::null())
            .stderr(Stdio::piped()),
    )?;
    let err = router.stderr.take().context("router stderr")?;
    let mut lines = BufReader::new(err).lines();
    for line in lines.by_ref() {
        let line = line?;
        if let Some(ep) = line.strip_prefix("router listening on ") {
            // Keep draining its stderr, so that it never blocks on a full pipe.
            std::thread::spawn(move || lines.for_each(drop));
            return Ok(ep.trim().to_string());
        }
    }
    Err(anyhow!("the router ended without saying where it listens"))
}

/// One received trial outcome: when, which run, how long it ran.
type Seen = (Instant, String, f64);
/// One advert: when, which run, how many trials it had ready (0 unless running).
type Ad = (Instant, String, u32);

/// Weighted max-min fair shares of `capacity` slots: run `i` (weight
/// `weights[i]`) wants `demand[i]` slots (`None`: as many as it gets, it has
/// trials ready). Each gets `min(demand, λ·weight)` with λ chosen so the
/// slots are used up, or its whole demand when all demands fit.
fn fair_shares(capacity: f64, weights: &[f64], demand: &[Option<f64>]) -> Vec<f64> {
    let mut share = vec![0.0; weights.len()];
    let mut open: Vec<usize> = (0..weights.len()).collect();
    let mut left = capacity;
    // Water-filling: settle every run whose demand lies under its weighted
    // share of what is left, then split the rest among the others.
    loop {
        let w: f64 = open.iter().map(|&i| weights[i]).sum();
        if open.is_empty() || w <= 0.0 || left <= 0.0 {
            return share;
        }
        let lambda = left / w;
        let (capped, rest): (Vec<usize>, Vec<usize>) = open
            .iter()
            .partition(|&&i| demand[i].is_some_and(|d| d <= lambda * weights[i]));
        if capped.is_empty() {
            for &i in &rest {
                share[i] = lambda * weights[i];
            }
            return share;
        }
        for &i in &capped {
            let d = demand[i].unwrap_or(0.0);
            share[i] = d;
            left -= d;
        }
        open = rest;
    }
}

/// Each run's fair slot-seconds over `[from, to)`, sampled every `step`: at
/// each instant a run wants what it runs plus what it has ready (its last
/// advert, at most a second old), and the fleet's slots are shared by weight
/// among those wants (what a run cannot use goes to the others, by design).
#[allow(clippy::too_many_arguments)]
fn fair_slot_seconds(
    ids: &[String],
    weights: &[f64],
    capacity: f64,
    seen: &[Seen],
    ads: &[Ad],
    from: Instant,
    to: Instant,
    step: Duration,
) -> Vec<f64> {
    let mut fair = vec![0.0; ids.len()];
    let mut t = from;
    while t < to {
        let demand: Vec<Option<f64>> = ids
            .iter()
            .map(|id| {
                let ready = ads
                    .iter()
                    .rfind(|(at, r, _)| r == id && *at <= t)
                    .map_or(0, |(_, _, ready)| *ready);
                let running = seen
                    .iter()
                    .filter(|(end, r, w)| {
                        r == id
                            && *end > t
                            && end
                                .checked_sub(Duration::from_secs_f64(w.max(0.0)))
                                .is_some_and(|start| start <= t)
                    })
                    .count();
                #[allow(clippy::cast_precision_loss)]
                Some(running as f64 + f64::from(ready))
            })
            .collect();
        for (f, s) in fair.iter_mut().zip(fair_shares(capacity, weights, &demand)) {
            *f += s * step.as_secs_f64();
        }
        t += step;
    }
    fair
}

#[derive(Debug, serde::Serialize)]
struct RunRow {
    name: String,
    priority: u32,
    share: f64,
    priority_share: f64,
    fair_share: f64,
    trials: u64,
    cpu_s: f64,
    dispatch_ms_p50: Option<f64>,
    dispatch_ms_p99: Option<f64>,
}

#[derive(Debug, serde::Serialize)]
struct Report {
    runs: usize,
    workers: u32,
    slots: u32,
    trial_ms: u64,
    window_s: f64,
    utilisation: f64,
    trials_per_s: f64,
    coordinator_cpu_ms_per_trial: f64,
    work_requests_per_trial: f64,
    adverts_per_trial: f64,
    empty_grants_per_trial: f64,
    service_cpu_ms_per_trial: f64,
    run_cpu_ms_per_decision: f64,
    decide_ms_per_decision: f64,
    dispatch_ms_p50: f64,
    dispatch_ms_p99: f64,
    worst_share_error: f64,
    worst_fair_share_error: f64,
    per_run: Vec<RunRow>,
    /// The web page's server, when the page was open.
    page: Option<page::PageRow>,
}

/// `naofarm bench fleet`.
#[allow(clippy::too_many_lines, clippy::cast_precision_loss)]
pub fn fleet(a: &FleetBenchArgs) -> Result<(), Failure> {
    // The experiment file's bounds for what the runs' files take.
    flag_in("--runs", a.runs, 1..=200)?;
    flag_in("--workers", a.workers, 1..=1000)?;
    flag_in("--slots", a.slots, 1..=256)?;
    flag_in("--trial-ms", a.trial_ms, 1..=60_000)?;
    flag_in("--iterations", a.iterations, 1..=10_000_000)?;
    flag_in("--trials", a.trials, 1..=10_000)?;
    flag_in("--depth", a.depth, 1..=1000)?;
    if a.priorities.is_empty() {
        return Err(Failure::Usage(anyhow!("--priorities: give at least one")));
    }
    for &p in &a.priorities {
        flag_in("--priorities", p, 1..=1000)?;
    }
    let mut reports = Vec::new();
    for page in if a.web {
        vec![false, true]
    } else {
        vec![false]
    } {
        reports.push(run(a, page).map_err(Failure::Job)?);
    }
    show(a, &reports).map_err(Failure::Job)
}

#[allow(clippy::too_many_lines, clippy::cast_precision_loss)]
fn run(a: &FleetBenchArgs, open_page: bool) -> anyhow::Result<Report> {
    let exe = std::env::current_exe()?;
    let base = a.dir.clone().unwrap_or_else(|| {
        let shm = std::path::Path::new("/dev/shm");
        if shm.is_dir() {
            shm.to_path_buf()
        } else {
            std::env::temp_dir()
        }
    });
    // Every process and file of the bench goes with it, however it ends.
    let crew = Crew::new();
    let dir = crew
        .scratch(&base, "naofarm-bench-fleet-")
        .with_context(|| format!("a scratch directory in {}", base.display()))?;
    eprintln!("journals in {}", dir.display());
    let ep = router(&exe, &crew)?;
    eprintln!(
        "router on {ep}; starting {} workers × {} slots…",
        a.workers, a.slots
    );
    for _ in 0..a.workers {
        crew.spawn(
            Command::new(&exe)
                .args(["worker", "--connect", &ep, "--slots", &a.slots.to_string()])
                .args(["--min-trial-ms", &a.trial_ms.to_string()])
                .args(["--heartbeat-ms", "1000", "--models", "synthetic"])
                .env("RUST_LOG", "error")
                .stdout(Stdio::null())
                .stderr(Stdio::null()),
        )?;
    }
    // Every trial outcome the coordinators publish, timestamped here.
    let mut zcfg = zenoh::Config::default();
    for (k, v) in [
        ("mode", "\"client\"".to_string()),
        ("scouting/multicast/enabled", "false".to_string()),
        ("connect/endpoints", format!("[\"{ep}\"]")),
        ("connect/timeout_ms", "-1".to_string()),
        ("connect/exit_on_failure", "false".to_string()),
    ] {
        zcfg.insert_json5(k, &v).map_err(|e| anyhow!("{e}"))?;
    }
    let session = zenoh::open(zcfg)
        .wait()
        .map_err(|e| anyhow!("zenoh: {e}"))?;
    let seen: Arc<Mutex<Vec<Seen>>> = Arc::new(Mutex::new(Vec::new()));
    let sink = seen.clone();
    let _sub = session
        .declare_subscriber("naofarm/*/*/trials/**")
        .callback(move |s| {
            let v: serde_json::Value =
                serde_json::from_slice(&s.payload().to_bytes()).unwrap_or_default();
            if let (Some(run), Some(w)) = (v["run"].as_str(), v["wall_time_s"].as_f64()) {
                if let Ok(mut g) = sink.lock() {
                    g.push((Instant::now(), run.to_string(), w));
                }
            }
        })
        .wait()
        .map_err(|e| anyhow!("zenoh: {e}"))?;

    // Every advert (has the run trials ready?), timestamped here.
    let ads: Arc<Mutex<Vec<Ad>>> = Arc::new(Mutex::new(Vec::new()));
    let ad_sink = ads.clone();
    let _ad_sub = session
        .declare_subscriber(protocol::keys::adverts_all("naofarm"))
        .callback(move |s| {
            use protocol::wire::WireMessage as _;
            if let Ok(ad) = protocol::wire::RunAdvert::decode(&s.payload().to_bytes()) {
                let ready = if ad.state == protocol::wire::RunState::Running {
                    ad.ready
                } else {
                    0
                };
                if let Ok(mut g) = ad_sink.lock() {
                    g.push((Instant::now(), ad.id, ready));
                }
            }
        })
        .wait()
        .map_err(|e| anyhow!("zenoh: {e}"))?;

    let page = if open_page {
        Some(page::Page::open(&exe, &crew, &ep)?)
    } else {
        None
    };
    let mut coords = Vec::new();
    let (tx, rx) = mpsc::channel::<(usize, serde_json::Value)>();
    for i in 0..a.runs {
        let exp = dir.join(format!("fleet-{i}.toml"));
        std::fs::write(&exp, experiment(i, a))?;
        let priority = a.priorities[i % a.priorities.len()];
        let mut cmd = Command::new(&exe);
        if let Ok(v) = std::env::var("NAOFARM_BENCH_COORD_ZRT") {
            cmd.env("ZENOH_RUNTIME", v);
        }
        let mut child = crew.spawn(
            cmd.arg("coordinator")
                .arg(&exp)
                .arg("--out")
                .arg(dir.join(format!("run-{i}")))
                .args([
                    "--connect",
                    &ep,
                    "--json",
                    "--priority",
                    &priority.to_string(),
                ])
                .env("RUST_LOG", "error")
                .stdout(Stdio::piped())
                .stderr(Stdio::null()),
        )?;
        let out = child.stdout.take().context("coordinator stdout")?;
        let tx = tx.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                if let Ok(v) = serde_json::from_str::<serde_json::Value>(&line) {
                    if v["event"] == "finished" {
                        let _ = tx.send((i, v));
                    }
                }
            }
        });
        coords.push((child, priority));
        if a.stagger_ms > 0 && i + 1 < a.runs {
            std::thread::sleep(Duration::from_millis(a.stagger_ms));
        }
    }
    let started = Instant::now();
    let page_from = page.as_ref().map(page::Page::cpu_s).transpose()?;
    let mut page_to = None;
    drop(tx);
    eprintln!("{} runs started; waiting for them to finish…", a.runs);
    let mut finished: Vec<Option<serde_json::Value>> = vec![None; a.runs];
    let mut first_done = None;
    let deadline = started + Duration::from_secs(a.timeout_s);
    while finished.iter().any(Option::is_none) {
        let left = deadline.saturating_duration_since(Instant::now());
        match rx.recv_timeout(left) {
            Ok((i, v)) => {
                if first_done.is_none() {
                    first_done = Some(Instant::now());
                    page_to = page.as_ref().map(page::Page::cpu_s).transpose()?;
                }
                finished[i] = Some(v);
            }
            Err(mpsc::RecvTimeoutError::Timeout) => {
                return Err(anyhow!(
                    "the runs did not finish within {} s (--timeout-s)",
                    a.timeout_s
                ))
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                return Err(anyhow!(
                    "a coordinator ended before its run finished (run {} of {})",
                    finished.iter().position(Option::is_none).unwrap_or(0) + 1,
                    a.runs
                ))
            }
        }
    }
    for (c, _) in &coords {
        crew.wait(c)?;
    }
    let page_row = match (&page, page_from, page_to, first_done) {
        (Some(p), Some(a), Some(b), Some(done)) => {
            Some(p.row(b - a, done.saturating_duration_since(started)))
        }
        _ => None,
    };
    drop(page);
    drop(crew);
    let _ = session.close().wait();
    let from = started + Duration::from_millis(2 * a.trial_ms);
    let to = first_done.unwrap_or_else(Instant::now);
    let window = to.saturating_duration_since(from).as_secs_f64();
    if window <= 0.0 {
        return Err(anyhow!(
            "a run finished before the warm-up ended: give more --iterations"
        ));
    }
    let seen = seen.lock().map_err(|_| anyhow!("poisoned"))?.clone();
    let ids: Vec<String> = finished
        .iter()
        .map(|f| {
            f.as_ref()
                .and_then(|v| v["status"]["id"].as_str())
                .unwrap_or_default()
                .to_string()
        })
        .collect();
    let in_window: Vec<&Seen> = seen
        .iter()
        .filter(|(t, _, _)| *t >= from && *t < to)
        .collect();
    // Busy slot-seconds inside the window: each trial's [end − its wall time,
    // end] clipped to it (a trial still running at the window's end is seen
    // only when it ends, at most one trial time later).
    let overlap = |(end, _, w): &Seen| -> f64 {
        let start = end
            .checked_sub(Duration::from_secs_f64(w.max(0.0)))
            .unwrap_or(*end);
        let (a, b) = (start.max(from), (*end).min(to));
        b.saturating_duration_since(a).as_secs_f64()
    };
    let busy: f64 = seen.iter().map(overlap).sum();
    let ads = ads.lock().map_err(|_| anyhow!("poisoned"))?.clone();
    let weights: Vec<f64> = coords.iter().map(|(_, p)| f64::from(*p)).collect();
    let fair = fair_slot_seconds(
        &ids,
        &weights,
        f64::from(a.workers) * f64::from(a.slots),
        &seen,
        &ads,
        from,
        to,
        Duration::from_millis(100),
    );
    let fair_sum: f64 = fair.iter().sum();
    let slot_s = f64::from(a.workers) * f64::from(a.slots) * window;
    let psum: f64 = coords.iter().map(|(_, p)| f64::from(*p)).sum();
    let mut per_run = Vec::new();
    let (mut cpu, mut trials, mut decide_s, mut decisions) = (0.0, 0u64, 0.0, 0u64);
    let (mut run_cpu, mut requests, mut adverts, mut empty) = (0.0, 0u64, 0u64, 0u64);
    let (mut p50s, mut p99) = (Vec::new(), 0.0f64);
    for (i, f) in finished.iter().enumerate() {
        let f = f.as_ref().context("a run without a final line")?;
        let mine: f64 = seen
            .iter()
            .filter(|(_, r, _)| *r == ids[i])
            .map(overlap)
            .sum();
        let c = f["cpu_s"].as_f64().unwrap_or(0.0);
        let n = f["accepted"].as_u64().unwrap_or(0);
        cpu += c;
        trials += n;
        decide_s += f["decide_s"].as_f64().unwrap_or(0.0);
        run_cpu += f["run_cpu_s"].as_f64().unwrap_or(0.0);
        requests += f["work_requests"].as_u64().unwrap_or(0);
        adverts += f["adverts"].as_u64().unwrap_or(0);
        empty += f["empty_grants"].as_u64().unwrap_or(0);
        decisions += f["status"]["decided"].as_u64().unwrap_or(0);
        if let Some(x) = f["dispatch_ms_p50"].as_f64() {
            p50s.push(x);
        }
        p99 = p99.max(f["dispatch_ms_p99"].as_f64().unwrap_or(0.0));
        per_run.push(RunRow {
            name: format!("fleet-{i}"),
            priority: coords[i].1,
            share: if busy > 0.0 { mine / busy } else { 0.0 },
            priority_share: f64::from(coords[i].1) / psum,
            fair_share: if fair_sum > 0.0 {
                fair[i] / fair_sum
            } else {
                0.0
            },
            trials: n,
            cpu_s: c,
            dispatch_ms_p50: f["dispatch_ms_p50"].as_f64(),
            dispatch_ms_p99: f["dispatch_ms_p99"].as_f64(),
        });
    }
    p50s.sort_by(f64::total_cmp);
    let worst = per_run
        .iter()
        .map(|r| (r.share / r.priority_share - 1.0).abs())
        .fold(0.0, f64::max);
    let worst_fair = per_run
        .iter()
        .filter(|r| r.fair_share > 0.0)
        .map(|r| (r.share / r.fair_share - 1.0).abs())
        .fold(0.0, f64::max);
    let report = Report {
        runs: a.runs,
        workers: a.workers,
        slots: a.slots,
        trial_ms: a.trial_ms,
        window_s: window,
        utilisation: busy / slot_s,
        trials_per_s: in_window.len() as f64 / window,
        coordinator_cpu_ms_per_trial: if trials > 0 {
            cpu / trials as f64 * 1e3
        } else {
            0.0
        },
        service_cpu_ms_per_trial: if trials > 0 {
            (cpu - run_cpu) / trials as f64 * 1e3
        } else {
            0.0
        },
        run_cpu_ms_per_decision: if decisions > 0 {
            run_cpu / decisions as f64 * 1e3
        } else {
            0.0
        },
        decide_ms_per_decision: if decisions > 0 {
            decide_s / decisions as f64 * 1e3
        } else {
            0.0
        },
        dispatch_ms_p50: p50s.get(p50s.len() / 2).copied().unwrap_or(0.0),
        dispatch_ms_p99: p99,
        work_requests_per_trial: requests as f64 / trials.max(1) as f64,
        adverts_per_trial: adverts as f64 / trials.max(1) as f64,
        empty_grants_per_trial: empty as f64 / trials.max(1) as f64,
        worst_share_error: worst,
        worst_fair_share_error: worst_fair,
        per_run,
        page: page_row,
    };
    Ok(report)
}

/// Prints the bench's reports (without and with the page open, for `--web`).
fn show(a: &FleetBenchArgs, reports: &[Report]) -> anyhow::Result<()> {
    if a.json {
        let v = match reports {
            [one] => serde_json::to_value(one)?,
            many => serde_json::json!({ "without_page": many.first(), "with_page": many.get(1) }),
        };
        crate::common::emit(&format!("{}\n", serde_json::to_string_pretty(&v)?))
            .map_err(|_| anyhow!("output"))?;
        return Ok(());
    }
    let mut all = String::new();
    for report in reports {
        all += &text(report);
    }
    if let [without, with] = reports {
        if let Some(p) = &with.page {
            all += &format!(
                "the web page open: its server {:.2} % of one core ({} feed events, {} page fetches); \
                 coordinator CPU {:.3} ms/trial without the page, {:.3} ms/trial with it ({:+.1} %)\n",
                p.cpu_percent,
                p.events,
                p.fetches,
                without.coordinator_cpu_ms_per_trial,
                with.coordinator_cpu_ms_per_trial,
                (with.coordinator_cpu_ms_per_trial / without.coordinator_cpu_ms_per_trial - 1.0) * 100.0
            );
        }
    }
    crate::common::emit(&all).map_err(|_| anyhow!("output"))
}

/// One report as text.
fn text(report: &Report) -> String {
    let page = report
        .page
        .as_ref()
        .map_or("without the web page".to_string(), |_| {
            "with the web page open".to_string()
        });
    let mut out = format!("{page}:\n") + &format!(
        "{} runs × {} workers × {} slots, trials of {} ms; window {:.1} s (every run with trials ready)\n\
         utilisation {:.1} %   {:.1} trials/s   dispatch latency p50 {:.1} ms, p99 {:.1} ms\n\
         coordinator CPU {:.3} ms/trial: service {:.3} ms/trial (zenoh, scheduling, topics) \
         + the run's thread {:.2} ms CPU/decision (journal, pickOut, CLOP; {:.2} ms wall)\n\
         per trial: {:.2} work requests (query and reply; {:.2} granted nothing), {:.2} adverts, \
         1 outcome, 1 published trial\n\
         worst share error {:.1} % of the priority's share; {:.1} % of the fair share \
         (the fleet shared by priority among what each run runs or has ready, at each instant)\n",
        report.runs,
        report.workers,
        report.slots,
        report.trial_ms,
        report.window_s,
        report.utilisation * 100.0,
        report.trials_per_s,
        report.dispatch_ms_p50,
        report.dispatch_ms_p99,
        report.coordinator_cpu_ms_per_trial,
        report.service_cpu_ms_per_trial,
        report.run_cpu_ms_per_decision,
        report.decide_ms_per_decision,
        report.work_requests_per_trial,
        report.empty_grants_per_trial,
        report.adverts_per_trial,
        report.worst_share_error * 100.0,
        report.worst_fair_share_error * 100.0
    );
    out += &format!(
        "{:<10} {:>8} {:>8} {:>10} {:>10} {:>8} {:>8}\n",
        "run", "priority", "share", "its share", "fair share", "trials", "CPU s"
    );
    for r in &report.per_run {
        out += &format!(
            "{:<10} {:>8} {:>7.1}% {:>9.1}% {:>9.1}% {:>8} {:>8.2}\n",
            r.name,
            r.priority,
            r.share * 100.0,
            r.priority_share * 100.0,
            r.fair_share * 100.0,
            r.trials,
            r.cpu_s
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::fair_shares;

    #[test]
    fn fair_shares_split_by_weight_and_give_what_a_run_cannot_use_to_the_others() {
        // All with trials ready: by weight.
        let s = fair_shares(60.0, &[1.0, 2.0, 3.0], &[None, None, None]);
        assert_eq!(s, [10.0, 20.0, 30.0]);
        // The weight-3 run runs only 12 and has nothing ready: the rest by 1:2.
        let s = fair_shares(60.0, &[1.0, 2.0, 3.0], &[None, None, Some(12.0)]);
        assert_eq!(s, [16.0, 32.0, 12.0]);
        // Water-filling goes on: capping one can cap the next.
        let s = fair_shares(100.0, &[1.0, 1.0, 1.0], &[Some(10.0), Some(40.0), None]);
        assert_eq!(s, [10.0, 40.0, 50.0]);
        // Demands that all fit are met.
        let s = fair_shares(100.0, &[1.0, 3.0], &[Some(5.0), Some(7.0)]);
        assert_eq!(s, [5.0, 7.0]);
    }
}
