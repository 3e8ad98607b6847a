//! Every command-line type (clap): the commands and their arguments. A leaf:
//! it uses no command module.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

/// A distributed trial farm that co-evolves a simulated NAO's body and walk.
#[derive(Parser)]
#[command(name = "naofarm", version, about)]
pub struct Cli {
    /// The command.
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// All in one: a coordinator and local workers over zenoh on loopback.
    Run {
        #[command(flatten)]
        job: JobArgs,
        /// Local workers to start (each with one slot); default: one per core.
        #[arg(long)]
        workers: Option<u32>,
        /// Print one JSON line per event instead of the progress view.
        #[arg(long)]
        json: bool,
        /// The loopback endpoint to serve on (default: a free port), e.g. tcp/127.0.0.1:7447,
        /// so that `naofarm watch` can be pointed at it.
        #[arg(long, value_name = "ENDPOINT")]
        listen: Option<String>,
        /// Mutual TLS with the certificates in DIR (`naofarm certs DIR`): the
        /// local workers and every watcher connect with a certificate of that
        /// CA, and the roles are enforced (`--listen` must be tls/127.0.0.1:PORT).
        #[arg(long, value_name = "DIR")]
        tls: Option<PathBuf>,
        #[command(flatten)]
        programs: ProgramArgs,
    },
    /// The coordinator alone (cluster use): owns the run, its journal and dispatch.
    Coordinator {
        #[command(flatten)]
        job: JobArgs,
        #[command(flatten)]
        net: NetArgs,
        /// Print one JSON line per decided iteration.
        #[arg(long)]
        json: bool,
    },
    /// A stateless worker (cluster use): runs trials for any coordinator it reaches.
    Worker {
        #[command(flatten)]
        net: NetArgs,
        /// Trials run at once (default: cores).
        #[arg(long)]
        slots: Option<u32>,
        /// Minimum wall time per trial in ms (paces the synthetic model for farm tests and benchmarks).
        #[arg(long, default_value_t = 0)]
        min_trial_ms: u64,
        /// Heartbeat interval to each run it holds trials of, ms (keep it
        /// well under the coordinators' --silence-s).
        #[arg(long, default_value_t = 500)]
        heartbeat_ms: u64,
        #[command(flatten)]
        limits: WorkerLimits,
        #[command(flatten)]
        programs: ProgramArgs,
    },
    /// A zenoh router inside naofarm (cluster use): runs, workers and watchers meet on it.
    Router {
        /// Listen on this endpoint (repeatable; default tcp/0.0.0.0:7447, tls/0.0.0.0:7447 with --tls).
        #[arg(long = "listen", value_name = "ENDPOINT")]
        listen: Vec<String>,
        /// A zenoh configuration file in zenohd's json5 format; flags override it.
        #[arg(long = "config", value_name = "FILE")]
        config: Option<PathBuf>,
        /// Mutual TLS with the router certificate in DIR (`naofarm certs DIR`).
        #[arg(long, value_name = "DIR")]
        tls: Option<PathBuf>,
    },
    /// This host's worker fingerprint (the hash of fixed probe trials and the
    /// naofarm version): workers of one fingerprint return the same bits.
    Fingerprint,
    /// Create a CA and one certificate per role (coordinator, worker, watcher, router) for --tls.
    Certs {
        /// Where the PEM files go (keys with mode 0600).
        dir: PathBuf,
        /// More certificates of a role, ROLE:NAME (repeatable), e.g. worker:node7.
        #[arg(long = "name", value_name = "ROLE:NAME")]
        names: Vec<String>,
        /// Host names or addresses the servers (router, listening coordinator) are reached by
        /// (repeatable; 127.0.0.1 and localhost are always in).
        #[arg(long = "host", value_name = "HOST")]
        hosts: Vec<String>,
        /// Validity in days.
        #[arg(long, default_value_t = 365)]
        days: u32,
        /// Replace existing files (keys included).
        #[arg(long)]
        force: bool,
        /// Test hook: certificates that expired yesterday (the CA stays valid).
        #[arg(long, hide = true)]
        expired: bool,
    },
    /// Pause, resume, stop a run or change its priority, from any machine while it runs.
    Ctl {
        /// The run: its id, the start of its id, or its name if no other live run has it.
        run: String,
        /// pause | resume | stop | priority N
        #[arg(value_name = "ACTION")]
        action: Vec<String>,
        #[command(flatten)]
        net: NetArgs,
        /// Give up when no coordinator answers within this many seconds.
        #[arg(long, default_value_t = 10.0)]
        timeout_s: f64,
    },
    /// Print the rebuilt robot: mass, segment lengths, hip-to-sole height, joint table.
    Model {
        /// League robot type 0–4.
        #[arg(long = "type", default_value_t = 0)]
        robot_type: u8,
        /// Override a morphology quantity, NAME=VALUE (repeatable), e.g. ThighRelHip2_Z=-0.05.
        #[arg(long = "param", value_name = "NAME=VALUE")]
        params: Vec<String>,
        /// Machine-readable output.
        #[arg(long, conflicts_with = "simspark")]
        json: bool,
        /// Print the body as an entry of SimSpark's naorobottypes.rb, to try it
        /// on the league's server (rcssserver3d).
        #[arg(long)]
        simspark: bool,
    },
    /// Hold a standing posture with the servos; report falls and torso height.
    Stand(StandArgs),
    /// Run n walking trials of one parameter set locally; print the Table IV row.
    Trial(TrialArgs),
    /// Benchmarks: `bench clop` (regret and cost), `bench sim` (physics speed), `bench farm`
    /// (trials/s through real processes), `bench fleet` (one fleet, many runs).
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Tune any noisy program locally with CLOP (an evaluator process or a script per game).
    Clop(ClopArgs),
    /// Follow a run from any machine (live view or JSON lines); without RUN, list the runs.
    Watch(WatchArgs),
    /// Serve a live web page of the fleet: every run, worker and figure.
    Web(WebArgs),
    /// Print a run's decided history H (iteration, p, s, mx, my, ex, ey, decision, best).
    History {
        /// The run directory.
        dir: PathBuf,
        /// An array of JSON rows.
        #[arg(long)]
        json: bool,
        /// Comma-separated values with a header line.
        #[arg(long)]
        csv: bool,
    },
    /// What a run found: figures (SVG), Table IV (Markdown, JSON) and an index.html.
    Report {
        /// The run directories (only read; a running run is read as it stands); with
        /// several, each gets its report and one page puts them side by side.
        #[arg(required = true)]
        dirs: Vec<PathBuf>,
        /// Where to write (default with one run: DIR/report; required with several).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Trials per Table IV column (Expert, Optim.1, Optim.2), seeds 777, 778, …
        #[arg(long, default_value_t = 100)]
        trials: u32,
        /// Threads for Table IV's trials (default: cores).
        #[arg(long)]
        threads: Option<usize>,
        /// A program run's Table IV runs its program, as a worker does.
        #[command(flatten)]
        programs: ProgramArgs,
    },
    /// Verify a run's journal (`check`) or copy its valid records into a new run (`salvage`).
    #[command(subcommand)]
    Journal(JournalCommand),
    /// Validate an experiment file and print it as parsed.
    Check {
        /// The experiment file (TOML).
        experiment: PathBuf,
        /// Print the parsed experiment as JSON.
        #[arg(long)]
        json: bool,
    },
}

