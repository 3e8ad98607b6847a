//! What a bench starts and makes — its processes (router, workers,
//! coordinators) and scratch directories — taken down with it: when the
//! bench returns, with a result or an error, and when SIGINT or SIGTERM
//! ends it; its processes also when SIGKILL does (they shut down when
//! their standard input, a pipe the crew holds, ends). Without this, a bench
//! that timed out left its coordinators running against a router that was
//! gone, and an interrupted one left its journals in `/dev/shm`.

use std::{
    path::{Path, PathBuf},
    process::{Child, ChildStderr, ChildStdout, Command, ExitStatus},
    sync::{Arc, Mutex, MutexGuard, Weak},
    time::Duration,
};

/// A bench's processes and scratch directories; see the module's doc. Its
/// members are killed, reaped and removed when it is dropped, or by the
/// signal watcher [`Crew::new`] starts, which then ends the process (exit 1).
pub struct Crew(Arc<Mutex<Inner>>);

#[derive(Default)]
struct Inner {
    children: Vec<(usize, Child)>,
    dirs: Vec<tempfile::TempDir>,
    next: usize,
}

impl Inner {
    /// Kills and reaps every process, then removes every directory
    /// (processes first: a coordinator still alive could write into them).
    fn take_down(&mut self) {
        for (_, c) in &mut self.children {
            let _ = c.kill();
            let _ = c.wait();
        }
        self.children.clear();
        self.dirs.clear();
    }
}

/// One process of a crew: its id there and the pipes it was started with.
pub struct Member {
    id: usize,
    /// Its stdout, when the command piped it.
    pub stdout: Option<ChildStdout>,
    /// Its stderr, when the command piped it.
    pub stderr: Option<ChildStderr>,
}

impl Crew {
    /// An empty crew, and a thread that takes it down on SIGINT or SIGTERM
    /// and ends the process with exit 1, saying so.
    pub fn new() -> Self {
        let inner = Arc::new(Mutex::new(Inner::default()));
        let weak = Arc::downgrade(&inner);
        std::thread::spawn(move || watch_signals(&weak));
        Self(inner)
    }

    fn lock(&self) -> MutexGuard<'_, Inner> {
        // A panic while holding it leaves nothing half-done that matters here.
        self.0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Starts `cmd` as one of the crew. Its standard input is a pipe the
    /// crew holds and never writes: if the bench ends without taking the crew
    /// down (SIGKILL), the pipe's end tells the process to shut down
    /// ([`crate::serve::EXIT_WITH_STDIN`]).
    pub fn spawn(&self, cmd: &mut Command) -> std::io::Result<Member> {
        let mut inner = self.lock();
        let mut child = cmd
            .stdin(std::process::Stdio::piped())
            .env(crate::serve::EXIT_WITH_STDIN, "1")
            .spawn()?;
        let id = inner.next;
        inner.next += 1;
        let member = Member {
            id,
            stdout: child.stdout.take(),
            stderr: child.stderr.take(),
        };
        inner.children.push((id, child));
        Ok(member)
    }

    /// Waits for `member` to end and returns how it ended; it leaves the
    /// crew. Polls every millisecond, so that a signal can take the crew
    /// down meanwhile.
    pub fn wait(&self, member: &Member) -> std::io::Result<ExitStatus> {
        loop {
            {
                let mut inner = self.lock();
                let Some(i) = inner.children.iter().position(|(id, _)| *id == member.id) else {
                    return Err(std::io::Error::other("not a process of this crew"));
                };
                if let Some(status) = inner.children[i].1.try_wait()? {
                    inner.children.remove(i);
                    return Ok(status);
                }
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// The process id of `member`, while it is one of the crew.
    pub fn pid(&self, member: &Member) -> Option<u32> {
        let inner = self.lock();
        inner
            .children
            .iter()
            .find(|(id, _)| *id == member.id)
            .map(|(_, c)| c.id())
    }

    /// Kills and reaps `member` (if it has not ended); it leaves the crew.
    pub fn kill(&self, member: &Member) {
        let mut inner = self.lock();
        if let Some(i) = inner.children.iter().position(|(id, _)| *id == member.id) {
            let (_, mut child) = inner.children.remove(i);
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    /// A new, empty scratch directory in `base`, named `PREFIX…`, removed
    /// with the crew.
    pub fn scratch(&self, base: &Path, prefix: &str) -> std::io::Result<PathBuf> {
        let dir = tempfile::Builder::new().prefix(prefix).tempdir_in(base)?;
        let path = dir.path().to_path_buf();
        self.lock().dirs.push(dir);
        Ok(path)
    }
}

impl Drop for Crew {
    fn drop(&mut self) {
        self.lock().take_down();
    }
}

/// Waits for SIGINT or SIGTERM; then takes the crew down, if it is still
/// there, and ends the process.
fn watch_signals(crew: &Weak<Mutex<Inner>>) {
    let Ok(rt) = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    else {
        // No watcher: the signals keep their default action.
        return;
    };
    let name = rt.block_on(crate::serve::interrupted());
    // Held to the end: the bench's own threads wait rather than go on with
    // processes that are gone.
    let inner = crew.upgrade();
    let _held = inner.as_ref().map(|inner| {
        let mut held = inner
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        held.take_down();
        held
    });
    eprintln!(
        "error: interrupted by {name}: the bench's processes were stopped and its \
         scratch directories removed"
    );
    std::process::exit(1);
}
