//! Programs that serve trials one after another: a program whose
//! `--version` says [`crate::program::SERVE_LINE`] is started once per run
//! and slot as `PROGRAM --serve`, a job like any trial program's
//! (contained, in a clean environment, under the owner's limits), and kept
//! running between the run's trials in that slot. Each trial goes to its
//! standard input as one line of JSON; its answer is the next non-blank
//! line of its standard output. A simulator that takes seconds to start
//! pays that once per slot instead of once per trial.
//!
//! The worker ends such a job — killed whole, as a one-trial program is
//! at its end — when a trial of it fails (a non-answer, junk, no answer
//! within the time-out), when its program's file changes, when its run ends
//! on the worker, and when the worker stops (asked with SIGTERM first). The
//! program must carry nothing from one trial into the next: a trial
//! answered by a kept process must be the one a fresh process would give
//! (docs/programs.md; the T1's test checks it bit for bit).

use std::{
    path::Path,
    sync::{Arc, Mutex, PoisonError},
};

use protocol::{measurement::Measurement, TrialRequest};
use tokio::{
    io::{AsyncReadExt, AsyncWriteExt},
    process::{ChildStdin, ChildStdout},
    task::JoinHandle,
};

use crate::{
    job::Job,
    program::{exit_failure, read_answer, tail, timeout_failure, Program, Settings, STDERR_TAIL},
};

/// Bytes an answer line may have.
const LINE_BYTES: usize = 64 << 10;
/// How long a program that closed its standard output has to exit.
const EXIT_WITHIN: std::time::Duration = std::time::Duration::from_secs(2);

/// The kept programs of a worker, idle between their trials.
#[derive(Debug, Default)]
pub struct Pool {
    idle: Mutex<Vec<Served>>,
}

/// One kept program: the job and its pipes.
#[derive(Debug)]
struct Served {
    run: String,
    slot: u32,
    name: String,
    identity: u64,
    job: Job,
    stdin: ChildStdin,
    stdout: ChildStdout,
    /// Bytes read from standard output past the last answer.
    pending: Vec<u8>,
    /// The last bytes of its standard error, since its trial began.
    stderr: Arc<Mutex<Vec<u8>>>,
    read_err: JoinHandle<()>,
}

impl Served {
    /// Starts `program --serve` for `run` in `slot`.
    fn start(
        program: &Program,
        run: &str,
        slot: u32,
        scratch: &Path,
        settings: &Settings,
    ) -> std::io::Result<Self> {
        let env = settings.env_for(scratch);
        let mut job =
            Job::start_with_args(&program.path, &["--serve"], scratch, &env, &settings.limits)?;
        let (Some(stdin), Some(stdout), Some(mut err)) = (
            job.child.stdin.take(),
            job.child.stdout.take(),
            job.child.stderr.take(),
        ) else {
            return Err(std::io::Error::other("its pipes could not be opened"));
        };
        let stderr = Arc::new(Mutex::new(Vec::new()));
        let kept = stderr.clone();
        let read_err = tokio::spawn(async move {
            let mut chunk = [0u8; 8192];
            while let Ok(n) = err.read(&mut chunk).await {
                if n == 0 {
                    break;
                }
                let mut k = kept.lock().unwrap_or_else(PoisonError::into_inner);
                k.extend_from_slice(&chunk[..n]);
                if k.len() > 4 * STDERR_TAIL {
                    let cut = k.len() - 2 * STDERR_TAIL;
                    k.drain(..cut);
                }
            }
        });
        Ok(Self {
            run: run.to_string(),
            slot,
            name: program.name.clone(),
            identity: program.identity,
            job,
            stdin,
            stdout,
            pending: Vec::new(),
            stderr,
            read_err,
        })
    }

    /// Sends one trial and reads its answer line: `None` when the program
    /// closed its standard output first.
    async fn ask(&mut self, input: &[u8]) -> Result<Option<Vec<u8>>, String> {
        let mut line = input.to_vec();
        line.push(b'\n');
        if self.stdin.write_all(&line).await.is_err() || self.stdin.flush().await.is_err() {
            return Ok(None);
        }
        let mut chunk = [0u8; 8192];
        loop {
            while let Some(i) = self.pending.iter().position(|&b| b == b'\n') {
                let got: Vec<u8> = self.pending.drain(..=i).collect();
                if !got.iter().all(u8::is_ascii_whitespace) {
                    return Ok(Some(got));
                }
            }
            if self.pending.len() > LINE_BYTES {
                return Err(format!(
                    "printed more than {} KiB without ending a line",
                    LINE_BYTES >> 10
                ));
            }
            match self.stdout.read(&mut chunk).await {
                Ok(0) | Err(_) => return Ok(None),
                Ok(n) => self.pending.extend_from_slice(&chunk[..n]),
            }
        }
    }

