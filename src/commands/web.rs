//! `naofarm web`: a live page of the fleet. It joins the fleet as a watcher
//! (it subscribes and queries, as `watch` does; it publishes nothing), keeps
//! what the topics say in memory ([`fleet::Fleet`], rebuilt from the topics
//! after a restart), and serves on `--http` (loopback by default):
//!
//! - `/` the fleet: every run with its progress, decisions, best walk, rate
//!   and share of the slots against its priority's; every worker; the
//!   utilisation;
//! - `/run/ID` a run: its figures (the report's drawings, growing as
//!   decisions arrive), its last decisions, failures and refusals by reason,
//!   and, once it is over, Table IV and the walks;
//! - `/events` the live feed (Server-Sent Events) both pages listen to.
//!
//! Control (pause, resume, stop, priority) is served only with `--control`,
//! through a second session with the coordinator's certificate under
//! `--tls`; a request must come from the page itself (its own `Host` and a
//! header a foreign page cannot send without asking).

mod fleet;

use std::{
    collections::BTreeMap,
    net::SocketAddr,
    sync::{Arc, Mutex},
    time::{Duration, Instant},
};

use anyhow::anyhow;
use axum::{
    body::Bytes,
    extract::{DefaultBodyLimit, Path, State},
    http::{header, HeaderMap, StatusCode},
    response::{
        sse::{Event, KeepAlive, Sse},
        Html, IntoResponse, Response,
    },
    routing::{get, post},
    Router,
};
use coordinator::evolve::DecidedIteration;
use fleet::{Ask, Fleet};
use protocol::{
    keys::{self, FleetKeys, RunKeys},
    wire::{Control, ControlRequest, IterationResult, RunStatus, WireMessage, WorkerStatus},
    Experiment,
};
use zenoh::{query::ConsolidationMode, sample::SampleKind, Session};

use crate::{
    args::WebArgs,
    commands::report::{self, figures},
    common::{usage_unless, Failure},
};

const PAGE: &str = include_str!("web/page.html");
const SCRIPT: &str = include_str!("web/page.js");
const STYLE: &str = include_str!("web/page.css");

/// Trials per column of a finished run's Table IV (the report's default).
const TABLE_TRIALS: u32 = 100;
/// The most often the feed sends the fleet (it sends only when it changed).
const FEED_EVERY: Duration = Duration::from_millis(250);
/// Largest request body (a control request is a few bytes).
const MAX_BODY: usize = 4096;

/// A finished run's Table IV or walk, computed once on first request.
#[derive(Clone)]
enum Computed {
    Running,
    Ready(String),
    Failed(String),
}

/// What the handlers share.
struct Shared {
    fleet: Mutex<Fleet>,
    /// Bumped on every change: the feed sends the fleet when it moved.
    changed: tokio::sync::watch::Sender<u64>,
    /// The session for control, when the page may control.
    control: Option<Session>,
    prefix: String,
    /// The address the page is served on (a control request must name it).
    http: SocketAddr,
    /// Runs whose history is being asked for.
    asking: Mutex<std::collections::BTreeSet<String>>,
    /// Finished runs' tables and walks, by (run id, what).
    computed: Mutex<BTreeMap<(String, String), Computed>>,
    /// Turns true on SIGINT or SIGTERM: the live feeds end, so the server's
    /// graceful shutdown does not wait for an open page.
    stopping: tokio::sync::watch::Receiver<bool>,
}

impl Shared {
    fn fleet(&self) -> std::sync::MutexGuard<'_, Fleet> {
        // A handler that panicked while holding the lock left a fleet that
        // is still a fleet; the page goes on showing it.
        self.fleet
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn bump(&self) {
        self.changed.send_modify(|v| *v = v.wrapping_add(1));
    }
}

