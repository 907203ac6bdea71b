//! What the command line accepts: every subcommand and its flags (clap),
//! with the units and defaults each flag documents. Parsing only: `local`
//! and `service` run them.

use std::path::PathBuf;

use clap::{Parser, Subcommand};

/// Default encoder step (m): the 1 µm encoder of the papers' device.
pub const DEFAULT_QUANTIZATION: f64 = 1e-6;

#[derive(Parser, Debug)]
#[command(
    name = "zwidth",
    version,
    about = "Velocity estimators and Z-width of haptic devices (SI units throughout)"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Estimate velocity: positions (m, one per line) on stdin, velocities (m/s) on stdout.
    Estimate {
        /// Sample rate (Hz).
        #[arg(long)]
        rate: f64,
        /// Estimator spec as JSON, e.g. '{"kind":"butterworth","cutoff_hz":100}'.
        #[arg(long)]
        estimator: String,
        /// Encoder quantization step d (m); sets Kalman r = d²/3 and the FOAW band.
        #[arg(long, default_value_t = DEFAULT_QUANTIZATION)]
        quantization: f64,
    },
    /// The 2011 paper's Fig. 2 study: RMS derivative error of every estimator vs sample rate.
    Accuracy {
        /// Sample rates (Hz), comma-separated.
        #[arg(long, value_delimiter = ',', default_values_t = [1e3, 2e3, 5e3, 1e4, 2e4, 5e4, 1e5])]
        rates: Vec<f64>,
        /// Print JSON instead of the table.
        #[arg(long)]
        json: bool,
        /// Also write the error-vs-rate plot here.
        #[arg(long)]
        svg: Option<PathBuf>,
        /// Encoder quantization step (m).
        #[arg(long, default_value_t = DEFAULT_QUANTIZATION)]
        quantization: f64,
    },
    /// Estimate the Lipschitz constant C (bound on |acceleration|, m/s²) of a position trace on stdin.
    Lipschitz {
        /// Sample rate (Hz).
        #[arg(long)]
        rate: f64,
        /// Encoder quantization step (m), if known; otherwise the noise is estimated from the data.
        #[arg(long)]
        quantization: Option<f64>,
        #[arg(long)]
        json: bool,
    },
    /// One wall hit (time domain, 2011 paper §2.4).
    Trial {
        /// Scene JSON file.
        #[arg(long)]
        scene: PathBuf,
        /// Wall stiffness K (N/m).
        #[arg(long)]
        k: f64,
        /// Wall damping B (N·s/m).
        #[arg(long, allow_negative_numbers = true)]
        b: f64,
        #[arg(long)]
        json: bool,
        /// Write the trace here: t, true and measured position, estimated and true velocity, force.
        #[arg(long)]
        trace: Option<PathBuf>,
    },
    /// Impedance of the rendered wall over the probe band (analytic when the scene is linear, else simulated).
    Impedance {
        #[arg(long)]
        scene: PathBuf,
        #[arg(long)]
        k: f64,
        #[arg(long, allow_negative_numbers = true)]
        b: f64,
        /// auto | analytic | frequency
        #[arg(long, default_value = "auto")]
        method: String,
        /// draft | standard | reference
        #[arg(long, default_value = "standard")]
        accuracy: String,
        #[arg(long)]
        json: bool,
    },
    /// Z-width map: the (K, B) region the scene renders.
    Map {
        #[arg(long)]
        scene: PathBuf,
        /// auto | analytic | time | frequency
        #[arg(long, default_value = "auto")]
        method: String,
        /// stability | impedance | strict_passivity
        #[arg(long, default_value = "impedance")]
        criterion: String,
        /// trace | bisect | robust_bisect | grid | psi (BLA-probed scenes with friction or quantization: a posterior per column, docs/zwidth.md; elsewhere bisection)
        #[arg(long, default_value = "bisect")]
        search: String,
        /// Only these damping values (N·s/m), comma-separated.
        #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
        b: Option<Vec<f64>>,
        /// Relative K resolution of the bisection (overrides the accuracy preset).
        #[arg(long)]
        k_rel_tol: Option<f64>,
        /// draft | standard | reference
        #[arg(long, default_value = "standard")]
        accuracy: String,
        #[arg(long)]
        json: bool,
        /// Write the Fig. 7-style plot here.
        #[arg(long)]
        svg: Option<PathBuf>,
        /// Start each column's bisection from this scene's simulated
        /// boundary (e.g. the device `zwidth identify` gave): where the
        /// prediction is right, two trials bracket a column.
        #[arg(long, conflicts_with = "prior_map")]
        prior_scene: Option<PathBuf>,
        /// Start each column's bisection from this map's boundary (the
        /// JSON of `zwidth map --json`, or a list of {b, k_max, k_lo, k_hi}).
        #[arg(long)]
        prior_map: Option<PathBuf>,
    },
    /// Tune the scene's estimator parameters (argmin) for an objective.
    Tune {
        #[arg(long)]
        scene: PathBuf,
        /// Parameters with bounds, e.g. '{"cutoff_hz":{"min":10,"max":500}}',
        /// '{"q":{"min":1e2,"max":1e8,"scale":"log"}}'.
        #[arg(long)]
        params: String,
        /// k_width | b_width | max_fidelity_error | area, or JSON:
        /// '{"weighted":{"k_width":1e-5,"b_width":1e-2}}', '{"pareto":["k_width","max_fidelity_error"]}'.
        #[arg(long)]
        objective: String,
        /// auto | analytic | time | frequency
        #[arg(long, default_value = "auto")]
        method: String,
        /// stability | impedance | strict_passivity
        #[arg(long, default_value = "impedance")]
        criterion: String,
        /// robust_bisect | bisect | trace | grid | psi: how each map searches.
        #[arg(long, default_value = "robust_bisect")]
        search: String,
        /// auto | brent | golden | nelder_mead | particle_swarm | grid | halton
        #[arg(long, default_value = "auto")]
        solver: String,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Accuracy while searching: draft | standard | reference.
        #[arg(long, default_value = "draft")]
        accuracy: String,
        /// Accuracy the finalists are re-evaluated at.
        #[arg(long, default_value = "reference")]
        final_accuracy: String,
        #[arg(long, default_value_t = 3)]
        finalists: usize,
        /// Noisy scenes: maps per finalist at the final accuracy, each with
        /// other random-phase realizations (more, up to twice this, where
        /// finalists' intervals overlap). 1: one map each.
        #[arg(long, default_value_t = 3)]
        replicates: usize,
        #[arg(long, default_value_t = 40)]
        max_evaluations: usize,
        /// levant | lyapunov (Levant gains only).
        #[arg(long)]
        constraint: Option<String>,
        /// Only these damping values (N·s/m), comma-separated.
        #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
        b: Option<Vec<f64>>,
        #[arg(long)]
        json: bool,
        /// Plot of the objective over evaluations (or the Pareto front).
        #[arg(long)]
        svg: Option<PathBuf>,
        /// Every evaluation as CSV.
        #[arg(long)]
        csv: Option<PathBuf>,
    },
    /// Every estimator on one scene, as the 2018 paper's Table I.
    Compare {
        /// Scene JSON file (default: the 2018 paper's simulated device at 1 kHz).
        scene: Option<PathBuf>,
        /// draft | standard | reference
        #[arg(long, default_value = "standard")]
        accuracy: String,
        #[arg(long)]
        json: bool,
        /// Write one map plot per estimator into this directory.
        #[arg(long)]
        svg_dir: Option<PathBuf>,
        /// Tune each estimator for this objective first (k_width, b_width,
        /// max_fidelity_error, area or a weighted JSON), as the paper did;
        /// without it the rows use the paper's fixed parameters.
        #[arg(long)]
        tuned: Option<String>,
        /// With --tuned: maps each estimator's search may make (1–200).
        #[arg(long, default_value_t = 24)]
        max_evaluations: usize,
        /// With --tuned: seeds the searches.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// impedance (the 2018 paper's test) | stability (the 2011 paper's
        /// wall hit: the time engine on a nonlinear scene) |
        /// strict_passivity (linear scenes)
        #[arg(long, default_value = "impedance")]
        criterion: String,
        /// Rounds that map the rows of unresolved K-width orders again,
        /// each at half the K resolution before (0–3; default 0, with
        /// --tuned 2).
        #[arg(long)]
        resolve_rounds: Option<u32>,
    },
    /// Record an open-loop identification trace from the scene's simulated
    /// device: a Schroeder multisine force, CSV t_s,force_n,position_m.
    Record {
        #[arg(long)]
        scene: PathBuf,
        /// The CSV to write.
        #[arg(long)]
        out: PathBuf,
        /// Record length (s).
        #[arg(long, default_value_t = 20.0)]
        duration: f64,
        /// Multisine period (s); the lowest line is its inverse.
        #[arg(long, default_value_t = 2.0)]
        period: f64,
        /// Highest multisine line (Hz).
        #[arg(long, default_value_t = 20.0)]
        f_max: f64,
        /// Peak force command (N).
        #[arg(long, default_value_t = 1.0)]
        peak_force: f64,
        /// A second band of lines added on the same period, from this
        /// frequency (Hz): around a transmission mode, for `identify
        /// --model two_mass`.
        #[arg(long, requires_all = ["band_max", "band_force"])]
        band_min: Option<f64>,
        /// The band's highest line (Hz).
        #[arg(long, requires_all = ["band_min", "band_force"])]
        band_max: Option<f64>,
        /// The band's own peak force (N); the summed command must stay
        /// within the device's force_limit.
        #[arg(long, requires_all = ["band_min", "band_max"])]
        band_force: Option<f64>,
    },
    /// Identify the device (mass, damping, Coulomb friction; with `--model
    /// two_mass` also its transmission mode and amplifier lag; with 95 %
    /// intervals) from an open-loop trace (CSV t_s,force_n,position_m).
    Identify {
        /// The trace CSV (as `zwidth record` writes, or from a rig).
        trace: PathBuf,
        /// mass_damper_coulomb | mass_damper | two_mass (a transmission
        /// mode, the encoder on the motor side; record with a band around
        /// the mode)
        #[arg(long, default_value = "mass_damper_coulomb")]
        model: String,
        /// two_mass: fit the mode on this second trace (recorded with a
        /// band around the mode) and the whole device on the first.
        #[arg(long)]
        mode_trace: Option<PathBuf>,
        /// Scene to take everything but the device from (default: the
        /// default scene at the trace's sample rate).
        #[arg(long)]
        scene: Option<PathBuf>,
        /// Write the identified scene here.
        #[arg(long)]
        out: Option<PathBuf>,
        #[arg(long)]
        json: bool,
    },
    /// Run the HTTP service: queue experiments, run them, store every run
    /// in SQLite (the default) or PostgreSQL.
    Serve {
        /// The database: a SQLite file (created and migrated on first start)
        /// or a postgres:// URL (the database must exist; it is migrated).
        #[arg(long, env = "ZWIDTH_DB", default_value = "zwidth.db")]
        db: String,
        /// Address to listen on; port 0 picks a free one (printed on start).
        #[arg(long, env = "ZWIDTH_BIND", default_value = "127.0.0.1:8080")]
        bind: String,
        /// Bearer tokens that may submit and cancel (comma-separated); required beyond loopback.
        #[arg(
            long = "token",
            env = "ZWIDTH_TOKENS",
            value_delimiter = ',',
            hide_env_values = true
        )]
        tokens: Vec<String>,
        /// A file with the bearer tokens, one per line (keeps them out of `ps`
        /// and the shell history; prefer this or ZWIDTH_TOKENS to --token).
        #[arg(long, env = "ZWIDTH_TOKEN_FILE")]
        token_file: Option<PathBuf>,
        /// Another origin that may write (e.g. a dashboard behind a proxy:
        /// https://lab.example); the server's own origin always may.
        #[arg(
            long = "allow-origin",
            env = "ZWIDTH_ALLOW_ORIGINS",
            value_delimiter = ','
        )]
        allow_origins: Vec<String>,
        /// Rigs, comma-separated: NAME[:THREADS] a simulator (0 threads: one
        /// per core), NAME:attached hardware behind a `zwidth agent`; the
        /// first is the default.
        #[arg(long, env = "ZWIDTH_RIGS", default_value = "sim:0")]
        rigs: String,
        /// A file with the agents' tokens, one per line (default
        /// `<db>.agent-token`, made owner-only on first start).
        #[arg(long, env = "ZWIDTH_AGENT_TOKEN_FILE")]
        agent_token_file: Option<PathBuf>,
        /// Agents' tokens (comma-separated), besides the file's: how a
        /// container is given them (docker-compose.yml's ZWIDTH_AGENT_TOKENS).
        #[arg(
            long = "agent-token",
            env = "ZWIDTH_AGENT_TOKENS",
            value_delimiter = ',',
            hide_env_values = true
        )]
        agent_token: Vec<String>,
        /// Attached rigs: the agents' heartbeat interval (ms) …
        #[arg(long, default_value_t = 2000)]
        agent_heartbeat_ms: u64,
        /// … the silence after which a rig is `lost_contact` (ms) …
        #[arg(long, default_value_t = 10_000)]
        agent_ttl_ms: u64,
        /// … and the further silence after which its session is fenced off
        /// and its trial sent again (ms).
        #[arg(long, default_value_t = 20_000)]
        agent_grace_ms: u64,
        /// Longest a request may take before a 503 (s).
        #[arg(long, env = "ZWIDTH_REQUEST_TIMEOUT_S", default_value_t = 30.0)]
        request_timeout_s: f64,
        /// Most connections one client address may hold at once; more are
        /// answered 503 and closed (1 to 100000).
        #[arg(long, env = "ZWIDTH_MAX_CONNECTIONS_PER_CLIENT", default_value_t = crate::http::accept::PER_CLIENT)]
        max_connections_per_client: usize,
        /// Run no experiments here, only the API (and attached rigs, whose
        /// agents connect here): `zwidth worker` processes run the rest.
        /// Needs a PostgreSQL database.
        #[arg(long)]
        api_only: bool,
        /// How long a running experiment's lease lasts without a heartbeat
        /// (ms): a process silent this long loses the run to another.
        #[arg(long, env = "ZWIDTH_LEASE_MS", default_value_t = crate::jobs::LEASE_MS)]
        lease_ms: i64,
        /// Serve HTTPS (and WSS to agents) with this PEM certificate chain,
        /// leaf first; needs --tls-key.
        #[arg(long, env = "ZWIDTH_TLS_CERT", requires = "tls_key")]
        tls_cert: Option<PathBuf>,
        /// The PEM private key of --tls-cert (PKCS#8, PKCS#1 or SEC1).
        #[arg(long, env = "ZWIDTH_TLS_KEY", requires = "tls_cert")]
        tls_key: Option<PathBuf>,
        /// `private`: every read (API and dashboard) needs the token too;
        /// `public`: reads are open. Default: private unless bound to
        /// loopback only.
        #[arg(long, env = "ZWIDTH_READS", value_parser = ["private", "public"])]
        reads: Option<String>,
        /// Host names the server is reached by (comma-separated), besides
        /// localhost and IP addresses: a request naming another host is
        /// refused (421), so a DNS-rebinding page reads nothing.
        #[arg(long = "host", env = "ZWIDTH_HOSTS", value_delimiter = ',')]
        hosts: Vec<String>,
    },
    /// Run experiments from a shared PostgreSQL database, next to any
    /// number of other workers and `serve --api-only` processes.
    Worker {
        /// The PostgreSQL database the API processes use (postgres://…).
        #[arg(long, env = "ZWIDTH_DB")]
        db: String,
        /// Simulated rigs this worker runs, comma-separated NAME[:THREADS]
        /// (0 threads: one per core); the same names the API was given.
        #[arg(long, env = "ZWIDTH_RIGS", default_value = "sim:0")]
        rigs: String,
        /// How long a running experiment's lease lasts without a heartbeat
        /// (ms): a worker silent this long loses the run to another.
        #[arg(long, env = "ZWIDTH_LEASE_MS", default_value_t = crate::jobs::LEASE_MS)]
        lease_ms: i64,
    },
    /// Connect a rig to a server: run its trials (on the simulated plant
    /// with --sim, or on a driver process) and send the results back.
    Agent {
        /// Run the simulated plant of each trial's scene (the reference agent).
        #[arg(long, conflicts_with = "driver")]
        sim: bool,
        /// A driver process for real hardware, run by `sh -c`, speaking the
        /// line-oriented JSON driver protocol (docs/rigs.md).
        #[arg(long)]
        driver: Option<String>,
        /// The server: http://HOST:PORT, or https:// for one serving TLS.
        #[arg(long, env = "ZWIDTH_SERVER", default_value = "http://127.0.0.1:8080")]
        server: String,
        /// A PEM file of CA certificates to trust for an https:// server,
        /// besides the system's (a lab's own CA, or a self-signed server's
        /// certificate); or ZWIDTH_CA_FILE.
        #[arg(long)]
        ca_file: Option<PathBuf>,
        /// The rig's id on the server (`serve --rigs NAME:attached`).
        #[arg(long)]
        rig: String,
        /// This agent's name (default: host name and process id).
        #[arg(long)]
        name: Option<String>,
        /// The agent token file (default `zwidth.db.agent-token`, made by
        /// `serve` next to its database; or ZWIDTH_AGENT_TOKEN_FILE, e.g. a
        /// compose secret); or ZWIDTH_AGENT_TOKEN.
        #[arg(long, env = "ZWIDTH_AGENT_TOKEN_FILE")]
        token_file: Option<PathBuf>,
        /// Where unacknowledged results wait (default `<rig>.outbox`).
        #[arg(long)]
        outbox: Option<PathBuf>,
        /// --sim: `realtime` paces each trial like hardware (10 s), `fast` runs at once.
        #[arg(long, default_value = "fast", value_parser = ["fast", "realtime"])]
        pace: String,
        /// --sim: each trial takes at least this long (ms); overrides --pace.
        #[arg(long)]
        trial_ms: Option<u64>,
        /// --sim: the capabilities to advertise (JSON; default a 10 N bench device).
        #[arg(long)]
        capabilities: Option<PathBuf>,
        /// --sim: simulate the device of this scene file instead of each
        /// trial's own (hardware that differs from its model: a prior's
        /// disagreement, a night rehearsed).
        #[arg(long, requires = "sim")]
        sim_device: Option<PathBuf>,
        /// --sim: faults to inject (JSON, docs/rigs.md), for tests.
        #[arg(long)]
        faults: Option<PathBuf>,
        /// The operator's limits: trials beyond them are refused whatever
        /// the server asks. Force (N) …
        #[arg(long, default_value_t = f64::INFINITY)]
        max_force_n: f64,
        /// … stiffness (N/m) …
        #[arg(long, default_value_t = f64::INFINITY)]
        max_k: f64,
        /// … damping (N·s/m) …
        #[arg(long, default_value_t = f64::INFINITY)]
        max_b: f64,
        /// … the speed past which the controller aborts a trial (m/s) …
        #[arg(long, default_value_t = f64::INFINITY)]
        max_speed_m_s: f64,
        /// … and the penetration past which it does (m).
        #[arg(long, default_value_t = f64::INFINITY)]
        max_penetration_m: f64,
    },
    /// Attached rigs on a running service.
    Rig {
        #[command(subcommand)]
        action: RigCommand,
    },
    /// Submit an experiment JSON file to a running service; prints its id.
    Submit {
        file: PathBuf,
        #[arg(long, env = "ZWIDTH_SERVER", default_value = "http://127.0.0.1:8080")]
        server: String,
        #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
        priority: i64,
        #[arg(long)]
        idempotency_key: Option<String>,
        /// Rig to run on (see GET /v1/rigs); default the server's first.
        #[arg(long)]
        rig: Option<String>,
        #[arg(long)]
        json: bool,
    },
    /// Show an experiment's state and progress (JSON).
    Status {
        id: String,
        #[arg(long, env = "ZWIDTH_SERVER", default_value = "http://127.0.0.1:8080")]
        server: String,
    },
    /// Follow an experiment with a progress line until it ends (exit 1 unless it succeeded).
    Watch {
        id: String,
        #[arg(long, env = "ZWIDTH_SERVER", default_value = "http://127.0.0.1:8080")]
        server: String,
    },
    /// Fetch a finished experiment's result: JSON on stdout, or points as CSV, or the plot.
    Results {
        id: String,
        #[arg(long, env = "ZWIDTH_SERVER", default_value = "http://127.0.0.1:8080")]
        server: String,
        #[arg(long)]
        csv: Option<PathBuf>,
        #[arg(long)]
        svg: Option<PathBuf>,
    },
    /// Print the service's OpenAPI 3.1 description (what api/openapi.json holds).
    Openapi {
        /// Print the agent protocol's message schemas instead
        /// (api/agent-protocol.json).
        #[arg(long)]
        agent_protocol: bool,
    },
    /// A consistent copy of a service's database in one file (SQLite
    /// `VACUUM INTO`), safe while the service runs; restore by starting
    /// `zwidth serve --db` on the copy.
    Backup {
        /// The database to copy.
        #[arg(long, env = "ZWIDTH_DB", default_value = "zwidth.db")]
        db: PathBuf,
        /// The copy to write (must not exist).
        #[arg(long)]
        out: PathBuf,
    },
    /// Measurements: `zwidth bench tradeoff`, `zwidth bench trust`.
    Bench {
        #[command(subcommand)]
        what: BenchCommand,
    },
    /// Report which convergence conditions a Levant gain pair meets.
    Gains {
        /// A levant estimator spec, e.g. '{"kind":"levant","alpha":13,"lambda":1.58,"lipschitz":12}'.
        #[arg(long)]
        estimator: String,
        #[arg(long)]
        json: bool,
    },
}

