//! `embodied`: plan, run and verify multi-robot systems of embodied agents.
#![forbid(unsafe_code)]

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use embodied::AppError;
use embodied::model_report::{load_robot, model_report, parse_q, render_text};

use embodied::{out, outln};

const EXIT_STATUS_HELP: &str = "Exit status: 0 success; 1 the work was done but did not succeed (no plan, not \
certified, a goal not reached, a run that failed); 2 bad input (arguments, files). File arguments \
accept `-` for standard input.";

fn builtin_help() -> String {
    let mut s = String::from("Built-in robots (and where their numbers come from):\n");
    for (name, source) in embodied_models::builtin_summaries() {
        s.push_str(&format!("\n  {name}\n      {source}\n"));
    }
    s
}

#[derive(Parser, Debug)]
#[command(
    name = "embodied",
    version = embodied::VERSION,
    about = "Deliberative planning and verification of multi-robot systems (embodied agents)",
    after_help = EXIT_STATUS_HELP
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// A folder to look for `package://NAME/...` files in: the package NAME itself or a folder
    /// holding it (repeatable; before ROS_PACKAGE_PATH, AMENT_PREFIX_PATH and the URDF's folders).
    #[arg(long, global = true, value_name = "DIR")]
    package_path: Vec<PathBuf>,
    /// Drop a collision mesh found nowhere (with a warning) instead of refusing the URDF.
    #[arg(long, global = true)]
    allow_missing_meshes: bool,
    /// Largest input file read, MB (text files and meshes; run logs: 16 times this). Default 256.
    #[arg(long, global = true, value_name = "MB")]
    max_input_mb: Option<u64>,
    /// Most values (array elements, entries, XML elements) a text file may hold. Default 10^7.
    #[arg(long, global = true, value_name = "N")]
    max_input_values: Option<usize>,
    /// Most triangles a mesh may have. Default 5,000,000.
    #[arg(long, global = true, value_name = "N")]
    max_mesh_triangles: Option<usize>,
    /// Most links a URDF may have. Default 10,000.
    #[arg(long, global = true, value_name = "N")]
    max_links: Option<usize>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Print a robot: joints, link poses, end effectors, self-collision and minimum distance at q.
    #[command(after_long_help = builtin_help())]
    Model {
        /// A built-in robot name (see --help) or a path to a URDF file.
        robot: String,
        /// SRDF for a URDF robot (disabled collision pairs, groups).
        #[arg(long)]
        srdf: Option<PathBuf>,
        /// Joint values, comma separated, in the robot's joint order (default: the home pose).
        #[arg(long, allow_hyphen_values = true)]
        q: Option<String>,
        /// Inverse kinematics: every joint solution placing the tool at X,Y,Z (m, world frame) with
        /// roll, pitch, yaw ROLL,PITCH,YAW (rad, as in scenario files), seeded at --q. Closed form
        /// where the arm has one (IRp-6), else the numerical solver. Exit status 1 if none exists.
        #[arg(long, allow_hyphen_values = true, value_name = "X,Y,Z,ROLL,PITCH,YAW")]
        ik: Option<String>,
        /// The end effector for --ik, by name (default: the robot's first).
        #[arg(long, requires = "ik")]
        ee: Option<String>,
        /// Print one JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Run a scenario as embodied agents in the simulated world (default: the built-in default scenario).
    Run {
        /// A built-in scenario name (see `embodied scenarios`) or a scenario TOML file.
        scenario: Option<String>,
        /// Simulated seconds to run (default: the scenario's `[run] duration`, else 6).
        #[arg(long)]
        duration: Option<f64>,
        /// Seed of all simulated noise (default: the scenario's).
        #[arg(long)]
        seed: Option<u64>,
        /// Write the JSON Lines log here (header, one line per 1 ms step, summary).
        #[arg(long)]
        log: Option<PathBuf>,
        /// Write an SVG plot of every joint's trajectory here.
        #[arg(long)]
        plot: Option<PathBuf>,
        /// Write a 3-D viewer page of the run here (one HTML file; opens offline).
        #[arg(long)]
        html: Option<PathBuf>,
        /// Print the summary as JSON.
        #[arg(long)]
        json: bool,
        /// How planning time is counted: `wall` (real planning time; the run is paced to real
        /// time while a plan is computed) or `simulated` (from the planner's collision checks:
        /// the same seed gives a byte-identical log). Default: the scenario's `[planner] clock`.
        #[arg(long, value_parser = ["wall", "simulated"])]
        clock: Option<String>,
        /// Simulated planning time per collision check, microseconds (implies --clock simulated;
        /// default: the scenario's `[planner] simulated_us_per_check`, else 2).
        #[arg(long)]
        us_per_check: Option<f64>,
    },
    /// Plan every agent of a scenario that has a goal and write the plan (JSON), or plan a MoveIt
    /// motion plan request in its planning scene (--urdf --srdf --scene --request).
    Plan {
        /// A built-in scenario name or a scenario TOML file.
        #[arg(required_unless_present_any = ["request", "batch"])]
        scenario: Option<String>,
        /// The robot of a MoveIt request or of a --batch folder (URDF or .xacro).
        #[arg(long, requires = "srdf")]
        urdf: Option<PathBuf>,
        /// Its SRDF (groups).
        #[arg(long)]
        srdf: Option<PathBuf>,
        /// A MoveIt planning scene (YAML).
        #[arg(long)]
        scene: Option<PathBuf>,
        /// A MoveIt motion plan request (YAML), planned instead of a scenario.
        #[arg(long, requires = "urdf", conflicts_with = "scenario")]
        request: Option<PathBuf>,
        /// MoveIt's joint_limits.yaml (acceleration limits URDF has not).
        #[arg(long, requires = "urdf")]
        limits: Option<PathBuf>,
        /// Output: embodied-plan/1 JSON, or a trajectory_msgs/JointTrajectory (YAML, or JSON for
        /// a .json file). Default: embodied for scenarios, joint-trajectory for requests.
        #[arg(long, value_enum)]
        format: Option<embodied::moveit_cli::PlanFormat>,
        /// Write the plan file here (default: print it).
        #[arg(short = 'o', long = "out")]
        out: Option<PathBuf>,
        /// Planning deadline per agent, milliseconds (default: the scenario's).
        #[arg(long)]
        deadline_ms: Option<f64>,
        /// Print a JSON summary (with -o) or the plan itself.
        #[arg(long)]
        json: bool,
        /// Write a 3-D viewer page of the plan here (one HTML file; opens offline).
        #[arg(long)]
        html: Option<PathBuf>,
        /// Plan many problems: a folder of MoveIt problems (`<family>/sceneNNNN.yaml` +
        /// `requestNNNN.yaml`, with --urdf --srdf) or a file listing scenarios (one name or TOML
        /// file per line). Each is planned and certified; prints a summary. Exit status 1 if any
        /// problem has no certified plan.
        #[arg(long, value_name = "DIR|LIST", conflicts_with_all = ["scenario", "request", "out", "html", "format", "json"])]
        batch: Option<PathBuf>,
        /// Plan only shard K of N of the --batch problems (problem i, in sorted order, goes to
        /// shard (i mod N) + 1); join the shards' --jsonl files with `embodied bench merge`.
        #[arg(long, value_name = "K/N", requires = "batch")]
        shard: Option<embodied::batch::Shard>,
        /// Write the --batch results as JSON Lines here (`-`: standard output, the summary then
        /// goes to standard error): a header line, then one line per problem with its plan.
        #[arg(long, value_name = "FILE", requires = "batch")]
        jsonl: Option<PathBuf>,
    },
    /// Write a 3-D viewer page (one self-contained HTML file) of a run log or a plan file:
    /// the robots, obstacles and carried object moving along the logged or planned motion,
    /// with a timeline of the events and the clearance.
    View {
        /// A run log (`embodied run --log RUN.jsonl`) or a plan file (`embodied plan -o PLAN.json`).
        input: PathBuf,
        /// The scenario (built-in name or TOML file; default: the built-in one the input names).
        #[arg(long)]
        scenario: Option<String>,
        /// Where to write the page (default: the input's name with `.html`).
        #[arg(short = 'o', long = "out")]
        out: Option<PathBuf>,
    },
    /// Check a plan (and/or a run log) against a scenario, independently of the planner: limits,
    /// collisions certified over the whole continuous path, closed-chain spans, timing.
    /// Exit status: 0 certified, 1 a violation or not certified, 2 bad input.
    Verify {
        /// A built-in scenario name or a scenario TOML file.
        #[arg(required_unless_present = "trajectory")]
        scenario: Option<String>,
        /// The plan file (`embodied plan -o PLAN.json`); optional when --log is given.
        #[arg(required_unless_present_any = ["log", "trajectory"])]
        plan: Option<PathBuf>,
        /// A trajectory_msgs/JointTrajectory (YAML or JSON) to certify, with --urdf.
        #[arg(long, requires = "urdf", conflicts_with_all = ["scenario", "plan", "log"])]
        trajectory: Option<PathBuf>,
        /// The robot of --trajectory (URDF or .xacro).
        #[arg(long, requires = "trajectory")]
        urdf: Option<PathBuf>,
        /// Its SRDF (disabled collision pairs).
        #[arg(long, requires = "trajectory")]
        srdf: Option<PathBuf>,
        /// A MoveIt planning scene (YAML): obstacles and the state of joints the trajectory leaves out.
        #[arg(long, requires = "trajectory")]
        scene: Option<PathBuf>,
        /// MoveIt's joint_limits.yaml.
        #[arg(long, requires = "trajectory")]
        limits: Option<PathBuf>,
        /// Check a run log (`embodied run --log FILE.jsonl`): limits and grasp..release closure.
        #[arg(long)]
        log: Option<PathBuf>,
        /// Print the report as one JSON object.
        #[arg(long)]
        json: bool,
        /// Distance evaluations the collision checks of the plan (and of the log) may spend in
        /// all; once they are spent the rest is reported not certified, never free (0: no limit).
        #[arg(long, default_value_t = embodied::verify::DEFAULT_MAX_EVALUATIONS)]
        max_evaluations: usize,
    },
    /// Benchmarks: MotionBenchMaker problems, planning deadlines.
    #[command(subcommand)]
    Bench(Box<BenchCommand>),
    /// Print a shell completion script (e.g. `embodied completions bash > /etc/bash_completion.d/embodied`).
    Completions {
        /// The shell.
        shell: clap_complete::Shell,
    },
    /// Print the manual page (roff; e.g. `embodied man > embodied.1 && man ./embodied.1`).
    Man,
    /// The fault campaign: random scenarios (built-in robots and random URDF arms, obstacles
    /// on the map, appearing and moving, random goals, deadlines and injected faults), each
    /// run's log checked by the log verifier. Fails (exit status 1) if any run broke a promise.
    Campaign {
        /// Runs.
        #[arg(long, default_value_t = 100)]
        runs: usize,
        /// Seed of the first run (run k has seed S + k).
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Run every N-th run twice and compare the logs' bytes (0: never).
        #[arg(long, default_value_t = 20)]
        determinism_every: usize,
        /// Folder for the logs while they are checked (default: the system's temporary folder).
        #[arg(long)]
        dir: Option<PathBuf>,
        /// Print one JSON object instead of the table.
        #[arg(long)]
        json: bool,
        /// Keep every run's log in the folder (`campaign-SEED-PID.jsonl`), not only the logs of
        /// runs that broke a promise.
        #[arg(long)]
        keep_logs: bool,
        /// Run nothing: merge these `--json` reports of one campaign run in chunks (their seeds
        /// must make one range, no seed twice) and print the one report.
        #[arg(long, num_args = 1.., value_name = "REPORT.json", conflicts_with_all = ["runs", "seed", "keep_logs", "dir"])]
        merge: Vec<PathBuf>,
    },
    /// Feed every file loader structure-aware random inputs (generated documents with the
    /// formats' keys and tags, random values and nesting, cuts and byte edits; edits of
    /// well-formed files): counts per loader of inputs accepted, refused and panicking, the
    /// slowest input and the peak memory. Exit status 1 if an input panicked, took longer than
    /// --max-input-s or was refused with an error naming no file.
    Fuzz {
        /// One loader, or `all`: scenario, urdf, srdf, moveit-scene, moveit-request,
        /// joint-limits, stl, obj, collada, plan, trajectory, log, log-view.
        #[arg(long, default_value = "all")]
        loader: String,
        /// Inputs per loader.
        #[arg(long, default_value_t = 1000)]
        inputs: u64,
        /// Seed: input i of a loader is the same for the same seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// An input slower than this fails the run, s.
        #[arg(long, default_value_t = 1.0)]
        max_input_s: f64,
        /// Folder for the files the inputs refer to (default: the system's temporary folder).
        #[arg(long)]
        dir: Option<PathBuf>,
        /// Print one JSON object instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// List the built-in scenarios (name and one-line description).
    Scenarios {
        /// Print a JSON array of {"name", "description", "agents", "obstacles"}.
        #[arg(long)]
        json: bool,
    },
}

/// `embodied bench mbm`'s flags (a later flag takes the place of the same one given before:
/// `--versus` adds its flags after the command's).
#[derive(clap::Args, Debug, Clone)]
#[command(args_override_self = true)]
struct MbmCli {
    #[arg(long)]
    urdf: PathBuf,
    #[arg(long)]
    srdf: PathBuf,
    /// Folder of family folders (e.g. the unpacked problems/).
    #[arg(long)]
    problems: PathBuf,
    /// Print the whole report as JSON.
    #[arg(long)]
    json: bool,
    /// Write {"problems": [{family, index, solved, planning_us, joint_names, path}]} here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Planning deadline per problem, milliseconds.
    #[arg(long, default_value_t = 1000.0)]
    deadline_ms: f64,
    /// Only the first N problems of each family.
    #[arg(long)]
    limit: Option<usize>,
    /// Only these families (folder names, comma separated, e.g. `box_ur5,cage_ur5`; default:
    /// every family folder found).
    #[arg(long, value_delimiter = ',', value_name = "NAMES")]
    families: Vec<String>,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The planner after the straight segment: rrt-connect or lazy-prm.
    #[arg(long, default_value = "rrt-connect")]
    algorithm: embodied_planner::motion::PlannerKind,
    /// Check the planner's edges by sampling at this resolution (rad) instead of certifying
    /// them free for the whole continuum (the default).
    #[arg(long)]
    resolution: Option<f64>,
    /// Random shortcut attempts per path after the greedy pass (more: shorter paths, slower).
    #[arg(long)]
    shortcut_attempts: Option<usize>,
    /// The least share of the path's length a random shortcut must gain to be checked (0:
    /// any; the planner's default 0.01)
    #[arg(long)]
    shortcut_min_gain: Option<f64>,
    /// Shortcuts and straight segments longer than this (C-space distance) are screened by an
    /// eight-point probe before their certificate (`inf`: never; the planner's default 2)
    #[arg(long)]
    screen_above: Option<f64>,
    /// Planners racing per problem: `auto` (the default) as many as the cores this process
    /// may run on, at most 2 (so 1 under `taskset -c 1`); 1: one planner; 2: two differently
    /// seeded planners, the second on a thread of its own; the first path wins and stops the
    /// other.
    #[arg(long, default_value = "auto")]
    threads: String,
    /// With --threads above 1: how long the racer threads look for work after their last
    /// racer before they sleep, ms (default 50; 0: at once; at most 10,000).
    #[arg(long, value_name = "MS")]
    racer_look_ms: Option<f64>,
    /// RRT-Connect's largest step (rad).
    #[arg(long)]
    rrt_range: Option<f64>,
    /// The share of RRT-Connect's samples drawn near a node of the tree about to grow, in
    /// [0, 1] (default 0.5; 0: every sample over the whole joint box).
    #[arg(long)]
    rrt_local_bias: Option<f64>,
    /// That share once an attempt has drawn --rrt-late-after samples, in [0, 1] (default
    /// 0.9: a problem that needs that many is most often a narrow passage).
    #[arg(long)]
    rrt_late_local_bias: Option<f64>,
    /// Samples of an RRT-Connect attempt before --rrt-late-local-bias applies (default 128).
    #[arg(long)]
    rrt_late_after: Option<usize>,
    /// The half-width of those samples' box around their node, as a share of each joint's
    /// sampling width, above 0 (default 0.5; at most --rrt-local-reach).
    #[arg(long)]
    rrt_local_span: Option<f64>,
    /// The most a joint of those samples is drawn from its node's value, rad (m for a
    /// prismatic joint), above 0 (default 2; `inf`: the span alone).
    #[arg(long)]
    rrt_local_reach: Option<f64>,
    /// Samples an RRT-Connect attempt may draw before it starts again with new trees, at
    /// least 1 (default 50,000).
    #[arg(long, value_name = "N")]
    max_samples: Option<usize>,
    /// RRT-Connect attempts after the first (default 64): a problem with no path ends after
    /// (1 + N) x --max-samples samples, or at the deadline.
    #[arg(long, value_name = "N")]
    rrt_restarts: Option<usize>,
    /// With certified edges, RRT-Connect probes its tree edges at this step (rad, the
    /// largest joint change between probed points) and certifies them once they lie on a
    /// path; 0 certifies each as it is added (default 0.1).
    #[arg(long, value_name = "RAD")]
    lazy_probe: Option<f64>,
    /// RRT-Connect without dynamic domain (Yershova et al. 2005; on by default).
    #[arg(long)]
    no_dynamic_domain: bool,
    /// RRT-Connect searches every joint at once even on a robot of independent groups of
    /// joints (two arms on a fixed torso), instead of first one group at a time.
    #[arg(long)]
    no_by_groups: bool,
    /// With `--threads` above 1, a plan by groups of joints races seeds of the whole plan
    /// instead of searching its legs two at a time (one on each thread; the default).
    #[arg(long)]
    serial_legs: bool,
    /// RRT-Connect swaps its trees every iteration instead of growing the smaller one while
    /// the other has twice its nodes (the default).
    #[arg(long)]
    no_balance: bool,
    /// RRT-Connect with goal retreats: once an attempt has drawn --rrt-late-after samples,
    /// each goal gets a chain of eight nodes pulling the hand 3 cm a node towards the first
    /// joint of its chain (for goals deep in shelves; off by default)
    #[arg(long)]
    goal_retreat: bool,
    /// How RRT-Connect draws samples: uniform or halton.
    #[arg(long, default_value = "uniform")]
    sampler: embodied_planner::motion::Sampler,
    /// Plan only shard K of N of the problems (problem i, families and problems sorted, goes
    /// to shard (i mod N) + 1); join the shards' --jsonl files with `embodied bench merge`.
    #[arg(long, value_name = "K/N")]
    shard: Option<embodied::batch::Shard>,
    /// Write the results as JSON Lines here (`-`: standard output, the table then goes to
    /// standard error): a header line (version, commit, machine, date, shard, settings),
    /// then one line per problem and run.
    #[arg(long, value_name = "FILE")]
    jsonl: Option<PathBuf>,
    /// Plan every problem N times (run r with seed --seed + r).
    #[arg(long, default_value_t = 1, value_name = "N")]
    runs: usize,
    /// Write OMPL benchmark logs (the format ompl_benchmark_statistics.py reads for Planner
    /// Arena) into this folder, one <family>_<NNNN>.log per problem with every run.
    #[arg(long, value_name = "DIR")]
    ompl_log: Option<PathBuf>,
    /// Plan every problem twice, with the settings given (A) and with these flags added to them
    /// (B; e.g. "--rrt-range 0.8 --goal-retreat"), in turns (A first on every other problem),
    /// and compare B with A problem by problem: the ratios of planning time (geometric mean,
    /// 95% interval, median, sums), collision checks and path lengths. For settings whose
    /// difference is smaller than the machine's drift between two runs.
    #[arg(long, value_name = "FLAGS", allow_hyphen_values = true)]
    versus: Option<String>,
}

#[derive(Subcommand, Debug)]
#[allow(clippy::large_enum_variant, reason = "parsed once per process from the command line")]
enum BenchCommand {
    /// Plan every sceneNNNN.yaml/requestNNNN.yaml pair of each MotionBenchMaker family folder.
    Mbm(MbmCli),
    /// Generate MotionBenchMaker-style UR5 problems (cage, bookshelf_tall, bookshelf_thin,
    /// table_under_pick) as <out>/<family>_ur5/sceneNNNN.yaml and requestNNNN.yaml, the files
    /// `bench mbm` reads; goals by inverse kinematics, kept only within the joint limits and
    /// collision-free. The same seed gives the same files.
    MbmGenerate {
        #[arg(long)]
        urdf: PathBuf,
        #[arg(long)]
        srdf: PathBuf,
        /// cage, bookshelf_tall, bookshelf_thin, table_under_pick, or all.
        #[arg(long)]
        family: String,
        /// Problems per family (1 to 9999).
        #[arg(long, default_value_t = 100)]
        count: usize,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Folder of the family folders (created if missing).
        #[arg(long)]
        out: PathBuf,
        /// Print a JSON array of {family, folder, problems, scenes_sampled, ik_calls}.
        #[arg(long)]
        json: bool,
    },
    /// Join the --jsonl files of the shards of `bench mbm --shard` or `plan --batch --shard`
    /// into the report one unsharded run prints. Refuses files that overlap, miss problems or
    /// shards, or ran with different settings or programs.
    Merge {
        /// The shards' JSON Lines files.
        #[arg(required = true, value_name = "FILE")]
        files: Vec<PathBuf>,
        /// Print the whole report as JSON.
        #[arg(long)]
        json: bool,
        /// bench mbm: write {"problems": [...]} here, as `bench mbm --out` does.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// The closed-chain QP of a two-handed carry, every held step solved by the fast dense
    /// solver (which drives) and by clarabel: time percentiles, late steps, agreement.
    Qp {
        /// A scenario with a [carry] table.
        #[arg(default_value = "two-irp6-carry")]
        scenario: String,
        #[arg(long)]
        json: bool,
    },
    /// Many agents on one runtime, a share of them deliberative, all asking one bounded planning
    /// queue (earliest deadline first or first come first served) for their plans: the
    /// real-time factor, the step's wall time, requests answered in time or halted for, waits.
    /// Exit status 1 if a request went unanswered without a halt or an agent never got a plan.
    Load {
        /// Agents in all.
        #[arg(long, default_value_t = 1000)]
        agents: usize,
        /// Share of them that deliberate (0 to 1).
        #[arg(long, default_value_t = 0.5)]
        deliberative_share: f64,
        /// Planner workers serving the queue.
        #[arg(long, default_value_t = 2)]
        workers: usize,
        /// Queue order: edf (earliest deadline first) or fifo.
        #[arg(long, default_value = "edf", value_parser = ["edf", "fifo"])]
        policy: String,
        /// Simulated seconds.
        #[arg(long, default_value_t = 3.0)]
        duration: f64,
        /// When a plan is needed, ms after its request.
        #[arg(long, default_value_t = 50.0)]
        deadline_ms: f64,
        /// When a request is given up, ms after it.
        #[arg(long, default_value_t = 500.0)]
        give_up_ms: f64,
        /// Step the agents one after the other instead of on the rayon pool.
        #[arg(long)]
        sequential: bool,
        /// Where the planners run: `threads` (the queue's own planner threads, beside the
        /// control step) or `inline` (inside the steps, on the control thread). The events and
        /// queue figures are the same; only wall-clock figures differ.
        #[arg(long, default_value = "threads", value_parser = ["threads", "inline"])]
        planning: String,
        #[arg(long)]
        json: bool,
    },
    /// Share of plans delivered in time, safe halts and overshoot for a set of deadlines.
    Deadlines {
        /// Deadlines in milliseconds, comma separated.
        #[arg(long, default_value = "0.5,1,2,5,10,50", value_delimiter = ',')]
        deadlines_ms: Vec<f64>,
        /// Scenarios (default: every built-in scenario).
        #[arg(long, value_delimiter = ',')]
        scenarios: Vec<String>,
        #[arg(long)]
        json: bool,
        /// Write an SVG plot of delivered-in-time against deadline.
        #[arg(long)]
        plot: Option<PathBuf>,
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Plan every problem with this many planner seeds, each counted as a problem (the
        /// scenario's seed and the next ones; for the MotionBenchMaker sample --seed and the next
        /// ones), at least 1: one problem's time depends on its random stream far more than on a
        /// setting.
        #[arg(long, default_value_t = 1, value_name = "N")]
        planner_seeds: u64,
        /// Add a sample of MotionBenchMaker problems from this folder of family folders (e.g.
        /// the unpacked problems/); needs --urdf and --srdf.
        #[arg(long, requires_all = ["urdf", "srdf"])]
        mbm: Option<PathBuf>,
        /// The MotionBenchMaker robot's URDF.
        #[arg(long)]
        urdf: Option<PathBuf>,
        /// The MotionBenchMaker robot's SRDF.
        #[arg(long)]
        srdf: Option<PathBuf>,
        /// How many MotionBenchMaker problems, spread evenly over the families.
        #[arg(long, default_value_t = 30)]
        mbm_sample: usize,
    },
}

/// A spinner with elapsed time on standard error while a long verb works, only on a terminal.
fn spinner(message: &str) -> indicatif::ProgressBar {
    if !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new_spinner().with_message(message.to_string());
    if let Ok(style) = indicatif::ProgressStyle::with_template("{spinner} {msg} ({elapsed})") {
        bar.set_style(style);
    }
    bar.enable_steady_tick(std::time::Duration::from_millis(120));
    bar
}

/// A progress bar on standard error, only on a terminal.
fn progress_bar() -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::hidden();
    if std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
    }
    bar
}

/// Print a `bench mbm` report (table or JSON; to standard error when standard output carries
/// JSON Lines) and write its paths file.
fn print_mbm(
    report: &embodied::mbm::MbmReport,
    json: bool,
    out: Option<&std::path::Path>,
    stdout_taken: bool,
) -> Result<(), AppError> {
    if let Some(path) = out {
        std::fs::write(path, to_json(&report.paths_file())?).map_err(|e| AppError::write(path, e))?;
    }
    let text = if json { to_json(report)? + "\n" } else { embodied::mbm::render_table(report) };
    if stdout_taken {
        eprint!("{text}");
    } else {
        out!("{text}");
    }
    Ok(())
}

fn to_json<T: serde::Serialize>(value: &T) -> Result<String, AppError> {
    serde_json::to_string(value).map_err(|e| AppError::Failed(e.to_string()))
}

/// The most racers `--threads auto` starts: two measured better than one on a two-core machine
/// (MotionBenchMaker UR5, two rounds: cage 79-83% -> 91-92% within 1 ms, max 6.7-8.6 -> 2.5-2.6
/// ms; the median within noise); more are not measured.
const AUTO_RACERS: usize = 2;

/// A flag's value when it is given and `ok` holds; otherwise a usage error `says, got VALUE`.
/// (`ok` sees NaN as it is: a comparison with NaN is false, so NaN is refused unless `ok` says
/// otherwise.)
fn checked<T: Copy + std::fmt::Display>(
    value: Option<T>,
    ok: impl Fn(T) -> bool,
    says: &str,
) -> Result<Option<T>, AppError> {
    match value {
        Some(v) if !ok(v) => Err(AppError::Usage(format!("{says}, got {v}"))),
        _ => Ok(value),
    }
}

/// `--threads`: `auto` (the cores this process may run on, at most [`AUTO_RACERS`]) or a count
/// of at least 1.
fn racers_of(value: &str) -> Result<usize, AppError> {
    if value == "auto" {
        let cores = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get);
        return Ok(cores.min(AUTO_RACERS));
    }
    match value.parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(AppError::Usage(format!("--threads must be `auto` or a count of at least 1, got `{value}`"))),
    }
}