/// `naofarm web`.
pub fn web(a: &WebArgs) -> Result<(), Failure> {
    let mut net = a.net.clone();
    if net.connect.is_empty() && net.config.is_none() {
        net.connect
            .push(crate::net::default_connect(net.tls.is_some()));
    }
    usage_unless(net.listen.is_empty(), || {
        "`web` only connects: give the fleet's router with --connect, and the page's own \
         address with --http"
            .into()
    })?;
    let watch_cfg = net.zenoh_config("watcher", &[]).map_err(Failure::Usage)?;
    let control_cfg = if a.control {
        Some(
            net.zenoh_config("coordinator", &[])
                .map_err(Failure::Usage)?,
        )
    } else {
        None
    };
    let rt = crate::serve::runtime()?;
    rt.block_on(async {
        let listener = tokio::net::TcpListener::bind(a.http)
            .await
            .map_err(|e| Failure::Job(anyhow!("cannot serve the page on {}: {e}", a.http)))?;
        let http = listener
            .local_addr()
            .map_err(|e| Failure::Job(anyhow!("the page's address: {e}")))?;
        let mut shutdown = crate::serve::signals();
        let session = crate::net::open_session(watch_cfg, "web", &net.connect).await?;
        let control = match control_cfg {
            Some(cfg) => Some(crate::net::open_session(cfg, "web (control)", &net.connect).await?),
            None => None,
        };
        let (changed, _) = tokio::sync::watch::channel(0u64);
        let shared = Arc::new(Shared {
            fleet: Mutex::new(Fleet::default()),
            changed,
            control,
            prefix: net.prefix.clone(),
            http,
            asking: Mutex::new(std::collections::BTreeSet::new()),
            computed: Mutex::new(BTreeMap::new()),
            stopping: shutdown.clone(),
        });
        let follow = tokio::spawn(follow(session.clone(), shared.clone()));
        let app = routes(shared.clone());
        eprintln!("web page at http://{http}/");
        let mut stop = shutdown.clone();
        let served = axum::serve(listener, app)
            .with_graceful_shutdown(async move {
                let _ = stop.wait_for(|s| *s).await;
            })
            .await;
        let _ = shutdown.wait_for(|s| *s).await;
        follow.abort();
        let _ = session.close().await;
        if let Some(c) = &shared.control {
            let _ = c.close().await;
        }
        served.map_err(|e| Failure::Job(anyhow!("the page's server: {e}")))
    })
}

fn routes(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/", get(page))
        .route("/run/{id}", get(run_page))
        .route(
            "/page.js",
            get(|| async { asset("text/javascript", SCRIPT) }),
        )
        .route("/page.css", get(|| async { asset("text/css", STYLE) }))
        .route("/events", get(events))
        .route("/api/fleet", get(fleet_json))
        .route("/api/run/{id}", get(run_json))
        .route("/api/run/{id}/figure/{name}", get(figure))
        .route("/api/run/{id}/table", get(table))
        .route("/api/run/{id}/walk/{set}", get(walk))
        .route("/api/run/{id}/control", post(control))
        .fallback(|| async { not_found("no such page") })
        .layer(DefaultBodyLimit::max(MAX_BODY))
        .with_state(shared)
}

fn asset(kind: &'static str, text: &'static str) -> Response {
    ([(header::CONTENT_TYPE, kind)], text).into_response()
}

/// A 404 page that says what was not found.
fn not_found(what: &str) -> Response {
    let body = format!(
        "<!doctype html><meta charset=utf-8><title>not found</title>\
         <link rel=stylesheet href=/page.css><p class=missing>{}: <a href=/>the fleet</a></p>",
        escape(what)
    );
    (StatusCode::NOT_FOUND, Html(body)).into_response()
}

fn text(code: StatusCode, why: impl Into<String>) -> Response {
    (
        code,
        [(header::CONTENT_TYPE, "text/plain; charset=utf-8")],
        why.into(),
    )
        .into_response()
}

fn json(v: &serde_json::Value) -> Response {
    ([(header::CONTENT_TYPE, "application/json")], v.to_string()).into_response()
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

async fn page() -> Html<&'static str> {
    Html(PAGE)
}

async fn run_page(State(sh): State<Arc<Shared>>, Path(id): Path<String>) -> Response {
    if sh.fleet().runs.contains_key(&id) {
        Html(PAGE).into_response()
    } else {
        not_found(&format!("no run `{id}` answers on this fleet"))
    }
}

async fn fleet_json(State(sh): State<Arc<Shared>>) -> Response {
    json(&sh.fleet().snapshot(Instant::now()))
}

/// How many decisions the run page lists.
const LAST_DECISIONS: usize = 20;