    /// Its standard error since its trial began, once it has ended (what is
    /// left in the pipe read, within a bound).
    async fn last_words(self) -> Vec<u8> {
        let _ = tokio::time::timeout(EXIT_WITHIN, self.read_err).await;
        let e = self.stderr.lock().unwrap_or_else(PoisonError::into_inner);
        e.clone()
    }
}

impl Pool {
    /// Runs one trial in the process kept for its run in `slot` (started
    /// if there is none): its measurement, or why it failed.
    #[allow(clippy::too_many_arguments)]
    pub(crate) async fn run(
        &self,
        program: &Program,
        req: &TrialRequest,
        input: &[u8],
        slot: u32,
        scratch: &Path,
        settings: &Settings,
        stop: &tokio_util::sync::CancellationToken,
    ) -> Result<Measurement, String> {
        let who = format!("program `{}`", program.name);
        let (kept, stale) = self.take(&req.run, slot, program);
        for mut s in stale {
            s.job.end().await;
        }
        let mut s = match kept {
            Some(s) => s,
            None => Served::start(program, &req.run, slot, scratch, settings)
                .map_err(|e| format!("{who} did not start: {e}"))?,
        };
        s.stderr
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clear();
        enum End {
            Answered(Result<Option<Vec<u8>>, String>),
            TimedOut,
            Stopped,
        }
        let end = tokio::select! {
            a = s.ask(input) => End::Answered(a),
            () = tokio::time::sleep(settings.timeout) => End::TimedOut,
            () = stop.cancelled() => End::Stopped,
        };
        match end {
            End::Answered(Ok(Some(line))) => match read_answer(&line, req) {
                Ok(m) => {
                    self.idle
                        .lock()
                        .unwrap_or_else(PoisonError::into_inner)
                        .push(s);
                    Ok(m)
                }
                Err(e) => {
                    s.job.end().await;
                    Err(format!("{who} {e}; {}", tail(&s.last_words().await)))
                }
            },
            End::Answered(Ok(None)) => {
                let status = tokio::time::timeout(EXIT_WITHIN, s.job.child.wait()).await;
                s.job.end().await;
                let err = s.last_words().await;
                Err(match status {
                    Ok(Ok(st)) if !st.success() => exit_failure(&who, st, &err, settings),
                    _ => format!(
                        "{who} closed its standard output without answering; {}",
                        tail(&err)
                    ),
                })
            }
            End::Answered(Err(e)) => {
                s.job.end().await;
                Err(format!("{who} {e}; {}", tail(&s.last_words().await)))
            }
            End::TimedOut => {
                s.job.end().await;
                Err(timeout_failure(&who, &s.last_words().await, settings))
            }
            End::Stopped => {
                s.job.stop(settings.grace).await;
                Err(format!(
                    "the worker is stopping; {who} was stopped; {}",
                    tail(&s.last_words().await)
                ))
            }
        }
    }

    /// The slots in which a process of `program` is kept idle for `run`.
    pub(crate) fn kept_slots(&self, run: &str, program: &str) -> Vec<u32> {
        let idle = self.idle.lock().unwrap_or_else(PoisonError::into_inner);
        idle.iter()
            .filter(|s| s.run == run && s.name == program)
            .map(|s| s.slot)
            .collect()
    }

    /// The idle process kept for `run` in `slot` for `program`, if any, and
    /// those kept there for an earlier build of it.
    fn take(&self, run: &str, slot: u32, program: &Program) -> (Option<Served>, Vec<Served>) {
        let mut idle = self.idle.lock().unwrap_or_else(PoisonError::into_inner);
        let (here, rest): (Vec<Served>, Vec<Served>) = std::mem::take(&mut *idle)
            .into_iter()
            .partition(|s| s.run == run && s.slot == slot && s.name == program.name);
        *idle = rest;
        let (same, stale): (Vec<Served>, Vec<Served>) = here
            .into_iter()
            .partition(|s| s.identity == program.identity);
        (same.into_iter().next(), stale)
    }

    /// Ends the processes kept for `run` (it ended on this worker).
    pub async fn end_run(&self, run: &str) {
        let ended: Vec<Served> = {
            let mut idle = self.idle.lock().unwrap_or_else(PoisonError::into_inner);
            let (ended, rest) = std::mem::take(&mut *idle)
                .into_iter()
                .partition(|s| s.run == run);
            *idle = rest;
            ended
        };
        for mut s in ended {
            s.job.end().await;
        }
    }

    /// Stops every kept process: SIGTERM to all, then SIGKILL to what is
    /// left after `grace`.
    pub async fn stop_all(&self, grace: std::time::Duration) {
        let all = std::mem::take(&mut *self.idle.lock().unwrap_or_else(PoisonError::into_inner));
        for s in &all {
            s.job.signal(nix::sys::signal::Signal::SIGTERM);
        }
        let deadline = tokio::time::Instant::now() + grace;
        for mut s in all {
            let _ = tokio::time::timeout_at(deadline, s.job.child.wait()).await;
            s.job.end().await;
        }
    }
}
