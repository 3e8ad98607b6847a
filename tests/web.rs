//! `naofarm web` in a real browser: headless Chromium driven through
//! ChromeDriver (the W3C WebDriver protocol), against a real fleet on
//! 127.0.0.1 — a router, two coordinators, two workers — and two pages: a
//! watcher's and a controller's. The screenshots the test takes are kept in
//! `target/tmp/web-screenshots/`.
#![allow(clippy::unwrap_used)]

mod util;

use std::{
    path::{Path, PathBuf},
    process::Stdio,
    time::{Duration, Instant},
};

use serde_json::{json, Value};
use util::{naofarm, scratch, Proc};

const TIMEOUT: Duration = Duration::from_secs(90);

/// A synthetic run of `iterations`.
fn experiment(dir: &Path, name: &str, seed: u64, iterations: u64) -> PathBuf {
    let text = format!(
        "name = \"{name}\"\nseed = {seed}\niterations = {iterations}\ntrials_per_iteration = 4\n\
         pipeline_depth = 2\nmodel = \"synthetic\"\nstart = \"expert\"\n\n\
         [[parameter]]\nname = \"ThighRelHip2_Z\"\nlower = -0.08\nupper = -0.03\nexpert = -0.04\n\n\
         [[parameter]]\nname = \"xlength_step_max\"\nlower = 0.02\nupper = 0.15\nexpert = 0.08\n\n\
         [clop]\nn_mcmc = 100\n"
    );
    let file = dir.join(format!("{name}.toml"));
    std::fs::write(&file, text).unwrap();
    file
}

fn router(dir: &Path, listen: &str) -> (Proc, String) {
    router_with(dir, listen, &[])
}

/// A router on `listen` with `extra` flags (`--tls DIR`); its endpoint.
fn router_with(dir: &Path, listen: &str, extra: &[&str]) -> (Proc, String) {
    let p = Proc::spawn(
        naofarm()
            .args(["router", "--listen", listen])
            .args(extra)
            .stdout(Stdio::null()),
        dir,
        "router",
    );
    let scheme = listen.split('/').next().unwrap_or("tcp");
    let line = p.wait_line(&format!("router listening on {scheme}/127.0.0.1:"), TIMEOUT);
    let endpoint = line.rsplit(' ').next().unwrap().trim().to_string();
    (p, endpoint)
}

/// `naofarm web` on a port the OS picks; its process and address.
fn web(dir: &Path, ep: &str, extra: &[&str]) -> (Proc, String) {
    let p = Proc::spawn(
        naofarm()
            .args(["web", "--connect", ep, "--http", "127.0.0.1:0"])
            .args(extra)
            .stdout(Stdio::null()),
        dir,
        "web",
    );
    let line = p.wait_line("web page at http://", TIMEOUT);
    let url = line
        .rsplit(' ')
        .next()
        .unwrap()
        .trim()
        .trim_end_matches('/');
    (p, url.to_string())
}

fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .timeout_global(Some(TIMEOUT + Duration::from_secs(30)))
        .build()
        .into()
}

/// An HTTP request: its status and body.
fn http(method: &str, url: &str, headers: &[(&str, &str)], body: Option<&str>) -> (u16, String) {
    let a = agent();
    let mut r = match (method, body) {
        ("GET", _) => {
            let mut req = a.get(url);
            for (k, v) in headers {
                req = req.header(*k, *v);
            }
            req.call().unwrap()
        }
        (_, b) => {
            let mut req = a.post(url);
            for (k, v) in headers {
                req = req.header(*k, *v);
            }
            req.send(b.unwrap_or("")).unwrap()
        }
    };
    let status = r.status().as_u16();
    (status, r.body_mut().read_to_string().unwrap())
}

/// Waits until `check` holds, asking it at once and again at each event of
/// the page server's feed at `page` (sent whenever the fleet changes).
fn on_feed(page: &str, what: &str, mut check: impl FnMut() -> bool) {
    use std::io::BufRead;
    if check() {
        return;
    }
    let deadline = Instant::now() + TIMEOUT;
    let mut r = agent().get(format!("{page}/events")).call().unwrap();
    let feed = std::io::BufReader::new(r.body_mut().as_reader());
    for line in feed.lines() {
        let line = line.unwrap_or_else(|e| panic!("the feed ended before {what}: {e}"));
        if line.starts_with("data:") && check() {
            return;
        }
        assert!(Instant::now() < deadline, "never {what}");
    }
    panic!("the feed ended before {what}");
}