async fn run_json(State(sh): State<Arc<Shared>>, Path(id): Path<String>) -> Response {
    let f = sh.fleet();
    let Some(e) = f.runs.get(&id) else {
        return not_found(&format!("no run `{id}`"));
    };
    let last: Vec<&IterationResult> = e.history.values().rev().take(LAST_DECISIONS).collect();
    let figures: Vec<String> = e.experiment.as_ref().map_or_else(Vec::new, |x| {
        x.parameter
            .iter()
            .map(|p| format!("param-{}.svg", p.name))
            .chain(["progress.svg".into(), "decisions.svg".into()])
            .collect()
    });
    json(&serde_json::json!({
        "status": e.status,
        "gone": e.gone,
        "known": e.history.len(),
        "last": last,
        "figures": figures,
        "model": e.experiment.as_ref().map(|x| x.model),
        "control": sh.control.is_some(),
    }))
}

/// The run's decided iterations in the report's form (parameters in the
/// experiment's order); none if a result lacks one of its parameters.
fn decided_of(exp: &Experiment, history: &BTreeMap<u64, IterationResult>) -> Vec<DecidedIteration> {
    let order = |pairs: &[(String, f64)]| -> Option<Vec<f64>> {
        exp.parameter
            .iter()
            .map(|p| pairs.iter().find(|(n, _)| *n == p.name).map(|(_, v)| *v))
            .collect()
    };
    history
        .values()
        .filter_map(|r| {
            Some(DecidedIteration {
                iteration: r.iteration,
                params: order(&r.params)?,
                stats: r.stats.clone(),
                decision: r.decision,
                best: match &r.best {
                    Some(b) => Some(protocol::pickout::Incumbent {
                        iteration: b.iteration,
                        params: order(&b.params)?,
                        stats: b.stats.clone(),
                    }),
                    None => None,
                },
            })
        })
        .collect()
}

async fn figure(
    State(sh): State<Arc<Shared>>,
    Path((id, name)): Path<(String, String)>,
) -> Response {
    let (exp, decided, optim2) = {
        let f = sh.fleet();
        let Some(e) = f.runs.get(&id) else {
            return not_found(&format!("no run `{id}`"));
        };
        let Some(exp) = e.experiment.clone() else {
            return not_found(&format!("run `{id}`'s experiment has not arrived yet"));
        };
        let decided = decided_of(&exp, &e.history);
        (exp, decided, e.status.optim2.clone())
    };
    let drawn = match name.as_str() {
        "progress.svg" => figures::progress_figure(&decided),
        "decisions.svg" => figures::decisions_figure(&decided),
        other => match other
            .strip_prefix("param-")
            .and_then(|n| n.strip_suffix(".svg"))
            .and_then(|n| exp.parameter.iter().position(|p| p.name == n))
        {
            Some(i) => {
                let name = &exp.parameter[i].name;
                let o2 = optim2.iter().find(|(n, _)| n == name).map(|(_, v)| *v);
                figures::parameter_figure(&exp, &decided, i, o2)
            }
            None => return not_found(&format!("run `{id}` has no figure `{name}`")),
        },
    };
    match drawn {
        Ok(svg) => ([(header::CONTENT_TYPE, "image/svg+xml")], svg).into_response(),
        Err(e) => text(StatusCode::INTERNAL_SERVER_ERROR, format!("{name}: {e:#}")),
    }
}

/// Table IV's sets of a run that is over: Expert, Optim.1, Optim.2.
fn table_sets(exp: &Experiment, s: &RunStatus) -> Option<Vec<(&'static str, Vec<f64>)>> {
    let order = |pairs: &[(String, f64)]| -> Option<Vec<f64>> {
        exp.parameter
            .iter()
            .map(|p| pairs.iter().find(|(n, _)| *n == p.name).map(|(_, v)| *v))
            .collect()
    };
    let [expert, optim1, optim2] = coordinator::evolve::TABLE_SETS;
    let mut sets = vec![(expert, exp.expert_values())];
    if let Some(b) = &s.best {
        sets.push((optim1, order(&b.params)?));
    }
    sets.push((optim2, order(&s.optim2)?));
    Some(sets)
}

/// A finished run's experiment and status, or the response that says why not.
fn over(sh: &Shared, id: &str) -> Result<(Experiment, RunStatus), Response> {
    let f = sh.fleet();
    let Some(e) = f.runs.get(id) else {
        return Err(not_found(&format!("no run `{id}`")));
    };
    let Some(exp) = e.experiment.clone() else {
        return Err(not_found(&format!(
            "run `{id}`'s experiment has not arrived yet"
        )));
    };
    if !e.status.finished {
        return Err(text(
            StatusCode::CONFLICT,
            format!("run `{id}` is not over: its report comes when it is"),
        ));
    }
    Ok((exp, e.status.clone()))
}

