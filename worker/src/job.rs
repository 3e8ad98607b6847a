//! A trial program's processes as one job, as a job runner runs them: one
//! unit the worker kills whole, tied to the worker's life, in a clean
//! environment, under the owner's limits, in a slot no other trial on the
//! host holds, with scratch space that goes with its owner.
//!
//! The mechanisms are the strongest the host allows, found once per process
//! ([`Host::get`]) and said at start and in the worker's status:
//!
//! - **a cgroup v2 per job** where this process may create one beside
//!   itself (as root, or in a cgroup delegated to it: systemd's
//!   `Delegate=yes`), killed with `cgroup.kill`; a watcher process of this
//!   process's, told by a parent-death signal, kills them all when this
//!   process dies, however it dies;
//! - else **a PID namespace per job** (util-linux `unshare`, as root or in
//!   a user namespace of its own, with its own `/proc`): the job's init is
//!   a shell that runs the program, and when it ends the kernel kills every
//!   process left in the namespace, whatever it did (`setsid`, a double
//!   fork);
//! - else **the job's process group with this process as child
//!   subreaper**: a process of the job that leaves the group (`setsid`) and
//!   loses its parent comes to this process, which kills it with the job
//!   (by the `NAOFARM_JOB` mark in its environment);
//! - always **the job's process group**, signalled whole, and a
//!   **parent-death signal** (util-linux `setpriv --pdeathsig`) on its first
//!   process;
//! - **limits** (address space, processes, file size, CPU seconds) set by
//!   util-linux `prlimit` before the program starts.
//!
//! `NAOFARM_JOB_CONTAINMENT=pidns` or `=group` (read once, at run time)
//! makes a host that allows a cgroup use the weaker mechanism instead: for
//! tests of those hosts.
//!
//! [`Scratch`] is a directory held by a lock for its owner's life: a
//! process that starts removes those whose owner is gone. [`Slot`] is a slot
//! number unique on the host while held (an abstract socket's name), so a
//! program may derive ports from it.
//!
//! Must not: run anything but the program it is given, hand a program the
//! worker's environment, or remove a directory it did not make.

use std::{
    ffi::OsString,
    fs::File,
    io,
    os::unix::net::{SocketAddr, UnixListener},
    path::{Path, PathBuf},
    process::{ExitStatus, Stdio},
    sync::{
        atomic::{AtomicU64, Ordering},
        OnceLock,
    },
    time::Duration,
};

use nix::{sys::signal::Signal, unistd::Pid};

/// The name prefix of this process's cgroup and of the scratch directories.
const PREFIX: &str = "naofarm-";

/// What a host allows for containing a job, found once per process.
#[derive(Debug, Clone, Default)]
pub struct Host {
    /// The cgroup v2 directory this process makes its jobs' cgroups in.
    cgroup: Option<PathBuf>,
    /// `setpriv`, when it sets a parent-death signal.
    setpriv: Option<PathBuf>,
    /// `prlimit`, when it runs.
    prlimit: Option<PathBuf>,
    /// `unshare` and its flags, when it makes a PID namespace here.
    pidns: Option<Vec<OsString>>,
    /// The shell, for joining a cgroup and for a namespace's init.
    sh: PathBuf,
    /// Whether this process is its jobs' child subreaper (neither a cgroup
    /// nor a PID namespace).
    subreaper: bool,
}

static HOST: OnceLock<Host> = OnceLock::new();

