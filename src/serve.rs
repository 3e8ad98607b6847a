//! What `run`, `coordinator` and `worker` share: the runtime, the shutdown
//! signals, opening the run directory, serving a run with its progress view,
//! the closing summary.

use std::time::Duration;

use anyhow::anyhow;
use coordinator::{
    run::{load_history, Run},
    service::{self, Ended, Event, ServiceConfig},
};
use protocol::{experiment::TrialModel, params::Shown, wire::RunStatus};

use crate::{
    args::JobArgs,
    common::{load_experiment, Failure},
    view::View,
};

pub fn runtime() -> Result<tokio::runtime::Runtime, Failure> {
    runtime_with(2)
}

/// A runtime of `threads` worker threads (besides the thread that blocks on it).
pub fn runtime_with(threads: usize) -> Result<tokio::runtime::Runtime, Failure> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(threads)
        .enable_all()
        .build()
        .map_err(|e| Failure::Job(e.into()))
}

/// The variable with which a bench starts its processes (`crate::crew`):
/// such a process also shuts down, as on SIGTERM, when its standard input
/// ends, that is when the bench holding the pipe's other end is gone,
/// however it ended (SIGKILL included); see [`watch_stdin`].
pub const EXIT_WITH_STDIN: &str = "NAOFARM_EXIT_WITH_STDIN";

/// How long a process whose standard input ended has to shut down before it
/// exits anyway (one still connecting, say, to a router that is gone).
const STDIN_GRACE: Duration = Duration::from_secs(10);

/// Whether standard input has ended, for [`signals`].
fn stdin_ended() -> &'static tokio::sync::watch::Sender<bool> {
    static ENDED: std::sync::OnceLock<tokio::sync::watch::Sender<bool>> =
        std::sync::OnceLock::new();
    ENDED.get_or_init(|| tokio::sync::watch::channel(false).0)
}

/// With [`EXIT_WITH_STDIN`] set, a thread that reads standard input (and
/// throws it away) until it ends; then [`signals`] turns true, and if the
/// process is still there [`STDIN_GRACE`] later, it exits (1). Called first
/// by `coordinator`, `worker` and `router`.
pub fn watch_stdin() {
    if std::env::var_os(EXIT_WITH_STDIN).is_none() {
        return;
    }
    let ended = stdin_ended();
    std::thread::spawn(move || {
        let _ = std::io::copy(&mut std::io::stdin().lock(), &mut std::io::sink());
        ended.send_replace(true);
        std::thread::sleep(STDIN_GRACE);
        eprintln!(
            "error: standard input ended ({EXIT_WITH_STDIN}: the process that started this one \
             is gone) and this process had not stopped {} s later",
            STDIN_GRACE.as_secs()
        );
        std::process::exit(1);
    });
}

/// A shutdown channel that turns true on SIGINT or SIGTERM (or, with
/// [`EXIT_WITH_STDIN`] set, when standard input ends).
pub fn signals() -> tokio::sync::watch::Receiver<bool> {
    let (tx, rx) = tokio::sync::watch::channel(false);
    let mut ended = stdin_ended().subscribe();
    tokio::spawn(async move {
        tokio::select! {
            _ = interrupted() => {}
            _ = ended.wait_for(|ended| *ended) => {}
        }
        let _ = tx.send(true);
    });
    rx
}

/// Waits for SIGINT or SIGTERM and names the one that came.
pub async fn interrupted() -> &'static str {
    let ctrl_c = tokio::signal::ctrl_c();
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        if let Ok(mut term) = signal(SignalKind::terminate()) {
            return tokio::select! {
                _ = ctrl_c => "SIGINT",
                _ = term.recv() => "SIGTERM",
            };
        }
    }
    let _ = ctrl_c.await;
    "SIGINT"
}

/// A run checked and ready to serve. A coordinator opens its zenoh session
/// between [`prepare_run`] and [`Prepared::open_beside`], so an endpoint it
/// cannot listen on leaves no new run directory behind, while an `--out`
/// that exists is opened (its lock taken) before any network, so another
/// coordinator holding it is named first.
pub enum Prepared {
    /// A new run: checked, nothing written yet.
    New(Box<NewRun>),
    /// An existing `--out` opened: a run resumed (or begun in an empty
    /// directory), its lock held.
    Resumed(Box<(Run, Vec<coordinator::run::Effect>)>),
}

/// A new run, everything a start can refuse refused, nothing written.
pub struct NewRun {
    exp: protocol::experiment::Experiment,
    text: String,
    imported: Option<coordinator::evolve::Imported>,
    out: std::path::PathBuf,
    priority: Option<protocol::wire::Control>,
    failure_limit: usize,
}