/// What `run` and `coordinator` share: the experiment, the run directory, overrides.
#[derive(clap::Args, Debug, Clone)]
pub struct JobArgs {
    /// The experiment file (TOML).
    pub experiment: PathBuf,
    /// The run directory (journal); an existing one is resumed.
    #[arg(long)]
    pub out: PathBuf,
    /// Override the number of iterations.
    #[arg(long)]
    pub iterations: Option<u64>,
    /// Override the seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Override the trial model (`nao` or `synthetic`).
    #[arg(long)]
    pub model: Option<String>,
    /// Start from an earlier run's history (its run directory).
    #[arg(long)]
    pub from: Option<PathBuf>,
    /// Seconds a trial stays with a worker that stops naming it in its
    /// heartbeat before it is given to another (a worker renews the leases
    /// of the trials it runs).
    #[arg(long, default_value_t = 120.0)]
    pub lease_s: f64,
    /// A worker not heard from (work request, heartbeat, outcome) for this
    /// long is silent; after four such periods its trials are offered again.
    #[arg(long, default_value_t = 3.0)]
    pub silence_s: f64,
    /// Distinct workers that may fail one trial before the run stops (1–100;
    /// a resumed run may raise it to retry the trial that stopped it).
    #[arg(long, default_value_t = 3)]
    pub max_trial_failures: u32,
    /// The run's priority, 1..=1000: its share of a shared fleet follows it
    /// (default 1 for a new run; a resumed run keeps its journaled priority
    /// unless this is given).
    #[arg(long)]
    pub priority: Option<u32>,
}