impl Host {
    /// This host's mechanisms (probed on first use, then kept).
    pub fn get() -> &'static Self {
        HOST.get_or_init(Self::detect)
    }

    fn detect() -> Self {
        let weaker = std::env::var("NAOFARM_JOB_CONTAINMENT").ok();
        let sh = find("sh").unwrap_or_else(|| PathBuf::from("/bin/sh"));
        let runs = |argv: &[&std::ffi::OsStr]| {
            std::process::Command::new(argv[0])
                .args(&argv[1..])
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()
                .is_ok_and(|s| s.success())
        };
        let truth = find("true").unwrap_or_else(|| PathBuf::from("/bin/true"));
        let t = truth.as_os_str();
        let setpriv = find("setpriv").filter(|p| {
            runs(&[
                p.as_os_str(),
                "--pdeathsig".as_ref(),
                "KILL".as_ref(),
                "--".as_ref(),
                t,
            ])
        });
        let prlimit = find("prlimit")
            .filter(|p| runs(&[p.as_os_str(), "--core=0".as_ref(), "--".as_ref(), t]));
        let cgroup = match weaker.as_deref() {
            Some("pidns" | "group") => None,
            _ => own_cgroup_dir().filter(|d| watch_cgroups(&sh, d)),
        };
        let wants_pidns = cgroup.is_none() && weaker.as_deref() != Some("group");
        let pidns = find("unshare").filter(|_| wants_pidns).and_then(|u| {
            let flags: [&[&str]; 2] = [
                &["--pid", "--mount-proc", "--fork", "--kill-child"],
                &[
                    "--user",
                    "--map-current-user",
                    "--pid",
                    "--mount-proc",
                    "--fork",
                    "--kill-child",
                ],
            ];
            flags.iter().find_map(|f| {
                let mut argv: Vec<OsString> = vec![u.clone().into()];
                argv.extend(f.iter().map(OsString::from));
                argv.push("--".into());
                let mut probe: Vec<&std::ffi::OsStr> =
                    argv.iter().map(OsString::as_os_str).collect();
                probe.push(t);
                runs(&probe).then_some(argv)
            })
        });
        let subreaper = cgroup.is_none()
            && pidns.is_none()
            && nix::sys::prctl::set_child_subreaper(true).is_ok();
        Self {
            subreaper,
            cgroup,
            setpriv,
            prlimit,
            pidns,
            sh,
        }
    }

    /// What contains a job here, in a few words (for the log and the
    /// worker's status).
    #[must_use]
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        if self.cgroup.is_some() {
            parts.push("cgroup v2");
        }
        if self.pidns.is_some() {
            parts.push("PID namespace");
        }
        parts.push("process group");
        if self.subreaper {
            parts.push("child subreaper");
        }
        if self.setpriv.is_some() {
            parts.push("parent-death signal");
        }
        if self.prlimit.is_some() {
            parts.push("rlimits");
        }
        parts.join(" + ")
    }

    /// Whether a process that leaves the job's process group (`setsid`) is
    /// still killed with the job here.
    #[must_use]
    pub fn contains_daemons(&self) -> bool {
        self.cgroup.is_some() || self.pidns.is_some()
    }
}

/// An executable named `name` on this process's PATH.
fn find(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_else(|| "/usr/local/bin:/usr/bin:/bin".into());
    std::env::split_paths(&path)
        .map(|d| d.join(name))
        .find(|p| p.is_file())
}

/// The parent of process `pid`, if it lives.
fn parent(pid: u32) -> Option<u32> {
    stat_field(pid, 1)
}

/// When process `pid` started (clock ticks after boot), if it lives.
fn started(pid: u32) -> Option<u64> {
    stat_field(pid, 19)
}

/// Field `n` after the command name of `/proc/PID/stat` (0: the state).
fn stat_field<T: std::str::FromStr>(pid: u32, n: usize) -> Option<T> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name may hold spaces and parentheses: fields follow the last ')'.
    let rest = &stat[stat.rfind(')')? + 1..];
    rest.split_whitespace().nth(n)?.parse().ok()
}

/// This process's own directory for its jobs' cgroups, made beside it in its
/// cgroup v2 (`naofarm-PID-START`), after removing those of processes that
/// are gone; none where it may not make one.
fn own_cgroup_dir() -> Option<PathBuf> {
    let mine = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    let rel = mine.lines().find_map(|l| l.strip_prefix("0::"))?.trim();
    let mounts = std::fs::read_to_string("/proc/self/mountinfo").ok()?;
    let mount = mounts.lines().find_map(|l| {
        let (left, right) = l.split_once(" - ")?;
        (right.split_whitespace().next() == Some("cgroup2"))
            .then(|| left.split_whitespace().nth(4).map(PathBuf::from))?
    })?;
    let base = mount.join(rel.trim_start_matches('/'));
    sweep_cgroups(&base);
    let pid = std::process::id();
    let dir = base.join(format!("{PREFIX}{pid}-{}", started(pid)?));
    match std::fs::create_dir(&dir) {
        Ok(()) => {}
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {}
        Err(_) => return None,
    }
    if dir.join("cgroup.kill").exists() {
        Some(dir)
    } else {
        let _ = std::fs::remove_dir(&dir);
        None
    }
}