/// Reads and checks the experiment, the flags and `--from` (exit 2 on a bad
/// one), writing nothing for a new run. An `--out` that exists is opened
/// here (a run resumed; a lock another coordinator holds, another
/// experiment, or a file exits 2 before any network), and a new one inside
/// another run's directory is refused here too.
pub fn prepare_run(job: &JobArgs) -> Result<Prepared, Failure> {
    let (mut exp, text) = load_experiment(&job.experiment)?;
    if let Some(n) = job.iterations {
        exp.iterations = n;
    }
    if let Some(s) = job.seed {
        exp.seed = s;
    }
    if let Some(m) = &job.model {
        exp.model = TrialModel::parse(m).map_err(|e| Failure::Usage(anyhow!("--model: {e}")))?;
    }
    exp.validate().map_err(|e| Failure::Usage(e.into()))?;
    if exp.model == TrialModel::Nao {
        for (_, note) in crate::common::type_overrides(&exp, exp.robot_type) {
            eprintln!("note: {note}");
        }
    }
    if !(job.silence_s.is_finite() && (0.1..=3600.0).contains(&job.silence_s)) {
        return Err(Failure::Usage(anyhow!(
            "--silence-s {}: must be in [0.1, 3600] seconds",
            Shown(job.silence_s)
        )));
    }
    if !(job.lease_s.is_finite() && (1.0..=86_400.0).contains(&job.lease_s)) {
        return Err(Failure::Usage(anyhow!(
            "--lease-s {}: must be in [1, 86400] seconds",
            Shown(job.lease_s)
        )));
    }
    if !(1..=100).contains(&job.max_trial_failures) {
        return Err(Failure::Usage(anyhow!(
            "--max-trial-failures {}: must be in 1..=100",
            job.max_trial_failures
        )));
    }
    let priority = match job.priority {
        Some(p) => {
            let action = protocol::wire::Control::Priority(p);
            action
                .check()
                .map_err(|e| Failure::Usage(anyhow!("--priority: {e}")))?;
            Some(action)
        }
        None => None,
    };
    let imported = match &job.from {
        Some(dir) => {
            if let Some(why) = crate::common::not_a_run(dir) {
                return Err(Failure::Usage(anyhow!("--from {why}")));
            }
            let from = load_history(dir, &exp).map_err(|e| match e {
                coordinator::run::RunError::FromMismatch { .. } => Failure::Usage(e.into()),
                e => Failure::Job(anyhow!("--from {}: {e}", dir.display())),
            })?;
            eprintln!(
                "starting from {}: {} of its {} points lie inside this experiment's bounds{}",
                dir.display(),
                from.imported.history.len(),
                from.total,
                if from.best_kept {
                    ""
                } else {
                    "; its best set does not, so ν′ starts undefined"
                }
            );
            Some(from.imported)
        }
        None => None,
    };
    let new = NewRun {
        exp,
        text,
        imported,
        out: job.out.clone(),
        priority,
        failure_limit: job.max_trial_failures as usize,
    };
    if job.out.exists() {
        return Ok(Prepared::Resumed(Box::new(new.open()?)));
    }
    // Inside another run's directory: refused before any network, as an
    // `--out` that exists is (`Run::open` asks again once the session is open).
    coordinator::run::refuse_new_run_at(&job.out).map_err(open_failure)?;
    Ok(Prepared::New(Box::new(new)))
}

impl Prepared {
    /// The run, once `session` is open: a new one's directory made now; the
    /// session closed if the run cannot be opened.
    pub async fn open_beside(
        self,
        session: &zenoh::Session,
    ) -> Result<(Run, Vec<coordinator::run::Effect>), Failure> {
        let opened = match self {
            Prepared::Resumed(opened) => return Ok(*opened),
            Prepared::New(new) => new.open(),
        };
        if opened.is_err() {
            let _ = session.close().await;
        }
        opened
    }
}

impl NewRun {
    /// Makes the run directory and its journal, or resumes the run in it.
    pub fn open(self) -> Result<(Run, Vec<coordinator::run::Effect>), Failure> {
        let mut opened =
            Run::open(&self.out, self.exp, &self.text, self.imported).map_err(open_failure)?;
        opened.0.set_failure_limit(self.failure_limit);
        if let Some(action) = self.priority {
            opened
                .0
                .control(action, "--priority")
                .map_err(|e| Failure::Job(e.into()))?;
        }
        if let Some(before) = opened.0.extended_from() {
            eprintln!(
                "extending {} from {before} to {} iterations",
                self.out.display(),
                opened.0.evolve().experiment().iterations
            );
        }
        Ok(opened)
    }
}