/// Headless Chromium under ChromeDriver, one session.
struct Browser {
    _driver: Proc,
    base: String,
    session: String,
}

/// Debian's Chromium and ChromeDriver (`.ci/run` installs both), or
/// `$NAOFARM_CHROMIUM` and `$NAOFARM_CHROMEDRIVER`.
fn browser_paths() -> Option<(PathBuf, PathBuf)> {
    let path = |var: &str, default: &str| {
        std::env::var_os(var)
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from(default))
    };
    let chromium = path("NAOFARM_CHROMIUM", "/usr/bin/chromium");
    let driver = path("NAOFARM_CHROMEDRIVER", "/usr/bin/chromedriver");
    (chromium.exists() && driver.exists()).then_some((chromium, driver))
}

impl Browser {
    fn start(dir: &Path, chromium: &Path, driver: &Path) -> Self {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        // ChromeDriver says on stdout when it listens: sent to the log file.
        let proc = Proc::spawn(
            std::process::Command::new("sh")
                .args(["-c", "exec \"$0\" \"$1\" 1>&2"])
                .arg(driver)
                .arg(format!("--port={port}"))
                .stdout(Stdio::null()),
            dir,
            "chromedriver",
        );
        proc.wait_line("was started successfully", TIMEOUT);
        let base = format!("http://127.0.0.1:{port}");
        let caps = json!({"capabilities": {"alwaysMatch": {
        "browserName": "chrome",
        "goog:chromeOptions": {
            "binary": chromium,
            "args": ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                     "--no-first-run", "--disable-background-networking",
                     "--disable-component-update", "--disable-sync",
                     "--window-size=1400,1000",
                     format!("--user-data-dir={}", dir.join("profile").display())],
        }}}});
        let (code, body) = http(
            "POST",
            &format!("{base}/session"),
            &[],
            Some(&caps.to_string()),
        );
        assert_eq!(code, 200, "a browser session: {body}");
        let v: Value = serde_json::from_str(&body).unwrap();
        let session = v["value"]["sessionId"].as_str().unwrap().to_string();
        let url = format!("{base}/session/{session}/timeouts");
        let script_ms = json!({ "script": TIMEOUT.as_millis() }).to_string();
        assert_eq!(http("POST", &url, &[], Some(&script_ms)).0, 200);
        Self {
            _driver: proc,
            base,
            session,
        }
    }

    fn command(&self, method: &str, path: &str, body: &Value) -> Value {
        let url = format!("{}/session/{}{path}", self.base, self.session);
        let (code, text) = http(method, &url, &[], Some(&body.to_string()));
        assert_eq!(code, 200, "{method} {path}: {text}");
        serde_json::from_str::<Value>(&text).unwrap()["value"].take()
    }

    fn go(&self, url: &str) {
        self.command("POST", "/url", &json!({ "url": url }));
    }

    fn eval(&self, script: &str) -> Value {
        self.command(
            "POST",
            "/execute/sync",
            &json!({"script": script, "args": []}),
        )
    }

    /// Waits until `script` returns something truthy; that value. The
    /// page checks it at once and again on every change of its document
    /// (the feed redraws it), so the test waits on the page's events.
    fn wait(&self, what: &str, script: &str) -> Value {
        let observer = format!(
            "const done = arguments[arguments.length - 1];
             const check = () => {{ try {{ return (function () {{ {script} }})(); }} catch (e) {{ return null; }} }};
             const first = check();
             if (first) {{ done(first); return; }}
             const seen = new MutationObserver(() => {{
               const v = check();
               if (v) {{ seen.disconnect(); done(v); }}
             }});
             seen.observe(document, {{subtree: true, childList: true, attributes: true, characterData: true}});"
        );
        let url = format!("{}/session/{}/execute/async", self.base, self.session);
        let body = json!({"script": observer, "args": []}).to_string();
        let (code, text) = http("POST", &url, &[], Some(&body));
        assert_eq!(code, 200, "the page never showed {what}: {text}");
        serde_json::from_str::<Value>(&text).unwrap()["value"].take()
    }

    /// A screenshot into `target/tmp/web-screenshots/NAME.png`; its pixels
    /// must not all be one colour.
    fn screenshot(&self, name: &str) {
        use base64::Engine as _;
        let v = self.command("GET", "/screenshot", &Value::Null);
        let bytes = base64::engine::general_purpose::STANDARD
            .decode(v.as_str().unwrap())
            .unwrap();
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("web-screenshots");
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join(format!("{name}.png"));
        std::fs::write(&file, &bytes).unwrap();
        let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        let n = info.color_type.samples();
        let px = &buf[..info.buffer_size()];
        let differing = px.chunks(n).filter(|p| p[..3] != px[..3]).count();
        assert!(
            differing > px.len() / n / 100,
            "{} is blank",
            file.display()
        );
        eprintln!("screenshot: {}", file.display());
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let url = format!("{}/session/{}", self.base, self.session);
        let _ = agent().delete(url).call();
    }
}