/// `bench mbm --families`: the names given (trimmed, each once, in their order), or `None` (every
/// family) when none is.
fn mbm_families(names: Vec<String>) -> Result<Option<Vec<String>>, AppError> {
    let mut wanted: Vec<String> = Vec::new();
    for name in names {
        let name = name.trim();
        if name.is_empty() {
            return Err(AppError::Usage(
                "--families must be family folder names separated by commas, got an empty name".into(),
            ));
        }
        if !wanted.iter().any(|w| w == name) {
            wanted.push(name.to_string());
        }
    }
    Ok((!wanted.is_empty()).then_some(wanted))
}

/// The benchmark's arguments from `bench mbm`'s flags (each value checked; the racer threads'
/// look, a setting of the process, is set here).
fn mbm_args(cli: &MbmCli) -> Result<embodied::mbm::MbmArgs, AppError> {
    let MbmCli {
        urdf,
        srdf,
        problems,
        deadline_ms,
        limit,
        families,
        seed,
        algorithm,
        resolution,
        shortcut_attempts,
        shortcut_min_gain,
        screen_above,
        threads,
        racer_look_ms,
        rrt_range,
        rrt_local_bias,
        rrt_late_local_bias,
        rrt_late_after,
        rrt_local_span,
        rrt_local_reach,
        max_samples,
        rrt_restarts,
        lazy_probe,
        no_dynamic_domain,
        no_by_groups,
        serial_legs,
        no_balance,
        goal_retreat,
        sampler,
        shard,
        runs,
        ..
    } = cli.clone();
    let threads = racers_of(&threads)?;
    if let Some(ms) = racer_look_ms {
        if !(ms.is_finite() && ms >= 0.0) {
            return Err(AppError::Usage(format!("--racer-look-ms must be a number of ms, at least 0, got {ms}")));
        }
        // At most 10 s (the planner's cap too), so that no value overflows here.
        let look = std::time::Duration::from_secs_f64(ms.min(10_000.0) / 1000.0);
        embodied_planner::motion::set_racer_look(look);
    }
    let mut args = embodied::mbm::MbmArgs::new(urdf, srdf, problems);
    args.algorithm = algorithm;
    args.threads = threads;
    args.dynamic_domain = !no_dynamic_domain;
    args.by_groups = !no_by_groups;
    args.parallel_legs = !serial_legs;
    args.balance = !no_balance;
    args.goal_retreat = goal_retreat;
    args.sampler = sampler;
    let share = |p: f64| (0.0..=1.0).contains(&p);
    if let Some(r) = checked(rrt_range, |r| r.is_finite() && r > 0.0, "--rrt-range must be a positive number")? {
        args.rrt_range = r;
    }
    if let Some(p) = checked(rrt_local_bias, share, "--rrt-local-bias must be a share in [0, 1]")? {
        args.rrt_local_bias = p;
    }
    if let Some(p) = checked(rrt_late_local_bias, share, "--rrt-late-local-bias must be a share in [0, 1]")? {
        args.rrt_late_local_bias = p;
    }
    if let Some(n) = rrt_late_after {
        args.rrt_late_after = n;
    }
    let says = "--rrt-local-span must be a positive share";
    if let Some(w) = checked(rrt_local_span, |w| w.is_finite() && w > 0.0, says)? {
        args.rrt_local_span = w;
    }
    let says = "--rrt-local-reach must be above 0 (rad, or `inf`)";
    if let Some(r) = checked(rrt_local_reach, |r| r > 0.0, says)? {
        args.rrt_local_reach = r;
    }
    if let Some(n) = checked(max_samples, |n| n > 0, "--max-samples must be at least 1")? {
        args.max_samples = n;
    }
    if let Some(n) = rrt_restarts {
        args.rrt_restarts = n;
    }
    let says = "--lazy-probe must be 0 (every tree edge certified as added) or a positive number of rad";
    if let Some(step) = checked(lazy_probe, |s| s.is_finite() && s >= 0.0, says)? {
        args.lazy_probe = step;
    }
    if let Some(r) = resolution {
        args.resolution = r;
        args.edge_check = embodied_planner::motion::EdgeCheck::Sampled;
    }
    if let Some(n) = shortcut_attempts {
        args.shortcut_attempts = n;
    }
    let says = "--shortcut-min-gain must be zero or a positive number";
    if let Some(g) = checked(shortcut_min_gain, |g| g.is_finite() && g >= 0.0, says)? {
        args.shortcut_min_gain = g;
    }
    if let Some(l) = checked(screen_above, |l| l >= 0.0, "--screen-above must be zero, a positive number or inf")? {
        args.screen_above = l;
    }
    args.deadline_ms = deadline_ms;
    args.limit = limit;
    args.families = mbm_families(families)?;
    args.seed = seed;
    args.runs = runs;
    args.shard = shard.unwrap_or(embodied::batch::Shard::ALL);
    Ok(args)
}

