//! Local CLOP tuning of any noisy program (`naofarm clop`), no zenoh involved:
//! the evaluator is either one long-lived process speaking lines or one
//! process per game (CLOP's classic contract); an optional JSON-lines log of
//! every game is replayed on restart so that a resumed tuning asks exactly
//! what an uninterrupted one would. This module does I/O (child processes, the
//! log file); the optimiser it drives ([`coordinator::clop`]) stays pure.

use std::{
    io::{BufRead, BufReader, Write},
    path::Path,
    process::{Child, ChildStdin, Command, Stdio},
    sync::mpsc,
    time::Duration,
};

use coordinator::clop::{Clop, Dim, Outcome};
use protocol::experiment::{ClopSettings, ParamKind};
use protocol::seed::mix;
use serde::{Deserialize, Serialize};

/// What went wrong, with the context it happened in (outermost first).
#[derive(Debug)]
pub struct Message(String);

impl std::fmt::Display for Message {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl<E: std::error::Error> From<E> for Message {
    fn from(e: E) -> Self {
        Self(e.to_string())
    }
}

type Result<T, E = Message> = std::result::Result<T, E>;

macro_rules! msg {
    ($($t:tt)*) => {
        Message(format!($($t)*))
    };
}

macro_rules! bail {
    ($($t:tt)*) => {
        return Err(msg!($($t)*))
    };
}

/// Adds what was being done to an error.
trait Context<T> {
    fn with_context(self, what: impl FnOnce() -> String) -> Result<T>;
}

impl<T, E: Into<Message>> Context<T> for std::result::Result<T, E> {
    fn with_context(self, what: impl FnOnce() -> String) -> Result<T> {
        self.map_err(|e| Message(format!("{}: {}", what(), e.into())))
    }
}

/// One tuned parameter: `NAME:KIND:LO:HI` on the command line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Param {
    /// Its name (what a script receives).
    pub name: String,
    /// Mapping kind.
    pub kind: ParamKind,
    /// Lower bound, external units.
    pub lo: f64,
    /// Upper bound, external units.
    pub hi: f64,
}

/// Parses `NAME:KIND:LO:HI` (KIND: linear, integer, gamma, integer_gamma).
pub fn parse_param(s: &str) -> Result<Param> {
    let parts: Vec<&str> = s.split(':').collect();
    let [name, kind, lo, hi] = parts.as_slice() else {
        bail!("--param `{s}`: expected NAME:KIND:LO:HI");
    };
    if name.is_empty() || name.chars().any(char::is_whitespace) {
        bail!("--param `{s}`: the name must be non-empty, without spaces");
    }
    let kind = match *kind {
        "linear" => ParamKind::Linear,
        "integer" => ParamKind::Integer,
        "gamma" => ParamKind::Gamma,
        "integer_gamma" => ParamKind::IntegerGamma,
        k => bail!("--param `{s}`: unknown kind `{k}` (linear, integer, gamma, integer_gamma)"),
    };
    let num = |what: &str, v: &str| -> Result<f64> {
        let x: f64 = v
            .parse()
            .map_err(|_| msg!("--param `{s}`: {what} `{v}` is not a number"))?;
        if !x.is_finite() {
            bail!("--param `{s}`: {what} must be finite");
        }
        Ok(x)
    };
    let (lo, hi) = (num("LO", lo)?, num("HI", hi)?);
    if lo > hi {
        bail!("--param `{s}`: LO {lo} exceeds HI {hi}");
    }
    if matches!(kind, ParamKind::Gamma | ParamKind::IntegerGamma) && lo <= 0.0 {
        bail!("--param `{s}`: a gamma parameter needs LO > 0");
    }
    if matches!(kind, ParamKind::Integer | ParamKind::IntegerGamma)
        && (lo.fract() != 0.0 || hi.fract() != 0.0)
    {
        bail!("--param `{s}`: an integer parameter needs integer bounds");
    }
    Ok(Param {
        name: (*name).to_string(),
        kind,
        lo,
        hi,
    })
}