/// How a run that cannot be opened fails: exit 2 for an `--out` that is
/// not this run's to begin or resume (another experiment, someone's files,
/// inside another run, held by another coordinator, a journal this build
/// replays otherwise), 1 for the rest (a damaged journal, an I/O error).
fn open_failure(e: coordinator::run::RunError) -> Failure {
    use coordinator::run::RunError as E;
    match e {
        E::OtherExperiment { .. }
        | E::NotARunDirectory { .. }
        | E::InsideARun { .. }
        | E::Locked(_)
        | E::Diverged { .. } => Failure::Usage(e.into()),
        e => Failure::Job(e.into()),
    }
}

pub fn service_config(job: &JobArgs, prefix: &str) -> ServiceConfig {
    ServiceConfig {
        prefix: prefix.to_string(),
        lease: Duration::from_secs_f64(job.lease_s),
        silence: Duration::from_secs_f64(job.silence_s),
    }
}

/// Shows the service's events in a [`View`] until the channel closes.
pub fn spawn_view(
    json: bool,
    mut rx: tokio::sync::mpsc::UnboundedReceiver<Event>,
) -> tokio::task::JoinHandle<(View, Option<RunStatus>)> {
    tokio::spawn(async move {
        let mut view = View::new(json);
        let mut last = None;
        while let Some(e) = rx.recv().await {
            match e {
                Event::Started(history, status) => {
                    view.history(&history);
                    view.status(&status);
                    last = Some(*status);
                }
                Event::Decided(result, status) => {
                    view.decided(&result);
                    view.status(&status);
                    last = Some(*status);
                }
            }
        }
        (view, last)
    })
}

pub fn summary(
    run_dir: &std::path::Path,
    ended: &Ended,
    view: Option<(View, Option<RunStatus>)>,
) -> Result<(), Failure> {
    if let Some((mut view, last)) = view {
        match (last, ended) {
            (Some(status), Ended::Finished(c)) => view.finish(
                &status,
                serde_json::json!({
                    "accepted": c.accepted,
                    "duplicates": c.duplicates,
                    "refused": c.refused,
                    "redispatched": c.redispatched,
                    "failures": c.failures,
                    "set_aside": c.set_aside,
                    "refused_reasons": c.refused_reasons,
                    "cpu_s": coordinator::cpu::process_cpu_seconds(),
                    "dispatch_ms_p50": c.dispatch_quantile(0.5),
                    "dispatch_ms_p99": c.dispatch_quantile(0.99),
                    "decide_s": c.decide_s,
                    "run_cpu_s": c.run_cpu_s,
                    "work_requests": c.work_requests,
                    "adverts": c.adverts,
                    "empty_grants": c.empty_grants,
                }),
            ),
            _ => view.abandon(),
        }
    }
    match ended {
        Ended::Finished(c) => {
            eprintln!(
                "run complete: {} outcomes journaled, {} duplicates ignored, {} refused, {} re-dispatched, {} trial failures{}; journal in {}",
                c.accepted,
                c.duplicates,
                c.refused,
                c.redispatched,
                c.failures,
                if c.set_aside.is_empty() {
                    String::new()
                } else {
                    format!(" (set aside: {})", c.set_aside.join(", "))
                },
                run_dir.display()
            );
            Ok(())
        }
        Ended::Interrupted(_) => Err(Failure::Job(anyhow!(
            "interrupted; resume with the same command (journal in {})",
            run_dir.display()
        ))),
        Ended::Stopped(_, by) => {
            eprintln!(
                "stopped by `naofarm ctl` ({by}); resume with the same command (journal in {})",
                run_dir.display()
            );
            Ok(())
        }
    }
}

/// Serves the run on `session`, its events shown in a [`View`]; returns how it
/// ended and the view with the last status.
pub async fn serve_with_view(
    session: &zenoh::Session,
    (run, effects): (Run, Vec<coordinator::run::Effect>),
    job: &JobArgs,
    prefix: &str,
    shutdown: tokio::sync::watch::Receiver<bool>,
    json: bool,
) -> (
    Result<Ended, service::ServiceError>,
    Option<(View, Option<RunStatus>)>,
) {
    let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
    let printer = spawn_view(json, rx);
    let ended = service::serve(
        session.clone(),
        run,
        effects,
        service_config(job, prefix),
        shutdown,
        Some(tx),
    )
    .await;
    (ended, printer.await.ok())
}