/// `bench mbm --versus FLAGS`: the command line again with `FLAGS` added at its end (in place
/// of the same flags given before, see [`MbmCli`]) gives B's settings; every problem is planned
/// with both in turns and the comparison printed.
fn run_mbm_versus(cli: &MbmCli, args: &embodied::mbm::MbmArgs, flags: &str) -> Result<(), AppError> {
    if cli.shard.is_some() || cli.jsonl.is_some() || cli.ompl_log.is_some() || cli.out.is_some() {
        return Err(AppError::Usage(
            "--versus reports both settings in one report: it takes no --shard, --jsonl, --ompl-log or --out".into(),
        ));
    }
    let mut argv: Vec<std::ffi::OsString> = Vec::new();
    let mut given = std::env::args_os();
    while let Some(token) = given.next() {
        if token == "--versus" {
            given.next();
        } else if !token.to_string_lossy().starts_with("--versus=") {
            argv.push(token);
        }
    }
    argv.extend(flags.split_whitespace().map(std::ffi::OsString::from));
    let bad = |why: String| AppError::Usage(format!("--versus `{flags}`: {why}"));
    let parsed = Cli::try_parse_from(&argv).map_err(|e| {
        let text = e.to_string();
        let first = text.lines().next().unwrap_or("");
        bad(first.strip_prefix("error: ").unwrap_or(first).to_string())
    })?;
    let Command::Bench(bench) = parsed.command else { return Err(bad("not a bench mbm command".into())) };
    let BenchCommand::Mbm(other) = *bench else { return Err(bad("not a bench mbm command".into())) };
    if other.versus.is_some() {
        return Err(bad("B cannot have a --versus of its own".into()));
    }
    if other.racer_look_ms != cli.racer_look_ms {
        return Err(bad("--racer-look-ms is a setting of the whole process; it cannot differ between A and B".into()));
    }
    let b = mbm_args(&other)?;
    let bar = if cli.json { indicatif::ProgressBar::hidden() } else { progress_bar() };
    let report = embodied::mbm::versus::run_versus(args, &b, flags, &mut |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    });
    bar.finish_and_clear();
    let report = report?;
    if cli.json {
        outln!("{}", to_json(&report)?);
    } else {
        out!("{}", embodied::mbm::versus::render_versus(&report));
    }
    Ok(())
}