/// Benchmarks.
#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// CLOP: simple regret on the test problems beside baselines, and cost per step.
    Clop(ClopBenchArgs),
    /// The rebuilt NAO: real-time factor and physics steps/s, standing and walking, per settings.
    Sim(SimBenchArgs),
    /// The farm: trials/s and coordinator CPU per trial through real processes on loopback.
    Farm(FarmBenchArgs),
    /// One fleet, many runs: utilisation, trials/s, shares by priority, coordinator CPU
    /// per trial and dispatch latency through one `naofarm router` on loopback.
    Fleet(FleetBenchArgs),
}

/// Arguments of `bench fleet`.
#[derive(Args, Debug)]
pub struct FleetBenchArgs {
    /// Runs (each its own coordinator process).
    #[arg(long, default_value_t = 20)]
    pub runs: usize,
    /// Worker processes.
    #[arg(long, default_value_t = 100)]
    pub workers: u32,
    /// Slots per worker.
    #[arg(long, default_value_t = 10)]
    pub slots: u32,
    /// Wall time of every (synthetic) trial, ms.
    #[arg(long, default_value_t = 1000)]
    pub trial_ms: u64,
    /// Iterations per run. The shares are measured while every run has trials
    /// ready, i.e. until the first run ends: at the defaults 600 iterations
    /// give a window of about 82 s; 300 give 41 s and 100 give 13 s, over
    /// which the window's own noise spreads the worst share error by about
    /// ±3 % and ±10 % (docs/fleet.md).
    #[arg(long, default_value_t = 600)]
    pub iterations: u64,
    /// Trials per iteration.
    #[arg(long, default_value_t = 10)]
    pub trials: u32,
    /// Pipeline depth of every run.
    #[arg(long, default_value_t = 8)]
    pub depth: u32,
    /// Priorities, given to the runs in turn.
    #[arg(long, default_value = "1,2,3", value_delimiter = ',')]
    pub priorities: Vec<u32>,
    /// Where the runs' journals go (default /dev/shm when there is one: the
    /// bench measures the farm, not the disk).
    #[arg(long)]
    pub dir: Option<std::path::PathBuf>,
    /// Start the runs this many ms apart (0: all at once). With trials of a
    /// fixed time, the phases the fleet's slots take at the start stay for
    /// the whole bench (docs/fleet.md).
    #[arg(long, default_value_t = 0)]
    pub stagger_ms: u64,
    /// Give up after this many seconds.
    #[arg(long, default_value_t = 1800)]
    pub timeout_s: u64,
    /// Run the bench twice, the second time with `naofarm web` serving an
    /// open page (its feed read, its run data and a figure fetched as they
    /// change): the page server's CPU and the coordinators' CPU per trial
    /// with and without it.
    #[arg(long)]
    pub web: bool,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `bench clop`.
#[derive(Args, Debug)]
pub struct ClopBenchArgs {
    /// Problem (log, flat, power, angle, step, rosenbrock, correlated, log2, log5, rosenbrock2, rosenbrock5, correlated2, or all).
    #[arg(long, default_value = "log")]
    pub problem: String,
    /// Budgets in games, comma-separated.
    #[arg(long, default_value = "100,1000", value_delimiter = ',')]
    pub budgets: Vec<u64>,
    /// Independent runs per problem and algorithm.
    #[arg(long, default_value_t = 50)]
    pub runs: usize,
    /// Seed of the outcome streams and samplers.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Algorithms, comma-separated (clop, cmaes, random).
    #[arg(long, default_value = "clop,cmaes,random", value_delimiter = ',')]
    pub algorithms: Vec<String>,
    /// Also measure the cost of one tell+ask at n = 100, 1000, 5000 for d = 1, 5 and 8.
    #[arg(long)]
    pub cost: bool,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `bench farm`.
#[derive(Args, Debug)]
pub struct FarmBenchArgs {
    /// Worker processes (one slot each) for the zero-cost synthetic runs.
    #[arg(long, default_value = "1,4,16", value_delimiter = ',')]
    pub workers: Vec<u32>,
    /// Iterations of each synthetic run (10 trials each, pipeline depth 4).
    #[arg(long, default_value_t = 150)]
    pub iterations: u64,
    /// Iterations of the NAO runs with 1 and 2 workers (0: skip them).
    #[arg(long, default_value_t = 4)]
    pub nao_iterations: u64,
    /// The experiment whose space and constants the runs use (the model is set per case).
    #[arg(long, default_value = "experiments/physical-technical.toml")]
    pub experiment: std::path::PathBuf,
    /// Run every case twice: over plain TCP and over mutual TLS (certificates
    /// made by `naofarm certs` in a temporary directory), to show what TLS costs.
    #[arg(long)]
    pub tls: bool,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
}

/// The journal commands.
#[derive(Subcommand, Debug)]
pub enum JournalCommand {
    /// Verify every frame of a run's journal: exit 0, or 1 with the offset of the damage.
    Check {
        /// The run directory.
        dir: PathBuf,
        /// Machine-readable output.
        #[arg(long)]
        json: bool,
    },
    /// Write every valid record of a damaged journal into a new run directory that resumes.
    Salvage {
        /// The damaged run directory (only read).
        dir: PathBuf,
        /// The new run directory (must hold no journal).
        #[arg(long)]
        out: PathBuf,
    },
}

/// Endpoint flags shared by `coordinator`, `worker`, `run` and `watch`.
#[derive(Args, Debug, Clone, Default)]
pub struct NetArgs {
    /// Connect to this zenoh endpoint (repeatable), e.g. tcp/10.0.0.5:7447.
    #[arg(long = "connect", value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// Listen on this zenoh endpoint (repeatable), e.g. tcp/0.0.0.0:7447.
    #[arg(long = "listen", value_name = "ENDPOINT")]
    pub listen: Vec<String>,
    /// A zenoh configuration file (json5); flags override it.
    #[arg(long = "config", value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Key prefix of every topic.
    #[arg(long, default_value = protocol::keys::DEFAULT_PREFIX)]
    pub prefix: String,
    /// Mutual TLS with the certificates in DIR (`naofarm certs DIR`): the
    /// command's role certificate and the CA; endpoints must be `tls/…`.
    #[arg(long, value_name = "DIR")]
    pub tls: Option<PathBuf>,
}

/// What a worker refuses to run (it gives such trials back with the reason).
#[derive(Args, Debug, Clone)]
pub struct WorkerLimits {
    /// Longest trial accepted, simulated seconds.
    #[arg(long, default_value_t = 3600.0)]
    pub max_duration_s: f64,
    /// Most physics substeps per 20 ms cycle accepted.
    #[arg(long, default_value_t = 50)]
    pub max_substeps: u32,
    /// Trial models served, comma-separated (nao, synthetic).
    #[arg(long, default_value = "nao,synthetic", value_delimiter = ',')]
    pub models: Vec<String>,
}

/// The trial programs a worker (or `run`'s local workers, or `report`'s
/// Table IV) may run: simulators of the owner's choosing, by name.
#[derive(Args, Debug, Default, Clone)]
pub struct ProgramArgs {
    /// Serve trials of the program at PATH under NAME (repeatable): an
    /// experiment with `model = "program"` and `program = "NAME"` runs it,
    /// once per trial (docs/programs.md). Nothing else is ever run.
    #[arg(long = "program", value_name = "NAME=PATH")]
    pub programs: Vec<String>,
    /// Longest wall time of one program trial, s; past it the program and
    /// every process it started are killed and the trial fails.
    #[arg(long, default_value_t = 600.0)]
    pub program_timeout_s: f64,
    /// How long a program asked to stop (SIGTERM: the worker stopping) has
    /// before it and everything it started are killed, s.
    #[arg(long, default_value_t = 5.0)]
    pub program_grace_s: f64,
    /// Pass a variable to every program (repeatable): NAME=VALUE, or NAME
    /// for this process's own value. Programs get nothing else of the
    /// worker's environment but PATH and LANG.
    #[arg(long = "program-env", value_name = "NAME[=VALUE]")]
    pub program_env: Vec<String>,
    /// Address space of each program process, MiB (0: no limit; default:
    /// the host's memory over the worker's slots).
    #[arg(long, value_name = "MIB")]
    pub program_memory_mib: Option<u64>,
    /// Processes of the programs' user (0: no limit; default 8192; the
    /// kernel does not apply it to root).
    #[arg(long, value_name = "N")]
    pub program_processes: Option<u64>,
    /// Largest file a program may write, MiB (0: no limit; default 16384).
    #[arg(long, value_name = "MIB")]
    pub program_file_size_mib: Option<u64>,
    /// CPU seconds of each program process (0 or unset: no limit; the
    /// time-out bounds a trial's wall time).
    #[arg(long, value_name = "S")]
    pub program_cpu_s: Option<u64>,
}

/// Arguments of `stand`.
#[derive(Args, Debug)]
pub struct StandArgs {
    /// League robot type 0–4.
    #[arg(long = "type", default_value_t = 0)]
    pub robot_type: u8,
    /// Override a morphology quantity, NAME=VALUE (repeatable).
    #[arg(long = "param", value_name = "NAME=VALUE")]
    pub params: Vec<String>,
    /// Simulated seconds.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `trial`.
#[derive(Args, Debug)]
pub struct TrialArgs {
    /// Start from a named set: `expert` (the experiment's expert values, else
    /// the paper's), or, with --experiment a run directory, Table IV's
    /// `optim1` (the run's ν′) or `optim2` (CLOP's mean).
    #[arg(long, default_value = "expert")]
    pub set: String,
    /// Override a parameter, NAME=VALUE (repeatable).
    #[arg(long = "param", value_name = "NAME=VALUE")]
    pub params: Vec<String>,
    /// Number of trials.
    #[arg(long, default_value_t = 10)]
    pub trials: u64,
    /// Seed of the first trial (then +1 per trial).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// League robot type 0–4 (default 0, or the experiment's).
    #[arg(long = "type")]
    pub robot_type: Option<u8>,
    /// Start from an experiment file, or from a run directory (the experiment
    /// as the run journaled it): its robot type, trial duration,
    /// physics, and its expert set (or --set's) with its fixed values. Every
    /// other flag overrides it (`--param` one value).
    #[arg(long, value_name = "FILE|RUN_DIR", conflicts_with = "run_dir")]
    pub experiment: Option<std::path::PathBuf>,
    /// Play the walk's plan without its feedback (no balance, no step
    /// gauge): to measure what the feedback carries; farm trials always
    /// use it.
    #[arg(long, hide = true)]
    pub no_feedback: bool,
    /// Trial duration, simulated seconds (default 10, or the experiment's).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Threads (default: cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Physics steps per 20 ms cycle, 1–50 (default 4, or the experiment's).
    #[arg(long)]
    pub substeps: Option<u32>,
    /// Rapier solver iterations per physics step, 1–16 (default 1).
    #[arg(long)]
    pub solver_iterations: Option<u32>,
    /// Rapier PGS iterations per solver iteration, 1–200 (default 28).
    #[arg(long)]
    pub pgs_iterations: Option<u32>,
    /// Record the first trial (seed --seed; with --run, the farm trial):
    /// every body's pose each 20 ms cycle, as JSON lines, for a replay.
    #[arg(long, value_name = "FILE")]
    pub record: Option<std::path::PathBuf>,
    /// Render the first trial (as --record chooses it) as an animated SVG:
    /// side and top view of the robot's bodies, to scale.
    #[arg(long, value_name = "FILE.svg")]
    pub render: Option<std::path::PathBuf>,
    /// Replay a farm trial of this run directory (with --iteration and
    /// --trial): its parameters, robot type, physics and seed come from the
    /// journal, and the result is compared with the journaled one bit for bit.
    #[arg(
        long = "run",
        value_name = "DIR",
        requires_all = ["iteration", "trial"],
        conflicts_with_all = ["params", "trials", "seed", "robot_type", "duration", "substeps",
            "solver_iterations", "pgs_iterations", "no_feedback"]
    )]
    pub run_dir: Option<std::path::PathBuf>,
    /// With --run: the iteration.
    #[arg(long, requires = "run_dir")]
    pub iteration: Option<u64>,
    /// With --run: the trial index within the iteration.
    #[arg(long, requires = "run_dir")]
    pub trial: Option<u32>,
    /// Machine-readable output with every trial.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `bench sim`.
#[derive(Args, Debug)]
pub struct SimBenchArgs {
    /// Simulated seconds per measurement.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Rounds of every measurement in turn; rows are the medians, shares
    /// the medians of each round's ratio.
    #[arg(long, default_value_t = 5)]
    pub rounds: u32,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `naofarm clop`.
#[derive(Args, Debug)]
pub struct ClopArgs {
    /// A parameter, NAME:KIND:LO:HI (KIND: linear, integer, gamma, integer_gamma); repeatable, in order.
    #[arg(long = "param", value_name = "NAME:KIND:LO:HI", required = true)]
    pub params: Vec<String>,
    /// Games to play in all (a resumed log's games count).
    #[arg(long)]
    pub budget: u64,
    /// Seed of CLOP's sampler and of the games' seeds.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// A command started once: reads `<game> <seed> <v1> <v2> …`, answers `W`, `D` or `L` per line.
    #[arg(long, conflicts_with = "script", required_unless_present = "script")]
    pub evaluator: Option<String>,
    /// A command run once per game with `<processor> <seed> <name1> <value1> …`; its last line is W, L or D.
    #[arg(long)]
    pub script: Option<String>,
    /// Append every game here (JSON lines); an existing log is replayed and continued.
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Seconds one game may take before the evaluator is declared hung.
    #[arg(long, default_value_t = 600.0)]
    pub timeout_s: f64,
    /// CLOP's DrawElo (draws are likelier with a larger value).
    #[arg(long, default_value_t = 0.0)]
    pub draw_elo: f64,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `web`.
#[derive(Args, Debug)]
pub struct WebArgs {
    #[command(flatten)]
    pub net: NetArgs,
    /// The page's address (HTTP); another than loopback only when asked.
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1:8080")]
    pub http: std::net::SocketAddr,
    /// Let the page pause, resume, stop and re-prioritise runs. With
    /// `--tls DIR`, control goes through DIR's coordinator certificate.
    #[arg(long)]
    pub control: bool,
}

/// Arguments of `watch`.
#[derive(Args, Debug)]
pub struct WatchArgs {
    /// The run to follow; without it, list the runs that answer.
    pub run: Option<String>,
    #[command(flatten)]
    pub net: NetArgs,
    /// One JSON line per event instead of the terminal view.
    #[arg(long)]
    pub json: bool,
    /// Seconds to wait for a coordinator to answer before giving up.
    #[arg(long, default_value_t = 5.0)]
    pub timeout_s: f64,
}