/// Computes `what` of run `id` once, on a thread of its own; its state now.
fn computed(
    sh: &Arc<Shared>,
    id: &str,
    what: &str,
    work: impl FnOnce() -> Result<String, Failure> + Send + 'static,
) -> Computed {
    let key = (id.to_string(), what.to_string());
    let mut all = sh
        .computed
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some(c) = all.get(&key) {
        return c.clone();
    }
    all.insert(key.clone(), Computed::Running);
    let sh = sh.clone();
    tokio::task::spawn_blocking(move || {
        let c = match work() {
            Ok(t) => Computed::Ready(t),
            Err(Failure::Job(e) | Failure::Usage(e)) => Computed::Failed(format!("{e:#}")),
        };
        sh.computed
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .insert(key, c);
        sh.bump();
    });
    Computed::Running
}

async fn table(State(sh): State<Arc<Shared>>, Path(id): Path<String>) -> Response {
    let (exp, status) = match over(&sh, &id) {
        Ok(x) => x,
        Err(r) => return r,
    };
    let Some(sets) = table_sets(&exp, &status) else {
        return text(
            StatusCode::INTERNAL_SERVER_ERROR,
            "the status lacks a parameter of the experiment",
        );
    };
    let c = computed(&sh, &id, "table", move || {
        report::table_markdown(&exp, sets, TABLE_TRIALS, 1)
    });
    match c {
        Computed::Running => json(&serde_json::json!({"state": "running", "trials": TABLE_TRIALS})),
        Computed::Ready(md) => json(&serde_json::json!({"state": "ready", "markdown": md})),
        Computed::Failed(why) => json(&serde_json::json!({"state": "failed", "why": why})),
    }
}

async fn walk(State(sh): State<Arc<Shared>>, Path((id, set)): Path<(String, String)>) -> Response {
    let (exp, status) = match over(&sh, &id) {
        Ok(x) => x,
        Err(r) => return r,
    };
    if exp.model != protocol::TrialModel::Nao {
        return not_found(&format!("run `{id}` walks no NAO"));
    }
    let Some(sets) = table_sets(&exp, &status) else {
        return text(
            StatusCode::INTERNAL_SERVER_ERROR,
            "the status lacks a parameter of the experiment",
        );
    };
    let Some((name, params)) = sets
        .into_iter()
        .find(|(n, _)| format!("{}.svg", crate::common::set_key(n)) == set)
    else {
        return not_found(&format!("run `{id}` has no walk `{set}`"));
    };
    match computed(&sh, &id, &set, move || {
        report::replay_svg(&exp, &params, name)
    }) {
        Computed::Running => text(StatusCode::ACCEPTED, "drawing the walk"),
        Computed::Ready(svg) => ([(header::CONTENT_TYPE, "image/svg+xml")], svg).into_response(),
        Computed::Failed(why) => text(StatusCode::INTERNAL_SERVER_ERROR, why),
    }
}

/// A control request as the page sends it.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct ControlBody {
    action: String,
    #[serde(default)]
    priority: Option<u32>,
}