/// `embodied bench ...`.
fn run_bench(bench: BenchCommand) -> Result<(), AppError> {
    match bench {
        BenchCommand::Mbm(cli) => {
            let args = mbm_args(&cli)?;
            if let Some(flags) = &cli.versus {
                return run_mbm_versus(&cli, &args, flags);
            }
            let MbmCli { json, out, jsonl, ompl_log, .. } = cli;
            let mut writer = jsonl.as_deref().map(embodied::batch::JsonlWriter::create).transpose()?;
            let bar = if json { indicatif::ProgressBar::hidden() } else { progress_bar() };
            let report = embodied::mbm::run_mbm_to(
                &args,
                &mut |done, total| {
                    bar.set_length(total as u64);
                    bar.set_position(done as u64);
                },
                writer.as_mut(),
            );
            bar.finish_and_clear();
            let report = report?;
            if let Some(dir) = &ompl_log {
                embodied::ompl_log::write_ompl_logs(&report, dir)?;
            }
            print_mbm(&report, json, out.as_deref(), jsonl.as_deref() == Some(std::path::Path::new("-")))
        }
        BenchCommand::MbmGenerate { urdf, srdf, family, count, seed, out, json } => {
            let families = embodied::mbm_generate::parse_families(&family)?;
            let args = embodied::mbm_generate::GenerateArgs { urdf, srdf, families, count, seed, out };
            let bar = if json { indicatif::ProgressBar::hidden() } else { progress_bar() };
            let outcomes = embodied::mbm_generate::generate_mbm(&args, &mut |family, done, total| {
                bar.set_message(family.folder());
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            });
            bar.finish_and_clear();
            let outcomes = outcomes?;
            let text = if json {
                to_json(&outcomes)? + "\n"
            } else {
                let mut t = format!("{:<24} {:>8} {:>14} {:>9}\n", "family", "problems", "scenes sampled", "IK calls");
                for o in &outcomes {
                    t.push_str(&format!(
                        "{:<24} {:>8} {:>14} {:>9}  {}\n",
                        o.family,
                        o.problems,
                        o.scenes_sampled,
                        o.ik_calls,
                        o.folder.display()
                    ));
                }
                t
            };
            std::io::Write::write_all(&mut std::io::stdout(), text.as_bytes()).map_err(AppError::Output)
        }
        BenchCommand::Merge { files, json, out } => {
            let merged = embodied::batch::read_shards(&files)?;
            if merged.header.kind == embodied::batch_plan::PLAN_BATCH_KIND {
                if out.is_some() {
                    return Err(AppError::Usage("--out writes the paths of bench mbm shards; these are plan --batch results, whose lines hold the plans".into()));
                }
                let report = embodied::batch_plan::merge_plan_batch(merged)?;
                if json {
                    outln!("{}", to_json(&report)?);
                } else {
                    out!("{}", embodied::batch_plan::render_batch(&report));
                }
                if report.certified < report.total {
                    return Err(AppError::Failed(format!(
                        "{} of {} problems without a certified plan",
                        report.total - report.certified,
                        report.total
                    )));
                }
                return Ok(());
            }
            let report = embodied::mbm::merge_mbm(merged)?;
            print_mbm(&report, json, out.as_deref(), false)
        }
        BenchCommand::Load {
            agents,
            deliberative_share,
            workers,
            policy,
            duration,
            deadline_ms,
            give_up_ms,
            sequential,
            planning,
            json,
        } => {
            use embodied_executor::deliberation::QueuePolicy;
            let settings = embodied::load::LoadSettings {
                agents,
                deliberative_share,
                workers,
                policy: if policy == "fifo" { QueuePolicy::Fifo } else { QueuePolicy::EarliestDeadline },
                duration_s: duration,
                deadline_ms,
                give_up_ms,
                parallel: !sequential,
                planner_threads: planning == "threads",
                ..embodied::load::LoadSettings::default()
            };
            let bar = spinner("running");
            let report = embodied::load::run_load(&settings);
            bar.finish_and_clear();
            let report = report?;
            if json {
                outln!("{}", to_json(&report)?);
            } else {
                out!("{}", embodied::load::render_load(&report));
            }
            if report.unanswered_without_halt > 0 || report.starved_agents > 0 {
                return Err(AppError::Failed(
                    "a request went unanswered without a halt, or an agent got no plan".into(),
                ));
            }
            Ok(())
        }
        BenchCommand::Qp { scenario, json } => {
            let bar = spinner("solving every held step's QP twice");
            let report = embodied::bench_qp::bench_qp(&scenario);
            bar.finish_and_clear();
            let report = report?;
            if json {
                outln!("{}", to_json(&report)?);
            } else {
                out!("{}", embodied::bench_qp::render_bench_qp(&report));
            }
            Ok(())
        }
        BenchCommand::Deadlines {
            deadlines_ms,
            scenarios,
            json,
            plot,
            seed,
            planner_seeds,
            mbm,
            urdf,
            srdf,
            mbm_sample,
        } => {
            checked(Some(planner_seeds), |n| n > 0, "--planner-seeds must be at least 1")?;
            let mbm = match (mbm, urdf, srdf) {
                (Some(problems), Some(urdf), Some(srdf)) => {
                    Some(embodied::deadlines::MbmSample { urdf, srdf, problems, count: mbm_sample })
                }
                (None, None, None) => None,
                _ => return Err(AppError::Usage("--mbm, --urdf and --srdf go together".into())),
            };
            // The built-in scenarios always, the MBM sample when asked for.
            let scenarios = if scenarios.is_empty() && mbm.is_some() {
                embodied::scenario::BUILTIN_SCENARIOS.iter().map(|(n, _)| (*n).to_string()).collect()
            } else {
                scenarios
            };
            let args = embodied::deadlines::DeadlineArgs {
                deadlines_ms,
                scenarios,
                seed,
                planner_seeds,
                mbm,
                ..embodied::deadlines::DeadlineArgs::default()
            };
            let bar = spinner("planning under every deadline");
            let report = embodied::deadlines::run_deadline_bench(&args);
            bar.finish_and_clear();
            let report = report?;
            if let Some(path) = &plot {
                embodied::deadlines::plot_svg(&report, path)?;
            }
            if json {
                outln!("{}", to_json(&report)?);
            } else {
                out!("{}", embodied::deadlines::render_table(&report));
            }
            Ok(())
        }
    }
}