/// Starts this process's cgroup watcher: a shell outside the jobs' cgroups
/// and process groups that sleeps until this process dies (its
/// parent-death signal, SIGTERM), then kills every job cgroup in `dir` and
/// removes them. It is started from a thread that lives as long as the
/// process, since the signal follows the thread that started it. Whether it
/// runs.
fn watch_cgroups(sh: &Path, dir: &Path) -> bool {
    use std::os::unix::process::CommandExt;
    const WATCH: &str = r#"trap 'kill $! 2>/dev/null
for k in "$0"/job-*/cgroup.kill; do [ -e "$k" ] && echo 1 > "$k"; done
for _ in 1 2 3 4 5 6 7 8 9 10; do rmdir "$0"/job-* "$0" 2>/dev/null; [ -d "$0" ] || exit 0; sleep 0.1; done
exit 0' TERM
while :; do sleep 86400 & wait $!; done"#;
    let Some(setpriv) = find("setpriv") else {
        return false;
    };
    let (sh, dir) = (sh.to_path_buf(), dir.to_path_buf());
    let (tx, rx) = std::sync::mpsc::channel();
    let spawned = std::thread::Builder::new()
        .name("naofarm-cgroup-watch".into())
        .spawn(move || {
            let child = std::process::Command::new(setpriv)
                .args(["--pdeathsig", "TERM", "--"])
                .arg(&sh)
                .args(["-c", WATCH])
                .arg(&dir)
                .env_clear()
                .env("PATH", "/usr/local/bin:/usr/bin:/bin")
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .process_group(0)
                .spawn();
            let _ = tx.send(child.is_ok());
            // The watcher's signal comes when this thread ends: never
            // before the process does.
            loop {
                std::thread::park();
            }
        })
        .is_ok();
    spawned && rx.recv().unwrap_or(false)
}

/// Kills and removes the job cgroups of naofarm processes that are gone.
fn sweep_cgroups(base: &Path) {
    let Ok(entries) = std::fs::read_dir(base) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let Some((pid, start)) = name
            .strip_prefix(PREFIX)
            .and_then(|r| r.split_once('-'))
            .and_then(|(p, s)| Some((p.parse::<u32>().ok()?, s.parse::<u64>().ok()?)))
        else {
            continue;
        };
        if started(pid) == Some(start) {
            continue;
        }
        let dir = e.path();
        if let Ok(jobs) = std::fs::read_dir(&dir) {
            for j in jobs.flatten().filter(|j| j.path().is_dir()) {
                remove_cgroup(&j.path());
            }
        }
        let _ = std::fs::remove_dir(&dir);
    }
}