/// The log's first line: what the games belong to.
#[derive(Debug, PartialEq, Serialize, Deserialize)]
struct Header {
    naofarm_clop_log: u32,
    params: Vec<Param>,
    seed: u64,
    draw_elo: f64,
}

/// One game of the log.
#[derive(Debug, Serialize, Deserialize)]
struct Game {
    game: u64,
    seed: u64,
    /// CLOP's internal coordinates (replayed exactly).
    u: Vec<f64>,
    /// External values, as the evaluator saw them.
    values: Vec<f64>,
    result: char,
}

fn outcome(answer: &str) -> Option<(Outcome, char)> {
    match answer.trim() {
        "W" => Some((Outcome::Win, 'W')),
        "D" => Some((Outcome::Draw, 'D')),
        "L" => Some((Outcome::Loss, 'L')),
        _ => None,
    }
}

/// Opens (or creates) the log, replays its games into `clop`; returns the
/// file for appending and the number of games replayed.
fn open_log(path: &Path, header: &Header, clop: &mut Clop) -> Result<(std::fs::File, u64)> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
        Err(e) => return Err(e).with_context(|| format!("--log {}", path.display())),
    };
    let mut keep = 0; // bytes of whole, valid lines
    let mut games = 0u64;
    if !text.is_empty() {
        let mut lines = text.split_inclusive('\n');
        let first = lines.next().unwrap_or_default();
        let h: Header = serde_json::from_str(first.trim_end()).with_context(|| {
            format!(
                "--log {}: the first line is not a naofarm clop log header",
                path.display()
            )
        })?;
        if &h != header {
            bail!(
                "--log {}: written for other parameters, seed or DrawElo; use another log",
                path.display()
            );
        }
        keep = first.len();
        for (i, line) in lines.enumerate() {
            let last = !line.ends_with('\n');
            let parsed = serde_json::from_str::<Game>(line.trim_end())
                .map_err(|e| e.to_string())
                .and_then(|g| {
                    let o = outcome(&g.result.to_string()).ok_or("result is not W, D or L")?;
                    if g.game != games {
                        return Err(format!("game {} where {games} was expected", g.game));
                    }
                    if g.u.len() != header.params.len()
                        || g.u.iter().any(|u| !(-1.0..=1.0).contains(u))
                    {
                        return Err("u does not fit the parameters".into());
                    }
                    Ok((g, o.0))
                });
            match (parsed, last) {
                (Ok((g, o)), false) => {
                    clop.replay(&g.u, o);
                    games += 1;
                    keep += line.len();
                }
                // A torn last line: its game is played again.
                (_, true) => {
                    eprintln!(
                        "warning: --log {}: dropped a torn last line",
                        path.display()
                    );
                }
                (Err(e), false) => {
                    bail!("--log {}: line {} is damaged: {e}", path.display(), i + 2)
                }
            }
        }
    }
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .read(true)
        .write(true)
        .truncate(false)
        .open(path)
        .with_context(|| format!("--log {}", path.display()))?;
    file.set_len(keep as u64)?;
    use std::io::Seek;
    file.seek(std::io::SeekFrom::End(0))?;
    if keep == 0 {
        writeln!(file, "{}", serde_json::to_string(header)?)?;
    }
    Ok((file, games))
}

/// How games are played.
enum Evaluator {
    /// One process, one line per game.
    Lines {
        child: Child,
        stdin: ChildStdin,
        answers: mpsc::Receiver<String>,
    },
    /// One process per game.
    Script(String),
}

fn shell(cmd: &str) -> Command {
    let mut c = Command::new("sh");
    c.arg("-c").arg(cmd);
    #[cfg(unix)]
    {
        use std::os::unix::process::CommandExt;
        // Its own process group, so that a hung evaluator dies with its children.
        c.process_group(0);
    }
    c
}

fn kill_group(child: &mut Child) {
    #[cfg(unix)]
    {
        let _ = Command::new("kill")
            .args(["-KILL", "--", &format!("-{}", child.id())])
            // A group that has ended already is no news.
            .stderr(std::process::Stdio::null())
            .status();
    }
    let _ = child.kill();
    let _ = child.wait();
}