fn run(cli: Cli) -> Result<(), AppError> {
    match cli.command {
        Command::Model { robot, srdf, q, ik, ee, json } => {
            let robot = load_robot(&robot, srdf.as_deref())?;
            let q = match q {
                Some(text) => parse_q(&robot, &text)?,
                None => robot.home().to_vec(),
            };
            let mut report = model_report(&robot, &q);
            if let Some(text) = ik {
                report.ik = Some(embodied::model_report::ik_report(&robot, &q, &text, ee.as_deref())?);
            }
            if json {
                let text = serde_json::to_string(&report).map_err(|e| AppError::Failed(e.to_string()))?;
                outln!("{text}");
            } else {
                out!("{}", render_text(&report));
            }
            if report.ik.as_ref().is_some_and(|r| r.solutions.is_empty()) {
                std::process::exit(1);
            }
            Ok(())
        }
        Command::Run { scenario, duration, seed, log, plot, html, json, clock, us_per_check } => {
            use embodied::scenario::ClockSpec;
            let scenario = scenario.unwrap_or_else(|| embodied::scenario::DEFAULT_SCENARIO.to_string());
            let clock = match (clock.as_deref(), us_per_check) {
                (_, Some(us)) if !(us.is_finite() && us >= 0.0) => {
                    return Err(AppError::Usage(format!("--us-per-check must be a time >= 0 µs, got {us}")));
                }
                (Some("wall"), Some(_)) => {
                    return Err(AppError::Usage("--us-per-check needs --clock simulated".into()));
                }
                (Some("wall"), None) => Some(ClockSpec::Wall),
                (_, Some(us)) => Some(ClockSpec::Simulated { us_per_check: us }),
                (Some(_), None) => {
                    let sc = embodied::scenario::load_scenario(&scenario)?;
                    Some(match sc.planner.clock {
                        ClockSpec::Simulated { us_per_check } => ClockSpec::Simulated { us_per_check },
                        ClockSpec::Wall => {
                            ClockSpec::Simulated { us_per_check: embodied::scenario::DEFAULT_US_PER_CHECK }
                        }
                    })
                }
                (None, None) => None,
            };
            if let Some(d) = duration
                && !(d.is_finite() && d > 0.0)
            {
                return Err(AppError::Usage(format!("--duration must be a positive number of seconds, got {d}")));
            }
            let html_note = html.clone();
            let options = embodied::system::RunOptions { duration, seed, clock, ..Default::default() };
            let args = embodied::system::RunArgs { scenario, options, log, plot, html };
            let bar = spinner("running");
            let result = embodied::system::run_scenario(&args);
            bar.finish_and_clear();
            let (summary, _) = result?;
            if json {
                outln!("{}", serde_json::to_string(&summary).map_err(|e| AppError::Failed(e.to_string()))?);
            } else {
                out!("{}", embodied::system::render_summary(&summary));
                match &html_note {
                    Some(path) => outln!("viewer page written to {} (open it in a browser)", path.display()),
                    None => outln!("to see it in 3-D: embodied run --html run.html (or embodied view RUN.jsonl)"),
                }
            }
            // An agent with a goal (it asked for a plan, got one or has a goal distance) that did
            // not reach it: the run did not succeed.
            let unreached: Vec<&str> = summary
                .agents
                .iter()
                .filter(|a| (a.plans_requested > 0 || a.planned || a.goal_error.is_some()) && !a.goal_reached)
                .map(|a| a.name.as_str())
                .collect();
            match summary.failure {
                Some(f) => Err(AppError::Failed(format!("run failed: {f}"))),
                None if !unreached.is_empty() => {
                    Err(AppError::Failed(format!("goal not reached by: {}", unreached.join(", "))))
                }
                None => Ok(()),
            }
        }
        Command::Plan { batch: Some(batch), urdf, srdf, limits, deadline_ms, shard, jsonl, scene, .. } => {
            if scene.is_some() {
                return Err(AppError::Usage("--scene goes with --request; a --batch folder holds its scenes".into()));
            }
            let args = embodied::batch_plan::BatchPlanArgs {
                input: batch,
                urdf,
                srdf,
                limits,
                deadline_ms,
                shard: shard.unwrap_or(embodied::batch::Shard::ALL),
            };
            let mut writer = jsonl.as_deref().map(embodied::batch::JsonlWriter::create).transpose()?;
            let bar = progress_bar();
            let report = embodied::batch_plan::plan_batch(&args, writer.as_mut(), &mut |done, total| {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            });
            bar.finish_and_clear();
            let report = report?;
            let text = embodied::batch_plan::render_batch(&report);
            if jsonl.as_deref() == Some(std::path::Path::new("-")) {
                eprint!("{text}");
            } else {
                out!("{text}");
            }
            if report.certified < report.total {
                return Err(AppError::Failed(format!(
                    "{} of {} problems without a certified plan",
                    report.total - report.certified,
                    report.total
                )));
            }
            Ok(())
        }
        Command::Plan { request: Some(request), urdf, srdf, scene, limits, format, out, deadline_ms, .. } => {
            let (Some(urdf), Some(srdf), Some(scene)) = (urdf, srdf, scene) else {
                return Err(AppError::Usage("--request needs --urdf, --srdf and --scene".into()));
            };
            let args = embodied::moveit_cli::MoveitPlanArgs { urdf, srdf, scene, request, limits, deadline_ms };
            let format = format.unwrap_or(embodied::moveit_cli::PlanFormat::JointTrajectory);
            let bar = spinner("planning");
            let result = embodied::moveit_cli::plan_moveit(&args, format, out.as_deref());
            bar.finish_and_clear();
            let (text, summary) = result?;
            match out {
                Some(path) => {
                    std::fs::write(&path, &text).map_err(|e| AppError::write(&path, e))?;
                    outln!("{summary}\nplan written to {}", path.display());
                }
                None => out!("{text}"),
            }
            Ok(())
        }
        Command::Plan { scenario, out, deadline_ms, json, format, html, urdf, .. } => {
            if urdf.is_some() {
                return Err(AppError::Usage("--urdf goes with --request or --batch, not with a scenario".into()));
            }
            let scenario = embodied::scenario::load_scenario(&scenario.unwrap_or_default())?;
            let bar = spinner("planning");
            let plan = embodied::plan::plan_scenario(&scenario, deadline_ms);
            bar.finish_and_clear();
            let plan = plan?;
            if let Some(path) = &html {
                let track = embodied::view::track_from_plan(&scenario, &plan)?;
                let title = format!("{}: plan", scenario.name);
                let scene = embodied::view::build_scene(&scenario, &track, &title, "embodied plan")?;
                embodied::view::write_html(path, &scene)?;
            }
            let text = match format {
                Some(embodied::moveit_cli::PlanFormat::JointTrajectory) => {
                    embodied::moveit_cli::plan_file_as_joint_trajectory(&plan, out.as_deref())?
                }
                _ => to_json(&plan)?,
            };
            match out {
                Some(path) => {
                    std::fs::write(&path, &text).map_err(|e| AppError::write(&path, e))?;
                    let summary: Vec<serde_json::Value> = plan
                        .plans
                        .iter()
                        .map(|p| serde_json::json!({"agent": p.agent, "duration_s": p.trajectory.duration(), "waypoints": p.path.len(), "stats": p.stats}))
                        .collect();
                    if json {
                        outln!("{}", serde_json::json!({"plan_file": path, "plans": summary}));
                    } else {
                        for p in &plan.plans {
                            outln!(
                                "{}: {} waypoints, {:.3} s of motion, planned by {} in {} us",
                                p.agent,
                                p.path.len(),
                                p.trajectory.duration(),
                                p.stats["planner"].as_str().unwrap_or("?"),
                                p.stats["planning_ms"].as_f64().map_or(
                                    p.stats["elapsed"]["secs"].as_f64().unwrap_or(0.0) * 1e6
                                        + p.stats["elapsed"]["nanos"].as_f64().unwrap_or(0.0) / 1e3,
                                    |ms| ms * 1e3
                                )
                            );
                        }
                        outln!("plan written to {}", path.display());
                    }
                }
                None => outln!("{text}"),
            }
            Ok(())
        }
        Command::View { input, scenario, out } => {
            let out = out.unwrap_or_else(|| input.with_extension("html"));
            if out == input {
                return Err(AppError::Usage(format!(
                    "{}: the page would overwrite its input; pass -o",
                    input.display()
                )));
            }
            let bar = spinner("building the scene");
            let scene = embodied::view::view_file(&input, scenario.as_deref());
            bar.finish_and_clear();
            let scene = scene?;
            embodied::view::write_html(&out, &scene)?;
            outln!(
                "viewer page written to {} ({} frames, {} bodies, {} events)",
                out.display(),
                scene.times.len(),
                scene.bodies.len(),
                scene.events.len()
            );
            Ok(())
        }
        Command::Verify { scenario, plan, log, json, trajectory, urdf, srdf, scene, limits, max_evaluations } => {
            let max_evaluations = (max_evaluations > 0).then_some(max_evaluations);
            let certified = match (trajectory, urdf) {
                (Some(t), Some(u)) => embodied::moveit_cli::verify_joint_trajectory(
                    &u,
                    srdf.as_deref(),
                    scene.as_deref(),
                    limits.as_deref(),
                    &t,
                    json,
                    max_evaluations,
                )?,
                _ => {
                    let settings = embodied_planner::verify::CheckSettings { max_evaluations, ..Default::default() };
                    let v = embodied::verify::verify_files(
                        &scenario.unwrap_or_default(),
                        plan.as_deref(),
                        log.as_deref(),
                        &settings,
                    )?;
                    if json {
                        outln!("{}", v.to_json()?);
                    } else {
                        out!("{}", v.render());
                    }
                    v.certified
                }
            };
            if !certified {
                // Checked and not certified: a status of its own (2 is bad input).
                use std::io::Write;
                let _ = std::io::stdout().flush();
                std::process::exit(i32::from(embodied::verify::EXIT_NOT_CERTIFIED));
            }
            Ok(())
        }
        Command::Bench(bench) => run_bench(*bench),
        Command::Completions { shell } => {
            use clap::CommandFactory;
            let mut script = Vec::new();
            clap_complete::generate(shell, &mut Cli::command(), "embodied", &mut script);
            out!("{}", String::from_utf8_lossy(&script));
            Ok(())
        }
        Command::Man => {
            use clap::CommandFactory;
            let mut page = Vec::new();
            clap_mangen::Man::new(Cli::command())
                .render(&mut page)
                .map_err(|e| AppError::Failed(format!("man page: {e}")))?;
            out!("{}", String::from_utf8_lossy(&page));
            Ok(())
        }
        Command::Campaign { merge, json, .. } if !merge.is_empty() => {
            let mut reports = Vec::new();
            for file in merge {
                let text = embodied::error::read_input(&file, embodied_models::formats::limits::InputKind::Text)?;
                let report: embodied::campaign::CampaignReport =
                    serde_json::from_str(&text).map_err(|e| AppError::Parse {
                        file: file.clone(),
                        line: e.line(),
                        column: e.column(),
                        message: format!("expected a report of `embodied campaign --json`: {e}"),
                    })?;
                reports.push((file, report));
            }
            let report = embodied::campaign::merge_reports(&reports)?;
            print_campaign(&report, json)
        }
        Command::Campaign { runs, seed, determinism_every, dir, json, keep_logs, .. } => {
            // Injected planner panics are caught and answered; only other panics are printed.
            let default_hook = std::panic::take_hook();
            std::panic::set_hook(Box::new(move |info| {
                let injected = info.payload().downcast_ref::<&str>().is_some_and(|m| m.starts_with("injected fault"));
                if !injected {
                    default_hook(info);
                }
            }));
            let dir =
                dir.unwrap_or_else(|| std::env::temp_dir().join(format!("embodied-campaign-{}", std::process::id())));
            let settings =
                embodied::campaign::CampaignSettings { runs, seed, determinism_every, dir: dir.clone(), keep_logs };
            // Progress on stderr every 100 runs: runs done, runs that broke a promise (seeds).
            let (mut done, mut bad) = (0usize, Vec::new());
            let report = embodied::campaign::campaign(&settings, |r| {
                done += 1;
                if r.violated() {
                    bad.push(r.seed);
                }
                if done.is_multiple_of(100) {
                    eprintln!("{done} runs, {} broke a promise {:?}", bad.len(), bad);
                }
            })?;
            let _ = std::fs::remove_dir(&dir);
            print_campaign(&report, json)
        }
        Command::Fuzz { loader, inputs, seed, max_input_s, dir, json } => {
            let loaders: Vec<String> = if loader == "all" {
                embodied::fuzz::LOADERS.iter().map(|l| (*l).to_string()).collect()
            } else {
                loader.split(',').map(str::to_string).collect()
            };
            let dir = dir.unwrap_or_else(|| std::env::temp_dir().join(format!("embodied-fuzz-{}", std::process::id())));
            let settings = embodied::fuzz::FuzzSettings { loaders, inputs, seed, dir };
            let report = embodied::fuzz::fuzz(&settings, |r| {
                eprintln!(
                    "{}: {} inputs, {} accepted, {} refused, {} panics, slowest {:.1} ms (input {}), peak {:.0} MB, {:.1} s",
                    r.loader,
                    r.inputs,
                    r.accepted,
                    r.refused,
                    r.panics,
                    r.slowest_s * 1e3,
                    r.slowest_input,
                    r.peak_rss_mb,
                    r.time_s
                );
            })?;
            if json {
                outln!("{}", to_json(&report)?);
            } else {
                out!("{}", embodied::fuzz::render(&report));
            }
            if report.failed(max_input_s) {
                return Err(AppError::Failed(format!(
                    "a loader panicked, took longer than {max_input_s} s or named no file (see the report)"
                )));
            }
            Ok(())
        }
        Command::Scenarios { json } => {
            let mut list = Vec::new();
            for (name, _) in embodied::scenario::BUILTIN_SCENARIOS {
                let sc = embodied::scenario::load_scenario(name)?;
                list.push(serde_json::json!({
                    "name": name,
                    "description": sc.description,
                    "agents": sc.agents.iter().map(|a| a.name.clone()).collect::<Vec<_>>(),
                    "obstacles": sc.obstacles.len(),
                    "default": *name == embodied::scenario::DEFAULT_SCENARIO,
                }));
            }
            if json {
                outln!("{}", serde_json::Value::Array(list));
            } else {
                for item in &list {
                    let default = if item["default"] == true { " (default)" } else { "" };
                    outln!(
                        "{:<22} {}{}",
                        item["name"].as_str().unwrap_or(""),
                        item["description"].as_str().unwrap_or(""),
                        default
                    );
                }
            }
            Ok(())
        }
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    embodied_models::urdf::set_urdf_defaults(embodied_models::urdf::UrdfDefaults {
        package_dirs: cli.package_path.clone(),
        allow_missing_meshes: cli.allow_missing_meshes,
    });
    embodied_models::formats::set_warning_sink(|w| eprintln!("{w}"));
    let mut limits = embodied_models::formats::limits::InputLimits::default();
    if let Some(mb) = cli.max_input_mb {
        limits.max_text_bytes = mb.saturating_mul(embodied_models::formats::limits::MIB);
        limits.max_mesh_bytes = limits.max_text_bytes;
        limits.max_log_bytes = limits.max_text_bytes.saturating_mul(16);
    }
    if let Some(n) = cli.max_input_values {
        limits.max_values = n;
    }
    if let Some(n) = cli.max_mesh_triangles {
        limits.max_mesh_triangles = n;
    }
    if let Some(n) = cli.max_links {
        limits.max_links = n;
    }
    embodied_models::formats::limits::set_input_limits(limits);
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // A closed standard output is not worth a word: the reader has what it wanted.
            if !matches!(&e, AppError::Output(io) if io.kind() == std::io::ErrorKind::BrokenPipe) {
                eprintln!("error: {e}");
            }
            ExitCode::from(e.exit_code())
        }
    }
}

/// A campaign's report as a table (or JSON); an error (exit status 1) when a run broke a promise.
fn print_campaign(report: &embodied::campaign::CampaignReport, json: bool) -> Result<(), AppError> {
    if json {
        outln!("{}", to_json(report)?);
    } else {
        out!("{}", embodied::campaign::render_campaign(report));
    }
    if report.violating_runs > 0 {
        return Err(AppError::Failed(format!("{} of {} runs broke a promise", report.violating_runs, report.runs)));
    }
    Ok(())
}