/// Kills every process of a job's cgroup, waits (a second at most) until it
/// is empty, and removes it.
fn remove_cgroup(dir: &Path) {
    let _ = std::fs::write(dir.join("cgroup.kill"), "1");
    for _ in 0..100 {
        if std::fs::remove_dir(dir).is_ok() || !dir.exists() {
            return;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// What a program may use: each `None` is no limit.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Limits {
    /// Address space of each process, MiB.
    pub memory_mib: Option<u64>,
    /// Processes of the program's user (the kernel's count: it binds users
    /// other than root).
    pub processes: Option<u64>,
    /// Largest file it may write, MiB.
    pub file_size_mib: Option<u64>,
    /// CPU seconds of each process.
    pub cpu_s: Option<u64>,
}

impl Limits {
    /// The defaults for a worker of `slots` slots: memory the host's over its
    /// slots, 8192 processes (the kernel counts all the user's threads),
    /// files of 16 GiB, CPU unlimited (the wall-time time-out bounds a
    /// trial).
    #[must_use]
    pub fn defaults(slots: u32) -> Self {
        let total_mib = std::fs::read_to_string("/proc/meminfo")
            .ok()
            .and_then(|m| {
                m.lines()
                    .find_map(|l| l.strip_prefix("MemTotal:"))
                    .and_then(|v| v.split_whitespace().next()?.parse::<u64>().ok())
            })
            .map(|kib| kib / 1024);
        Self {
            memory_mib: total_mib.map(|m| (m / u64::from(slots.max(1))).max(256)),
            processes: Some(8192),
            file_size_mib: Some(16 << 10),
            cpu_s: None,
        }
    }

    /// `prlimit`'s arguments for these limits.
    fn prlimit_args(&self) -> Vec<String> {
        let mut a = Vec::new();
        if let Some(m) = self.memory_mib {
            a.push(format!("--as={}", m.saturating_mul(1 << 20)));
        }
        if let Some(n) = self.processes {
            a.push(format!("--nproc={n}"));
        }
        if let Some(f) = self.file_size_mib {
            a.push(format!("--fsize={}", f.saturating_mul(1 << 20)));
        }
        if let Some(c) = self.cpu_s {
            // SIGXCPU at the soft limit; SIGKILL two seconds later.
            a.push(format!("--cpu={c}:{}", c.saturating_add(2)));
        }
        a
    }

    /// The limit a program that ended with `status` and wrote `stderr` ran
    /// into, named with its value, if it shows one.
    #[must_use]
    pub fn hit(&self, status: ExitStatus, stderr: &str) -> Option<String> {
        use std::os::unix::process::ExitStatusExt;
        // A signal, or a namespace's init reporting one as 128 + its number.
        let sig = status
            .signal()
            .or_else(|| status.code().filter(|c| *c > 128).map(|c| c - 128));
        match (sig, self) {
            (Some(24), Self { cpu_s: Some(c), .. }) => Some(format!(
                "it went over its CPU-time limit of {c} s (SIGXCPU)"
            )),
            (
                Some(25),
                Self {
                    file_size_mib: Some(f),
                    ..
                },
            ) => Some(format!(
                "it went over its file-size limit of {f} MiB (SIGXFSZ)"
            )),
            _ => {
                let low = stderr.to_lowercase();
                let memory = [
                    "memoryerror",
                    "bad_alloc",
                    "cannot allocate memory",
                    "out of memory",
                ];
                let fork = [
                    "resource temporarily unavailable",
                    "cannot fork",
                    "can't fork",
                ];
                // A program that ignores SIGXFSZ (Python does) sees EFBIG.
                let big = ["file too large", "file size limit exceeded"];
                if let (Some(f), true) = (self.file_size_mib, big.iter().any(|p| low.contains(p))) {
                    Some(format!("it went over its file-size limit of {f} MiB"))
                } else if let (Some(m), true) =
                    (self.memory_mib, memory.iter().any(|p| low.contains(p)))
                {
                    Some(format!("it ran out of memory under its limit of {m} MiB"))
                } else if let (Some(n), true) =
                    (self.processes, fork.iter().any(|p| low.contains(p)))
                {
                    Some(format!(
                        "it could not start a process under its limit of {n} processes"
                    ))
                } else {
                    None
                }
            }
        }
    }
}

/// One job: a program started under [`Host`]'s mechanisms. Dropping it
/// kills whatever of it still runs.
#[derive(Debug)]
pub struct Job {
    /// The job's first process (the program, or the tools that wrap it).
    pub child: tokio::process::Child,
    pgid: Option<Pid>,
    cgroup: Option<PathBuf>,
    /// The `NAOFARM_JOB=…` mark of its processes' environment (this
    /// process a child subreaper only).
    mark: Option<String>,
}

/// Numbers the jobs of this process (their cgroups' names).
static JOBS: AtomicU64 = AtomicU64::new(0);

impl Job {
    /// Starts `program` in `dir` with exactly `env`, under `limits`, its
    /// three standard streams piped.
    pub fn start(
        program: &Path,
        dir: &Path,
        env: &[(String, String)],
        limits: &Limits,
    ) -> io::Result<Self> {
        Self::start_with_args(program, &[], dir, env, limits)
    }

    /// [`Job::start`] with arguments.
    pub fn start_with_args(
        program: &Path,
        args: &[&str],
        dir: &Path,
        env: &[(String, String)],
        limits: &Limits,
    ) -> io::Result<Self> {
        let host = Host::get();
        let mut argv: Vec<OsString> = Vec::new();
        if let Some(s) = &host.setpriv {
            argv.extend([
                s.as_os_str().into(),
                "--pdeathsig".into(),
                "KILL".into(),
                "--".into(),
            ]);
        }
        let cgroup = match &host.cgroup {
            Some(base) => {
                let d = base.join(format!("job-{}", JOBS.fetch_add(1, Ordering::Relaxed)));
                std::fs::create_dir(&d)?;
                // The shell joins the job's cgroup, then becomes the rest.
                argv.extend([
                    host.sh.as_os_str().into(),
                    "-c".into(),
                    "echo $$ > \"$0\" && exec \"$@\"".into(),
                    d.join("cgroup.procs").into(),
                ]);
                Some(d)
            }
            None => None,
        };
        let limit_args = limits.prlimit_args();
        if let (Some(p), false) = (&host.prlimit, limit_args.is_empty()) {
            argv.push(p.as_os_str().into());
            argv.extend(limit_args.into_iter().map(OsString::from));
            argv.push("--".into());
        }
        if let Some(u) = &host.pidns {
            argv.extend(u.iter().cloned());
            // The namespace's init: a shell that runs the program and says
            // how it ended (128 + a signal's number), so the program is not
            // the init (which ignores signals it does not handle).
            argv.extend([
                host.sh.as_os_str().into(),
                "-c".into(),
                "\"$@\"; exit $?".into(),
                "naofarm-job".into(),
            ]);
        }
        argv.push(program.as_os_str().into());
        argv.extend(args.iter().map(OsString::from));
        let n = JOBS.fetch_add(1, Ordering::Relaxed);
        let mark = host
            .subreaper
            .then(|| format!("{}-{n}", std::process::id()));
        let mut cmd = tokio::process::Command::new(&argv[0]);
        cmd.args(&argv[1..])
            .env_clear()
            .envs(env.iter().map(|(k, v)| (k, v)))
            .envs(mark.iter().map(|m| ("NAOFARM_JOB", m)))
            .current_dir(dir)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .process_group(0)
            .kill_on_drop(true);
        let child = match cmd.spawn() {
            Ok(c) => c,
            Err(e) => {
                if let Some(d) = &cgroup {
                    let _ = std::fs::remove_dir(d);
                }
                return Err(e);
            }
        };
        let pgid = child
            .id()
            .and_then(|p| i32::try_from(p).ok())
            .map(Pid::from_raw);
        Ok(Self {
            child,
            pgid,
            cgroup,
            mark,
        })
    }

    /// Sends `sig` to every process of the job: its process group, and each
    /// process of its cgroup.
    pub fn signal(&self, sig: Signal) {
        if let Some(g) = self.pgid {
            let _ = nix::sys::signal::killpg(g, sig);
        }
        if let Some(d) = &self.cgroup {
            if sig == Signal::SIGKILL {
                let _ = std::fs::write(d.join("cgroup.kill"), "1");
            } else if let Ok(procs) = std::fs::read_to_string(d.join("cgroup.procs")) {
                for p in procs.lines().filter_map(|l| l.trim().parse::<i32>().ok()) {
                    let _ = nix::sys::signal::kill(Pid::from_raw(p), sig);
                }
            }
        }
        for p in self.orphans() {
            let _ = nix::sys::signal::kill(p, sig);
        }
    }

    /// The job's processes that left its group and came to this process
    /// (its child subreaper): this process's children with the job's mark.
    fn orphans(&self) -> Vec<Pid> {
        let Some(mark) = &self.mark else {
            return Vec::new();
        };
        let me = std::process::id();
        let needle = format!("NAOFARM_JOB={mark}\0");
        let Ok(procs) = std::fs::read_dir("/proc") else {
            return Vec::new();
        };
        procs
            .flatten()
            .filter_map(|e| e.file_name().to_str()?.parse::<u32>().ok())
            .filter(|&pid| parent(pid) == Some(me))
            .filter(|pid| {
                std::fs::read(format!("/proc/{pid}/environ"))
                    .is_ok_and(|env| String::from_utf8_lossy(&env).contains(&needle))
            })
            .filter_map(|pid| i32::try_from(pid).ok().map(Pid::from_raw))
            .collect()
    }

    /// Kills the job's orphans until none is left (a killed one's own
    /// children come next), and reaps them: a second at most.
    async fn reap_orphans(&self) {
        use nix::sys::wait::{waitpid, WaitPidFlag, WaitStatus};
        let mut killed: Vec<Pid> = Vec::new();
        for _ in 0..100 {
            for p in self.orphans() {
                let _ = nix::sys::signal::kill(p, Signal::SIGKILL);
                if !killed.contains(&p) {
                    killed.push(p);
                }
            }
            killed.retain(|p| {
                matches!(
                    waitpid(*p, Some(WaitPidFlag::WNOHANG)),
                    Ok(WaitStatus::StillAlive)
                )
            });
            if killed.is_empty() && self.orphans().is_empty() {
                return;
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    }

    /// Asks the job to stop (SIGTERM to every process), waits up to `grace`
    /// for its first process to end, then kills what is left.
    pub async fn stop(&mut self, grace: Duration) {
        self.signal(Signal::SIGTERM);
        let _ = tokio::time::timeout(grace, self.child.wait()).await;
        self.end().await;
    }

    /// Kills whatever of the job still runs, reaps its first process and
    /// removes its cgroup.
    pub async fn end(&mut self) {
        self.signal(Signal::SIGKILL);
        let _ = self.child.kill().await;
        self.reap_orphans().await;
        // Reaped: its group id may name another process's group from now on.
        self.pgid = None;
        if let Some(d) = self.cgroup.take() {
            let _ = tokio::task::spawn_blocking(move || remove_cgroup(&d)).await;
        }
    }
}

impl Drop for Job {
    fn drop(&mut self) {
        self.signal(Signal::SIGKILL);
        if let Some(d) = &self.cgroup {
            // Empty once the kernel has delivered the kill; a cgroup still
            // busy here goes with this process's directory later.
            let _ = std::fs::remove_dir(d);
        }
    }
}

/// A directory of its owner's (`naofarm-KIND-…` in the temporary
/// directory), held by a lock for the owner's life and removed when it is
/// dropped; [`Scratch::create`] first removes those whose owner is gone.
#[derive(Debug)]
pub struct Scratch {
    dir: PathBuf,
    _lock: File,
}

/// The lock file inside a scratch directory.
const LOCK: &str = ".naofarm-lock";

impl Scratch {
    /// A new scratch directory `naofarm-KIND-ID` in the temporary directory.
    pub fn create(kind: &str, id: &str) -> io::Result<Self> {
        let tmp = std::env::temp_dir();
        Self::sweep(&tmp, kind);
        let dir = tmp.join(format!("{PREFIX}{kind}-{id}"));
        std::fs::create_dir_all(&dir)?;
        let lock = File::create(dir.join(LOCK))?;
        lock.try_lock()
            .map_err(|e| io::Error::other(e.to_string()))?;
        Ok(Self { dir, _lock: lock })
    }

    /// The directory.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// Removes the `naofarm-KIND-*` directories in `tmp` whose lock no
    /// process holds (their owner is gone). A directory without a lock file
    /// is not known to be ours and stays.
    pub fn sweep(tmp: &Path, kind: &str) {
        let Ok(entries) = std::fs::read_dir(tmp) else {
            return;
        };
        let prefix = format!("{PREFIX}{kind}-");
        for e in entries.flatten() {
            if !e.file_name().to_string_lossy().starts_with(&prefix) {
                continue;
            }
            let dir = e.path();
            let Ok(lock) = File::open(dir.join(LOCK)) else {
                continue;
            };
            if lock.try_lock().is_ok() {
                tracing::info!(dir = %dir.display(), "removing the scratch space of a naofarm process that is gone");
                let _ = std::fs::remove_dir_all(&dir);
            }
        }
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if let Err(e) = std::fs::remove_dir_all(&self.dir) {
            if e.kind() != io::ErrorKind::NotFound {
                tracing::warn!(dir = %self.dir.display(), error = %e, "scratch space not removed");
            }
        }
    }
}

/// A slot number no other holder on this host has while this is held (the
/// name of an abstract socket, released by the kernel with its holder).
#[derive(Debug)]
pub struct Slot {
    /// The number.
    pub n: u32,
    _name: UnixListener,
}

impl Slot {
    /// The lowest slot number free on this host.
    pub fn claim() -> io::Result<Self> {
        Self::claim_preferring(&[])
    }

    /// The first of `preferred` free on this host, else the lowest free
    /// slot number. A worker prefers the slots it keeps programs in, so
    /// that workers sharing a host do not each keep one in every slot.
    pub fn claim_preferring(preferred: &[u32]) -> io::Result<Self> {
        for &n in preferred {
            if let Some(slot) = Self::bind(n)? {
                return Ok(slot);
            }
        }
        for n in 0..65_536 {
            if let Some(slot) = Self::bind(n)? {
                return Ok(slot);
            }
        }
        Err(io::Error::other(
            "all 65536 slot numbers of this host are taken",
        ))
    }

    /// Slot `n`, or `None` when another process holds it.
    fn bind(n: u32) -> io::Result<Option<Self>> {
        use std::os::linux::net::SocketAddrExt;
        let addr = SocketAddr::from_abstract_name(format!("naofarm-slot-{n}").as_bytes())?;
        match UnixListener::bind_addr(&addr) {
            Ok(l) => Ok(Some(Self { n, _name: l })),
            Err(e) if e.kind() == io::ErrorKind::AddrInUse => Ok(None),
            Err(e) => Err(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_held_at_once_differ_and_come_back() {
        let a = Slot::claim().expect("a slot");
        let b = Slot::claim().expect("another");
        assert_ne!(a.n, b.n);
        let n = a.n;
        drop(a);
        let c = Slot::claim().expect("again");
        assert!(c.n <= n || c.n != b.n);
    }

    #[test]
    fn a_preferred_slot_is_claimed_when_free_and_passed_when_held() {
        // A number far above what lowest-free claims reach, free.
        let far = 60_000 + std::process::id() % 5_000;
        let a = Slot::claim_preferring(&[far]).expect("the preferred slot");
        assert_eq!(a.n, far);
        // Held: the preference passes it (and the next preferred) for a
        // free one.
        let b = Slot::claim_preferring(&[far, far]).expect("another slot");
        assert_ne!(b.n, far);
        drop(a);
        let c = Slot::claim_preferring(&[far]).expect("the preferred slot again");
        assert_eq!(c.n, far);
    }

    #[test]
    fn a_limit_is_named_by_how_the_program_ended() {
        use std::os::unix::process::ExitStatusExt;
        let l = Limits {
            memory_mib: Some(100),
            processes: Some(10),
            file_size_mib: Some(1),
            cpu_s: Some(3),
        };
        let by_code = |c: i32| ExitStatus::from_raw(c << 8);
        let by_signal = ExitStatus::from_raw;
        assert!(l
            .hit(by_code(152), "")
            .unwrap()
            .contains("CPU-time limit of 3 s"));
        assert!(l.hit(by_signal(24), "").unwrap().contains("CPU-time"));
        assert!(l
            .hit(by_code(153), "")
            .unwrap()
            .contains("file-size limit of 1 MiB"));
        assert!(l
            .hit(by_code(1), "Traceback …\nMemoryError")
            .unwrap()
            .contains("memory under its limit of 100 MiB"));
        assert!(l
            .hit(by_code(1), "OSError: [Errno 27] File too large")
            .unwrap()
            .contains("file-size limit of 1 MiB"));
        assert_eq!(l.hit(by_code(1), "the simulator crashed"), None);
        assert_eq!(Limits::default().hit(by_code(152), ""), None);
    }

    #[test]
    fn a_dead_owners_scratch_is_swept_and_a_live_ones_kept() {
        let tmp = tempdir();
        let live = tmp.join(format!("{PREFIX}t-live"));
        let dead = tmp.join(format!("{PREFIX}t-dead"));
        let foreign = tmp.join(format!("{PREFIX}t-foreign"));
        for d in [&live, &dead, &foreign] {
            std::fs::create_dir_all(d).expect("a dir");
        }
        let held = File::create(live.join(LOCK)).expect("lock");
        held.try_lock().expect("locked");
        File::create(dead.join(LOCK)).expect("lock");
        Scratch::sweep(&tmp, "t");
        assert!(live.exists() && foreign.exists() && !dead.exists());
        let _ = std::fs::remove_dir_all(&tmp);
    }

    fn tempdir() -> PathBuf {
        let d = std::env::temp_dir().join(format!("naofarm-jobtest-{}", uuid::Uuid::new_v4()));
        std::fs::create_dir_all(&d).expect("a temporary dir");
        d
    }
}