#[derive(Subcommand, Debug)]
pub enum RigCommand {
    /// Issue rig ID a new agent credential of its own: it alone opens the
    /// rig's agent sessions from now on (the rig's earlier one and the
    /// server's shared agent tokens no longer do). Written owner-only to
    /// --out, never printed unless --out is `-`.
    Token {
        id: String,
        #[arg(long, env = "ZWIDTH_SERVER", default_value = "http://127.0.0.1:8080")]
        server: String,
        /// The file to write it to (default `ID.agent-token`; created, never
        /// overwritten); `-`: stdout.
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Against a running service: 1 000 submissions, then GET latency at 500 requests/s while a long experiment runs.
    Service {
        #[arg(long, env = "ZWIDTH_SERVER", default_value = "http://127.0.0.1:8080")]
        server: String,
        #[arg(long, default_value_t = 1000)]
        submissions: usize,
        #[arg(long, default_value_t = 500.0)]
        rate: f64,
        #[arg(long, default_value_t = 10.0)]
        seconds: f64,
    },
    /// Tuning on the seed device: Butterworth tuner vs a 1 Hz brute-force scan, Levant tuned vs rule gains.
    Tune {
        /// Accuracy of the Butterworth scan and tune.
        #[arg(long, default_value = "draft")]
        accuracy: String,
        /// Points of the brute-force scan (490: 1 Hz steps over 10–499 Hz); the tuner gets a fifth.
        #[arg(long, default_value_t = 490)]
        scan_points: usize,
        /// Accuracy of the Levant tune.
        #[arg(long, default_value = "standard")]
        levant_accuracy: String,
        /// Evaluations the Levant tune may make.
        #[arg(long, default_value_t = 16)]
        levant_evaluations: usize,
        #[arg(long)]
        json: bool,
    },
    /// Scaling out: a column-heavy sweep and a campaign of trace maps, each
    /// on 1 and 2 workers (PostgreSQL) and 1 (SQLite), then the claim rate and latency with 1, 8 and 32
    /// claimers. Needs a PostgreSQL database; it deletes what it stores.
    Scale {
        /// The PostgreSQL database to measure (postgres://…).
        #[arg(long, env = "ZWIDTH_DB")]
        db: String,
        /// Maps in each campaign of trace maps.
        #[arg(long, default_value_t = 16)]
        maps: usize,
        /// Column-heavy sweeps (24 B columns of ~0.6 s each) in each sweep run.
        #[arg(long, default_value_t = 1)]
        sweeps: usize,
        /// Empty experiments claimed in each claim-rate run.
        #[arg(long, default_value_t = 2000)]
        claims: usize,
        /// Runs of each configuration (interleaved; the fastest counts).
        #[arg(long, default_value_t = 2)]
        repeat: usize,
        #[arg(long)]
        json: bool,
    },
    /// Each dashboard page's server time (median and slowest of --repeat)
    /// and size on a new database seeded with --experiments runs holding
    /// --trials trials (--big of them in one run), through the real router
    /// in this process; the JSON list is the baseline.
    Ui {
        /// A new or empty database to seed (a file path or postgres://…).
        #[arg(long, env = "ZWIDTH_DB")]
        db: String,
        #[arg(long, default_value_t = 10_000)]
        experiments: usize,
        #[arg(long, default_value_t = 1_000_000)]
        trials: usize,
        /// Trials of the biggest run.
        #[arg(long, default_value_t = 20_000)]
        big: usize,
        #[arg(long, default_value_t = 5)]
        repeat: usize,
        #[arg(long)]
        json: bool,
    },
    /// Wall time and K/B-width error against `reference` for each accuracy preset, on the example scenes.
    Tradeoff {
        /// Only the examples whose name contains this (e.g. `seed_2018`,
        /// `mode_lag`: its reference map alone takes minutes).
        #[arg(long)]
        scene: Option<String>,
        /// bisect | robust_bisect | trace | grid | psi: how every map searches
        /// (each preset against the same search's reference).
        #[arg(long, default_value = "bisect")]
        search: String,
        #[arg(long)]
        json: bool,
    },
    /// The seed device's K-width with its interval against the probe seed,
    /// the Butterworth cutoff 480–499 Hz and the probe amplitude (standard
    /// accuracy; ~3 min on 2 cores).
    Trust {
        #[arg(long)]
        json: bool,
    },
}

impl Command {
    /// Commands that run or talk to the service.
    pub(super) fn is_service(&self) -> bool {
        matches!(
            self,
            Command::Serve { .. }
                | Command::Worker { .. }
                | Command::Agent { .. }
                | Command::Rig { .. }
                | Command::Submit { .. }
                | Command::Openapi { .. }
                | Command::Backup { .. }
                | Command::Status { .. }
                | Command::Watch { .. }
                | Command::Results { .. }
        )
    }
}