/// Reads `out` line by line into a channel (ends when the pipe closes).
fn line_reader(out: impl std::io::Read + Send + 'static) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}

impl Evaluator {
    fn start(how: &Games) -> Result<Self> {
        if let Games::Lines(cmd) = how {
            let mut child = shell(cmd)
                .stdin(Stdio::piped())
                .stdout(Stdio::piped())
                .spawn()
                .with_context(|| format!("cannot start the evaluator `{cmd}`"))?;
            let stdin = child.stdin.take().ok_or_else(|| msg!("evaluator stdin"))?;
            let stdout = child
                .stdout
                .take()
                .ok_or_else(|| msg!("evaluator stdout"))?;
            Ok(Self::Lines {
                child,
                stdin,
                answers: line_reader(stdout),
            })
        } else if let Games::Script(script) = how {
            Ok(Self::Script(script.clone()))
        } else {
            bail!("no evaluator")
        }
    }

    fn play(
        &mut self,
        game: u64,
        seed: u64,
        names: &[String],
        values: &[f64],
        timeout: Duration,
    ) -> Result<(Outcome, char)> {
        match self {
            Self::Lines {
                child,
                stdin,
                answers,
            } => {
                let mut line = format!("{game} {seed}");
                for v in values {
                    line += &format!(" {v}");
                }
                if writeln!(stdin, "{line}")
                    .and_then(|()| stdin.flush())
                    .is_err()
                {
                    let status = child.try_wait().ok().flatten();
                    bail!("the evaluator stopped ({status:?}) before game {game}");
                }
                match answers.recv_timeout(timeout) {
                    Ok(answer) => outcome(&answer).ok_or_else(|| {
                        msg!("the evaluator answered `{answer}` to game {game}; expected W, D or L")
                    }),
                    Err(mpsc::RecvTimeoutError::Timeout) => {
                        kill_group(child);
                        bail!(
                            "the evaluator did not answer game {game} within {} s; it was killed",
                            timeout.as_secs_f64()
                        )
                    }
                    Err(mpsc::RecvTimeoutError::Disconnected) => {
                        let status = child
                            .wait()
                            .map_or_else(|e| format!("its status unknown: {e}"), |s| s.to_string());
                        bail!("the evaluator exited ({status}) without answering game {game}")
                    }
                }
            }
            Self::Script(script) => {
                let mut args = vec!["local".to_string(), seed.to_string()];
                for (n, v) in names.iter().zip(values) {
                    args.push(n.clone());
                    args.push(v.to_string());
                }
                let mut child = shell(&format!("{script} \"$@\""))
                    .arg("naofarm-clop")
                    .args(&args)
                    .stdin(Stdio::null())
                    .stdout(Stdio::piped())
                    .spawn()
                    .with_context(|| format!("cannot start the script `{script}`"))?;
                let stdout = child.stdout.take().ok_or_else(|| msg!("script stdout"))?;
                let lines = line_reader(stdout);
                let deadline = std::time::Instant::now() + timeout;
                let mut last = None;
                loop {
                    let left = deadline.saturating_duration_since(std::time::Instant::now());
                    match lines.recv_timeout(left) {
                        Ok(l) if !l.trim().is_empty() => last = Some(l),
                        Ok(_) => {}
                        Err(mpsc::RecvTimeoutError::Disconnected) => break,
                        Err(mpsc::RecvTimeoutError::Timeout) => {
                            kill_group(&mut child);
                            bail!(
                                "the script did not finish game {game} within {} s; it was killed",
                                timeout.as_secs_f64()
                            );
                        }
                    }
                }
                let status = child.wait()?;
                let last = last.unwrap_or_default();
                outcome(&last).ok_or_else(|| {
                    msg!("the script's last line for game {game} is `{last}` ({status}); expected W, L or D")
                })
            }
        }
    }
}

impl Drop for Evaluator {
    fn drop(&mut self) {
        if let Self::Lines { child, .. } = self {
            kill_group(child);
        }
    }
}

/// How games are played.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Games {
    /// A command started once: reads `<game> <seed> <v1> <v2> …`, answers `W`, `D` or `L`.
    Lines(String),
    /// A command run per game with `<processor> <seed> <name1> <value1> …`; its last line decides.
    Script(String),
}