fn sigterm(p: &Proc) {
    let ok = std::process::Command::new("kill")
        .args(["-TERM", &p.child.id().to_string()])
        .status()
        .unwrap();
    assert!(ok.success());
}

/// The fleet page lists every run and both workers, a run that is over
/// shows its Table IV, a running run's figure gains
/// points as decisions arrive without a reload, a stopped worker leaves the
/// list, the control is absent on a watcher's page and works on a
/// controller's, and a page whose fleet goes away says so and recovers when
/// it returns; bad URLs and bodies get 4xx.
#[test]
fn the_fleet_page_lives_in_a_real_browser() {
    let Some((chromium, driver)) = browser_paths() else {
        eprintln!(
            "SKIPPED: no Chromium and ChromeDriver at /usr/bin (`.ci/run` installs Debian's \
             `chromium` and `chromium-driver`; run it as root)"
        );
        return;
    };
    let dir = scratch("web");
    let (mut router_proc, ep) = router(&dir, "tcp/127.0.0.1:0");
    let coordinator = |name: &str, seed: u64, priority: u32, iterations: u64| {
        Proc::spawn(
            naofarm()
                .args([
                    "coordinator",
                    "--connect",
                    &ep,
                    "--priority",
                    &priority.to_string(),
                ])
                .arg(experiment(&dir, name, seed, iterations))
                .arg("--out")
                .arg(dir.join(name))
                .stdout(Stdio::null()),
            &dir,
            "coordinator",
        )
    };
    // Two runs that go on while the test runs.
    let _alpha = coordinator("alpha", 1, 1, 5000);
    let _beta = coordinator("beta", 2, 3, 5000);
    let worker = || {
        Proc::spawn(
            naofarm()
                .args([
                    "worker",
                    "--connect",
                    &ep,
                    "--slots",
                    "2",
                    "--min-trial-ms",
                    "60",
                ])
                .stdout(Stdio::null()),
            &dir,
            "worker",
        )
    };
    let (w1, w2) = (worker(), worker());
    let (_watcher, page) = web(&dir, &ep, &[]);
    let (_controller, control_page) = web(&dir, &ep, &["--control"]);
    // And one that is soon over, started once the pages watch.
    let _gamma = coordinator("gamma", 3, 6, 30);
    let b = Browser::start(&dir, &chromium, &driver);

    // The fleet: both runs, both workers.
    b.go(&format!("{page}/"));
    b.wait(
        "three runs and two workers",
        "return document.querySelectorAll('#runs tr[data-run]').length == 3 \
         && document.querySelectorAll('#workers tr[data-worker]').length == 2",
    );
    let names = b.eval(
        "return [...document.querySelectorAll('#runs tr[data-run] a')].map(a => a.textContent)",
    );
    assert_eq!(names, json!(["alpha", "beta", "gamma"]));
    let workers = b.eval(
        "return [...document.querySelectorAll('#workers tr[data-worker]')].map(r => r.dataset.worker)",
    );
    b.screenshot("fleet");
    let fleet: Value =
        serde_json::from_str(&http("GET", &format!("{page}/api/fleet"), &[], None).1).unwrap();
    let id = |name: &str| {
        fleet["runs"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["run"] == name)
            .unwrap()["id"]
            .as_str()
            .unwrap()
            .to_string()
    };
    let (alpha, beta, gamma) = (id("alpha"), id("beta"), id("gamma"));

    // A run that is over: its page shows its Table IV.
    b.go(&format!("{page}/run/{gamma}"));
    b.wait(
        "gamma's Table IV",
        "return document.getElementById('table4') !== null",
    );
    let table = b.eval("return document.getElementById('table4').textContent");
    for column in ["Expert", "Optim.1", "Optim.2"] {
        assert!(table.as_str().unwrap().contains(column), "{table}");
    }
    b.screenshot("finished-run");

    // A run's figure grows without a reload; a watcher's page has no control.
    b.go(&format!("{page}/run/{alpha}"));
    let points = "const f = document.querySelector('[data-figure=\"param-ThighRelHip2_Z.svg\"]'); \
                  return f && Number(f.dataset.points || 0)";
    let before = b.wait("the parameter figure", points).as_u64().unwrap();
    let loaded = b.eval("return window.naofarmLoaded");
    b.wait(
        "the figure gaining points",
        &format!("{points} > {before} && Number(document.querySelector('[data-figure=\"param-ThighRelHip2_Z.svg\"]').dataset.points)"),
    );
    assert_eq!(
        b.eval("return window.naofarmLoaded"),
        loaded,
        "the page reloaded"
    );
    assert_eq!(
        b.eval("return document.querySelectorAll('#controls button').length"),
        0
    );
    b.screenshot("run");

    // A controller's page pauses and resumes a run.
    b.go(&format!("{control_page}/run/{beta}"));
    b.wait(
        "the controls",
        "return document.querySelectorAll('#controls button').length == 4",
    );
    b.eval("document.querySelector('#controls button[data-action=pause]').click()");
    b.wait(
        "the run paused",
        "return document.getElementById('run-state').textContent == 'paused'",
    );
    b.eval("document.querySelector('#controls button[data-action=resume]').click()");
    b.wait(
        "the run running again",
        "return document.getElementById('run-state').textContent == 'running'",
    );

    // A stopped worker leaves the list.
    sigterm(&w2);
    b.go(&format!("{page}/"));
    let left = b.wait(
        "one worker left",
        "const r = [...document.querySelectorAll('#workers tr[data-worker]')]; \
         return r.length == 1 && r[0].dataset.worker",
    );
    assert!(
        workers.as_array().unwrap().contains(&left),
        "{left} was not listed before"
    );
    drop(w1);

    // The fleet goes away: the page says so; it comes back: the page recovers.
    router_proc.kill();
    b.wait(
        "that the fleet is gone",
        "return document.getElementById('gone') !== null",
    );
    let (_router_again, _) = router(&dir, &ep);
    b.wait(
        "the fleet back",
        "return document.getElementById('gone') === null \
         && document.querySelectorAll('#runs tr[data-run][data-state=running]').length == 2 \
         && document.querySelectorAll('#runs tr[data-run][data-state=finished]').length == 1",
    );
    b.screenshot("fleet-recovered");

    // Bad input: 404, 403, 400, 413, 409; never a panic.
    let get = |url: String| http("GET", &url, &[], None).0;
    assert_eq!(get(format!("{page}/run/no-such-run")), 404);
    assert_eq!(get(format!("{page}/api/run/no-such-run")), 404);
    assert_eq!(
        get(format!("{page}/api/run/{alpha}/figure/param-nope.svg")),
        404
    );
    assert_eq!(get(format!("{page}/nothing/here")), 404);
    assert_eq!(get(format!("{page}/api/run/{alpha}/table")), 409);
    let post = |base: &str, headers: &[(&str, &str)], body: &str| {
        http(
            "POST",
            &format!("{base}/api/run/{alpha}/control"),
            headers,
            Some(body),
        )
    };
    let page_headers = [
        ("x-naofarm", "control"),
        ("content-type", "application/json"),
    ];
    assert_eq!(post(&page, &page_headers, r#"{"action":"pause"}"#).0, 403);
    assert_eq!(post(&control_page, &[], r#"{"action":"pause"}"#).0, 403);
    assert_eq!(post(&control_page, &page_headers, "{not json").0, 400);
    assert_eq!(
        post(&control_page, &page_headers, r#"{"action":"explode"}"#).0,
        400
    );
    assert_eq!(
        post(
            &control_page,
            &page_headers,
            r#"{"action":"priority","priority":0}"#
        )
        .0,
        400
    );
    let big = format!(r#"{{"action":"pause","pad":"{}"}}"#, "x".repeat(10_000));
    assert_eq!(post(&control_page, &page_headers, &big).0, 413);

    // A page server started now rebuilds every run's history from the topics.
    let (_fresh, fresh) = web(&dir, &ep, &[]);
    on_feed(&fresh, "had alpha's history", || {
        let (code, body) = http("GET", &format!("{fresh}/api/run/{alpha}"), &[], None);
        let v: Value = serde_json::from_str(&body).unwrap_or_default();
        code == 200
            && v["known"].as_u64() > Some(0)
            && v["known"].as_u64() >= v["status"]["decided"].as_u64()
    });
}

/// Over mutual TLS with roles, a page started with the watcher's
/// certificate sees every run (its history and experiment) and every
/// worker; one started with `--control` acts with the coordinator's.
#[test]
fn over_tls_a_watchers_page_sees_the_fleet_and_a_controllers_acts() {
    let dir = scratch("web-tls");
    let pki = dir.join("pki");
    util::succeed(naofarm().arg("certs").arg(&pki));
    let pki = pki.to_str().unwrap();
    let (_router, ep) = router_with(&dir, "tls/127.0.0.1:0", &["--tls", pki]);
    let _coordinator = Proc::spawn(
        naofarm()
            .args(["coordinator", "--connect", &ep, "--tls", pki])
            .arg(experiment(&dir, "delta", 4, 5000))
            .arg("--out")
            .arg(dir.join("delta"))
            .stdout(Stdio::null()),
        &dir,
        "coordinator",
    );
    let _worker = Proc::spawn(
        naofarm()
            .args(["worker", "--connect", &ep, "--tls", pki, "--slots", "2"])
            .args(["--min-trial-ms", "60"])
            .stdout(Stdio::null()),
        &dir,
        "worker",
    );
    let (_watcher, page) = web(&dir, &ep, &["--tls", pki]);
    let (_controller, control_page) = web(&dir, &ep, &["--tls", pki, "--control"]);
    let mut id = String::new();
    on_feed(&page, "saw the run whole on the watcher's page", || {
        let fleet: Value =
            serde_json::from_str(&http("GET", &format!("{page}/api/fleet"), &[], None).1).unwrap();
        let (Some(run), 1) = (
            fleet["runs"][0]["id"].as_str(),
            fleet["workers"].as_array().map_or(0, Vec::len),
        ) else {
            return false;
        };
        let (code, body) = http("GET", &format!("{page}/api/run/{run}"), &[], None);
        let v: Value = serde_json::from_str(&body).unwrap_or_default();
        id = run.to_string();
        code == 200
            && v["known"].as_u64() > Some(0)
            && v["figures"].as_array().is_some_and(|f| !f.is_empty())
            && v["control"] == false
    });
    let headers = [
        ("x-naofarm", "control"),
        ("content-type", "application/json"),
    ];
    let (code, body) = http(
        "POST",
        &format!("{control_page}/api/run/{id}/control"),
        &headers,
        Some(r#"{"action":"pause"}"#),
    );
    assert_eq!(code, 200, "{body}");
    let status: Value = serde_json::from_str(&body).unwrap();
    assert_eq!(status["state"], "paused");
}

/// SIGTERM to `web` while a page's live feed is open: the feed ends and
/// the page server exits, instead of waiting for the page to go.
#[test]
fn web_stops_on_sigterm_with_a_page_open() {
    use std::io::BufRead;
    let dir = scratch("web-term");
    let (_router, ep) = router(&dir, "tcp/127.0.0.1:0");
    let (mut w, page) = web(&dir, &ep, &[]);
    let mut r = agent().get(format!("{page}/events")).call().unwrap();
    let mut feed = std::io::BufReader::new(r.body_mut().as_reader());
    let mut first = String::new();
    while !first.starts_with("data:") {
        first.clear();
        assert!(
            feed.read_line(&mut first).unwrap() > 0,
            "the feed ended at once"
        );
    }
    sigterm(&w);
    let status = util::wait_for("web to stop with its feed open", TIMEOUT, || {
        w.child.try_wait().unwrap()
    });
    assert!(status.success(), "{status}: {}", w.stderr());
    // What is left of the feed ends: no more events after the stop.
    let rest: Vec<String> = feed.lines().map_while(Result::ok).collect();
    assert!(
        rest.iter().filter(|l| l.starts_with("data:")).count() <= 1,
        "{rest:?}"
    );
}