async fn control(
    State(sh): State<Arc<Shared>>,
    Path(id): Path<String>,
    headers: HeaderMap,
    body: Bytes,
) -> Response {
    let Some(session) = sh.control.clone() else {
        return text(
            StatusCode::FORBIDDEN,
            "this page only watches: control needs `naofarm web --control` (with --tls, a \
             coordinator certificate)",
        );
    };
    // Only the page itself: its own Host (no other site's name resolved
    // here), and a header that a foreign page cannot send without asking.
    let host_ok = headers
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .is_some_and(|h| h == sh.http.to_string() || h == format!("localhost:{}", sh.http.port()));
    let from_page = headers.get("x-naofarm").is_some_and(|v| v == "control");
    if !(host_ok && from_page) {
        return text(
            StatusCode::FORBIDDEN,
            "control requests come from the page itself",
        );
    }
    let b: ControlBody = match serde_json::from_slice(&body) {
        Ok(b) => b,
        Err(e) => {
            return text(
                StatusCode::BAD_REQUEST,
                format!("not a control request: {e}"),
            )
        }
    };
    let action = match (b.action.as_str(), b.priority) {
        ("pause", None) => Control::Pause,
        ("resume", None) => Control::Resume,
        ("stop", None) => Control::Stop,
        ("priority", Some(p)) => Control::Priority(p),
        _ => {
            return text(
                StatusCode::BAD_REQUEST,
                "the action is pause, resume, stop, or priority with a priority",
            )
        }
    };
    if let Err(e) = action.check() {
        return text(StatusCode::BAD_REQUEST, e);
    }
    if !sh.fleet().runs.contains_key(&id) {
        return not_found(&format!("no run `{id}`"));
    }
    let req = ControlRequest {
        action,
        by: format!("the web page at {}", sh.http),
    };
    let bytes = match req.encode() {
        Ok(b) => b,
        Err(e) => return text(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    };
    let asked = session
        .get(FleetKeys::new(&sh.prefix, &id).ctl())
        .payload(bytes)
        .timeout(Duration::from_secs(5))
        .await;
    let replies = match asked {
        Ok(r) => r,
        Err(e) => return text(StatusCode::BAD_GATEWAY, format!("zenoh: {e}")),
    };
    match replies.recv_async().await {
        Ok(reply) => match reply.result() {
            Ok(sample) => {
                let t = String::from_utf8_lossy(&sample.payload().to_bytes()).into_owned();
                match RunStatus::from_json(&t) {
                    Ok(s) => {
                        let v = serde_json::json!(s);
                        sh.fleet().status(s, Instant::now());
                        sh.bump();
                        json(&v)
                    }
                    Err(e) => text(
                        StatusCode::BAD_GATEWAY,
                        format!("the coordinator's answer: {e}"),
                    ),
                }
            }
            Err(e) => text(
                StatusCode::CONFLICT,
                format!(
                    "refused: {}",
                    String::from_utf8_lossy(&e.payload().to_bytes())
                ),
            ),
        },
        Err(_) => text(
            StatusCode::GATEWAY_TIMEOUT,
            format!("run `{id}` did not answer"),
        ),
    }
}

/// The live feed: the fleet when it changed, at most every [`FEED_EVERY`].
async fn events(
    State(sh): State<Arc<Shared>>,
) -> Sse<impl futures_util::Stream<Item = Result<Event, std::convert::Infallible>>> {
    let rx = sh.changed.subscribe();
    let stream = futures_util::stream::unfold((sh, rx, true), |(sh, mut rx, first)| async move {
        let mut stopping = sh.stopping.clone();
        if *stopping.borrow() {
            return None;
        }
        if !first {
            let next = async {
                tokio::time::sleep(FEED_EVERY).await;
                rx.changed().await
            };
            tokio::select! {
                changed = next => changed.ok()?,
                _ = stopping.wait_for(|s| *s) => return None,
            }
        }
        rx.mark_unchanged();
        let data = sh.fleet().snapshot(Instant::now()).to_string();
        Some((
            Ok(Event::default().event("fleet").data(data)),
            (sh, rx, false),
        ))
    });
    Sse::new(stream).keep_alive(KeepAlive::default())
}

/// Text of a sample's payload.
fn payload(s: &zenoh::sample::Sample) -> String {
    String::from_utf8_lossy(&s.payload().to_bytes()).into_owned()
}

/// Follows the fleet's topics into [`Shared::fleet`] until aborted.
async fn follow(session: Session, sh: Arc<Shared>) -> Result<(), Failure> {
    let z = |e: zenoh::Error| Failure::Job(anyhow!("zenoh: {e}"));
    let prefix = sh.prefix.clone();
    let subscribe = |key: String| session.declare_subscriber(key);
    let statuses = subscribe(keys::status_all(&prefix)).await.map_err(z)?;
    let results = subscribe(keys::results_all(&prefix)).await.map_err(z)?;
    let workers = subscribe(keys::worker_statuses_all(&prefix))
        .await
        .map_err(z)?;
    // Tokens already up count too (history).
    let live = |key: String| session.liveliness().declare_subscriber(key).history(true);
    let tokens = live(keys::workers_all(&prefix)).await.map_err(z)?;
    let coordinators = live(keys::coordinators_all(&prefix)).await.map_err(z)?;
    let mut tick = tokio::time::interval(Duration::from_secs(1));
    loop {
        tokio::select! {
            s = statuses.recv_async() => {
                let Ok(s) = s else { break };
                match RunStatus::from_json(&payload(&s)) {
                    Ok(st) => took_status(&session, &sh, st),
                    Err(e) => tracing::warn!(error = %e, "ignored a malformed status"),
                }
            }
            s = results.recv_async() => {
                let Ok(s) = s else { break };
                // <prefix>/<name>/<id>/results/<i>
                let key = s.key_expr().as_str().to_string();
                let id = key.rsplit('/').nth(2).unwrap_or_default().to_string();
                match IterationResult::from_json(&payload(&s)) {
                    Ok(r) => {
                        if sh.fleet().result(&id, r) {
                            sh.bump();
                        }
                    }
                    Err(e) => tracing::warn!(error = %e, "ignored a malformed result"),
                }
            }
            s = workers.recv_async() => {
                let Ok(s) = s else { break };
                match WorkerStatus::from_json(&payload(&s)) {
                    Ok(w) => {
                        let live = keys::worker_of_status(s.key_expr().as_str()) == w.worker;
                        if live {
                            sh.fleet().worker(w, Instant::now());
                            sh.bump();
                        } else {
                            tracing::warn!(worker = %w.worker, "ignored a worker status under another worker's key");
                        }
                    }
                    Err(e) => tracing::warn!(error = %e, "ignored a malformed worker status"),
                }
            }
            s = tokens.recv_async() => {
                let Ok(s) = s else { break };
                if s.kind() == SampleKind::Delete && sh.fleet().worker_gone(keys::last_chunk(s.key_expr().as_str())) {
                    sh.bump();
                }
            }
            s = coordinators.recv_async() => {
                let Ok(s) = s else { break };
                let id = keys::last_chunk(s.key_expr().as_str()).to_string();
                if s.kind() == SampleKind::Delete {
                    sh.fleet().coordinator_gone(&id);
                } else {
                    // A run started, or the fleet came back: its status.
                    sh.fleet().coordinator_back(&id);
                    let key = keys::status_of(&sh.prefix, &id);
                    tokio::spawn(ask_statuses(session.clone(), sh.clone(), key));
                }
                sh.bump();
            }
            _ = tick.tick() => {
                let info = session.info();
                let reached = info.routers_zid().await.next().is_some() || info.peers_zid().await.next().is_some();
                let expired = sh.fleet().expire(Instant::now());
                let moved = {
                    let mut f = sh.fleet();
                    let moved = f.connected != reached;
                    f.connected = reached;
                    moved
                };
                if expired || moved {
                    sh.bump();
                }
                if reached && moved {
                    tokio::spawn(ask_statuses(session.clone(), sh.clone(), keys::status_all(&sh.prefix)));
                }
            }
        }
    }
    Ok(())
}

/// A status came: kept, and the run's history asked for if the page lacks some.
fn took_status(session: &Session, sh: &Arc<Shared>, st: RunStatus) {
    let (id, name) = (st.id.clone(), st.run.clone());
    let ask = sh.fleet().status(st, Instant::now());
    sh.bump();
    if ask == Ask::History
        && sh
            .asking
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .insert(id.clone())
    {
        tokio::spawn(ask_history(session.clone(), sh.clone(), name, id));
    }
}

/// Every answer to `key` that comes within 3 s.
async fn ask_all(session: &Session, key: &str) -> Vec<String> {
    let mut out = Vec::new();
    if let Ok(replies) = session
        .get(key)
        .consolidation(ConsolidationMode::None)
        .timeout(Duration::from_secs(3))
        .await
    {
        while let Ok(reply) = replies.recv_async().await {
            if let Ok(sample) = reply.result() {
                out.push(payload(sample));
            }
        }
    }
    out
}

/// Asks `key` for run statuses and takes each answer.
async fn ask_statuses(session: Session, sh: Arc<Shared>, key: String) {
    for text in ask_all(&session, &key).await {
        if let Ok(st) = RunStatus::from_json(&text) {
            took_status(&session, &sh, st);
        }
    }
}

async fn ask_history(session: Session, sh: Arc<Shared>, name: String, id: String) {
    let rkeys = RunKeys::new(&sh.prefix, &name, &id);
    let history = protocol::wire::history_from_parts(&ask_all(&session, &rkeys.history()).await)
        .unwrap_or_else(|e| {
            tracing::warn!(run = %id, error = %e, "ignored a history answer");
            Vec::new()
        });
    let exp = ask_all(&session, &rkeys.experiment())
        .await
        .iter()
        .filter_map(|t| serde_json::from_str::<Experiment>(t).ok())
        .find(|x| x.validate().is_ok());
    sh.fleet().history(&id, history, exp);
    sh.asking
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
        .remove(&id);
    sh.bump();
}