/// A tuning job.
#[derive(Debug, Clone)]
pub struct Tuning {
    /// The parameters, in order.
    pub params: Vec<Param>,
    /// Games to play in all (a resumed log's games count).
    pub budget: u64,
    /// Seed of CLOP's sampler and of the games' seeds.
    pub seed: u64,
    /// The evaluator.
    pub games: Games,
    /// The log, if any.
    pub log: Option<std::path::PathBuf>,
    /// How long one game may take.
    pub timeout: Duration,
    /// CLOP's DrawElo.
    pub draw_elo: f64,
}

/// Why a tuning stopped.
#[derive(Debug, thiserror::Error)]
pub enum TuneError {
    /// The job itself is malformed (parameters, log of other parameters…).
    #[error("{0}")]
    Bad(Message),
    /// Games failed (the evaluator died, hung or answered nonsense); the log keeps those played.
    #[error("{0}")]
    Failed(Message),
}

/// Plays the tuning to its budget; returns the optimiser (its `mean`, `max`
/// and `counts` are the answer).
pub fn tune(t: &Tuning) -> Result<Clop, TuneError> {
    let bad = |m: String| TuneError::Bad(Message(m));
    for (i, p) in t.params.iter().enumerate() {
        if t.params[..i].iter().any(|q| q.name == p.name) {
            return Err(bad(format!("--param `{}` is given twice", p.name)));
        }
    }
    if t.params.is_empty() {
        return Err(bad("give at least one --param".into()));
    }
    if t.budget == 0 {
        return Err(bad("--budget must be at least 1".into()));
    }
    if t.timeout.is_zero() {
        return Err(bad(
            "--timeout-s must be a positive number of seconds".into()
        ));
    }
    if !(t.draw_elo.is_finite() && t.draw_elo >= 0.0) {
        return Err(bad("--draw-elo must be finite and not negative".into()));
    }
    let dims: Vec<Dim> = t
        .params
        .iter()
        .map(|p| Dim {
            kind: p.kind,
            lo: p.lo,
            hi: p.hi,
        })
        .collect();
    let settings = ClopSettings {
        draw_elo: t.draw_elo,
        ..ClopSettings::default()
    };
    let mut clop = Clop::new(dims, settings);
    let header = Header {
        naofarm_clop_log: 1,
        params: t.params.clone(),
        seed: t.seed,
        draw_elo: t.draw_elo,
    };
    let (mut log, mut played) = match &t.log {
        Some(path) => {
            let (f, n) = open_log(path, &header, &mut clop).map_err(TuneError::Bad)?;
            (Some(f), n)
        }
        None => (None, 0),
    };
    let names: Vec<String> = t.params.iter().map(|p| p.name.clone()).collect();
    let result = (|| -> Result<()> {
        if played >= t.budget {
            return Ok(());
        }
        let mut evaluator = Evaluator::start(&t.games)?;
        while played < t.budget {
            let u = clop.ask(mix(t.seed ^ 0xC10F ^ mix(played)));
            let values = clop.to_external(&u);
            let seed = mix(t.seed ^ mix(played + 1));
            let (o, c) = evaluator.play(played, seed, &names, &values, t.timeout)?;
            if let Some(f) = log.as_mut() {
                let g = Game {
                    game: played,
                    seed,
                    u: u.clone(),
                    values,
                    result: c,
                };
                writeln!(f, "{}", serde_json::to_string(&g)?)?;
                f.flush()?;
            }
            clop.tell(&u, o);
            played += 1;
        }
        Ok(())
    })();
    if let Err(e) = result {
        let kept = t
            .log
            .as_ref()
            .map(|p| format!("; the {played} games played are in {}", p.display()))
            .unwrap_or_default();
        return Err(TuneError::Failed(msg!("after {played} games{kept}: {e}")));
    }
    Ok(clop)
}
