//! `mdrlat`: the command line of the mdrlat toolkit. Argument parsing and glue only; the
//! work happens in the library crates.

/// `println!` that ends the program quietly when stdout is closed (`mdrlat … | head`)
/// instead of panicking.
macro_rules! out {
    ($($t:tt)*) => {
        $crate::emit(format_args!($($t)*))
    };
}

/// mimalloc instead of glibc malloc: the learner allocates and frees multi-megabyte
/// tensors every step, which glibc returns to the OS and faults back in (see
/// docs/performance.md).
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// Tells mimalloc to keep the memory it frees instead of purging it back to the OS after its
/// default 10 ms: a learner step (longer than that for MDRLAT) frees its multi-megabyte buffers and
/// allocates them again in the next step, and purged memory comes back through page faults and the
/// kernel zeroing every page again (17,000 faults and a visible share of the learner's time in
/// `clear_page_erms` over a 3-second `bench train --variants mdrlat`; 530 faults without the purge;
/// see docs/performance.md). The process keeps its peak footprint, which a training run reaches in
/// its first steps anyway. `MIMALLOC_PURGE_DELAY` in the environment still decides when set.
#[allow(unsafe_code)]
fn keep_freed_memory() {
    if std::env::var_os("MIMALLOC_PURGE_DELAY").is_some() {
        return;
    }
    // `mi_option_purge_delay`, the 16th option of mimalloc's `mi_option_e` (in both its v2
    // and v3 headers; libmimalloc-sys 0.1.49, pinned, names no constant for it).
    const PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;
    // SAFETY: setting an option stores a value in mimalloc's option table; any value is
    // valid for this option (-1: never purge) and it may be set at any time.
    unsafe { libmimalloc_sys::mi_option_set(PURGE_DELAY, -1) };
}

mod cmd;
mod config;
mod progress;

use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

/// Multimodal deep-RL obstacle avoidance (MDRLAT, Song et al. 2021): a fast 2.5D simulator
/// with a 2D laser and a depth camera.
#[derive(Debug, Parser)]
#[command(name = "mdrlat", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Runs a seeded episode in a built-in world, writes a GIF, pictures and the trajectory,
    /// evaluates the scripted baselines in `office` (a small success table), then
    /// benchmarks the simulator. The first thing to run.
    Demo(cmd::demo::Args),
    /// Lists the built-in worlds.
    Worlds,
    /// Works with world files.
    #[command(subcommand)]
    World(WorldCommand),
    /// Writes what both sensors see at a pose: laser.npy, depth.npy (metres) and view.png.
    Observe(cmd::observe::Args),
    /// Draws a world from above with the robot, its laser rays and its depth image beside.
    Render(cmd::render::Args),
    /// Runs one episode with a scripted policy and writes its trajectory as CSV (and a GIF).
    Rollout(cmd::rollout::Args),
    /// Trains an agent (paper Algorithm 1) into a run directory: config.toml, metrics.csv,
    /// eval.csv, model.safetensors.
    Train(cmd::train::Args),
    /// Evaluates a trained run or a scripted policy by the paper's protocol: success rate
    /// (no collision within 300 steps) over 5 runs of 50 seeded episodes per world.
    Eval(cmd::eval::Args),
    /// The paper's evaluation section in one command: trains the six variants, evaluates
    /// them in the unseen worlds, writes Table 2 beside the paper's numbers, Fig. 4 and a
    /// report. Resumable; runs here or on a Slurm cluster.
    Reproduce(cmd::reproduce::Args),
    /// Compares a trained network's Q-values along its own greedy episodes with the returns
    /// they earned; the reward's terms; the TD error by action.
    Diagnose(cmd::diagnose::Args),
    /// Writes a trained run's network as a model folder to ship: model.safetensors (f16 by
    /// default) and a README with its Q-value difference to f32 and its success table.
    Export(cmd::export::Args),
    /// Draws smoothed training curves of runs (paper Fig. 4) as a PNG.
    Plot(cmd::plot::Args),
    /// Drives a robot with a trained policy as a ROS 1 node: laser, depth and odometry in,
    /// velocity commands out at 5 Hz, zero velocity whenever a sensor is stale or malformed.
    Ros(cmd::ros::Args),
    /// Runs the simulator as a ROS 1 robot (turtlebot2 with RPLIDAR and Kinect): publishes
    /// laser, depth and odometry, moves from /cmd_vel.
    RosSim(cmd::ros::SimArgs),
    /// The same node on ROS 2 (DDS, pure Rust): LaserScan, Image and Odometry in, Twist or
    /// TwistStamped out, ROS_DOMAIN_ID honoured, the same safety rules.
    Ros2(cmd::ros2::Args),
    /// The simulator as a ROS 2 robot: publishes scan, depth and odometry as drivers do,
    /// moves from /cmd_vel.
    Ros2Sim(cmd::ros2::SimArgs),
    /// Measures performance.
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Prints or checks configuration files.
    #[command(subcommand)]
    Config(ConfigCommand),
}

#[derive(Debug, Subcommand)]
enum WorldCommand {
    /// Validates a world file (.toml) or a ROS map_server map (.yaml); exits non-zero with
    /// the file, field and problem if it is invalid.
    Check {
        /// Path to the world file or map YAML.
        file: PathBuf,
    },
    /// Writes a procedural world: rooms split by walls with one door each, furniture of
    /// every height class (tall, under the laser plane, overhanging), walkers; `--family home`
    /// adds coffee tables, chairs and benches. The same seed gives the same file; `--world
    /// gen-N` (`home-N`) anywhere uses it without a file.
    Generate {
        /// Seed of the world.
        #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
        seed: u64,
        /// The family: gen (the furniture above) or home (with coffee tables, chairs, benches).
        #[arg(long, default_value = "gen", value_parser = ["gen", "home"])]
        family: String,
        /// The world file to write (default: print it).
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

#[derive(Debug, Subcommand)]
enum BenchCommand {
    /// Environment steps per second with full sensors: one env, and a VecEnv on all cores.
    Sim(cmd::bench::SimArgs),
    /// Gradient-step time (batch 32) per variant, single-decision inference latency and
    /// replay memory.
    Train(cmd::bench_train::TrainArgs),
    /// Scan-in to Twist-out latency of `mdrlat ros` over a running ROS master (p50/p99),
    /// and inference time per decision on one core.
    Ros(cmd::bench_ros::RosArgs),
    /// The same over ROS 2: scan-in to Twist-out latency of `mdrlat ros2` on a DDS domain
    /// (p50/p99), and inference time per decision on one core.
    Ros2(cmd::bench_ros::Ros2Args),
}

#[derive(Debug, Subcommand)]
enum ConfigCommand {
    /// Prints the default configuration, every key commented.
    Default,
    /// Checks a configuration file and prints it resolved (defaults filled in).
    Check {
        /// Path to the TOML file.
        file: PathBuf,
    },
}

/// Writes one line to stdout; a closed pipe ends the program with success.
pub fn emit(args: std::fmt::Arguments) {
    use std::io::Write;
    let mut o = std::io::stdout().lock();
    if let Err(e) = o.write_fmt(args).and_then(|()| o.write_all(b"\n")) {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(0);
        }
        eprintln!("error: writing to stdout: {e}");
        std::process::exit(1);
    }
}

fn dispatch(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Demo(a) => cmd::demo::run(&a),
        Command::Eval(a) => cmd::eval::run(&a),
        Command::Worlds => cmd::worlds::list(),
        Command::World(WorldCommand::Check { file }) => cmd::worlds::check(&file),
        Command::World(WorldCommand::Generate { seed, family, out }) => {
            let family = if family == "home" {
                mdrlat_world::Family::Home
            } else {
                mdrlat_world::Family::Gen
            };
            cmd::worlds::generate(family, seed, out.as_deref())
        }
        Command::Observe(a) => cmd::observe::run(&a),
        Command::Render(a) => cmd::render::run(&a),
        Command::Rollout(a) => cmd::rollout::run(&a),
        Command::Train(a) => cmd::train::run(&a),
        Command::Plot(a) => cmd::plot::run(&a),
        Command::Ros(a) => cmd::ros::run(&a),
        Command::RosSim(a) => cmd::ros::sim(&a),
        Command::Ros2(a) => cmd::ros2::run(&a),
        Command::Ros2Sim(a) => cmd::ros2::sim(&a),
        Command::Bench(BenchCommand::Sim(a)) => cmd::bench::sim(&a),
        Command::Bench(BenchCommand::Train(a)) => cmd::bench_train::run(&a),
        Command::Bench(BenchCommand::Ros(a)) => cmd::bench_ros::run(&a),
        Command::Bench(BenchCommand::Ros2(a)) => cmd::bench_ros::run2(&a),
        Command::Config(ConfigCommand::Default) => {
            out!("{}", config::DEFAULT_TOML.trim_end());
            Ok(())
        }
        Command::Config(ConfigCommand::Check { file }) => config::check(&file),
        Command::Reproduce(a) => cmd::reproduce::run(&a),
        Command::Export(a) => cmd::export::run(&a),
        Command::Diagnose(a) => cmd::diagnose::run(&a),
    }
}

fn main() -> ExitCode {
    keep_freed_memory();
    let cli = Cli::parse();
    match dispatch(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every step of a sweep's jobs shows as a command line the parser accepts, for the
    /// command the step runs: the log says what a user would type to do the same.
    #[test]
    fn a_sweep_step_shows_as_a_command_line_that_parses() {
        use mdrlat_sweep::job::{Step, steps};
        let dir = std::env::temp_dir().join(format!("mdrlat-step-argv-{}", std::process::id()));
        for preset in ["smoke", "fast", "nav"] {
            let sweep = mdrlat_sweep::Sweep::preset(preset).expect("a preset");
            let plan = mdrlat_sweep::Plan::new(sweep, &dir.join(preset));
            for job in &plan.jobs {
                for step in steps(&plan, job, 2).expect("steps") {
                    let argv = step.argv();
                    let cli = Cli::try_parse_from(
                        std::iter::once("mdrlat".to_string()).chain(argv.clone()),
                    )
                    .unwrap_or_else(|e| panic!("{preset} {}: {argv:?}: {e}", job.id));
                    let same = matches!(
                        (&step, &cli.command),
                        (Step::Train(_) | Step::Resume(_), Command::Train(_))
                            | (Step::Evaluate(_), Command::Eval(_))
                            | (Step::Plot { .. }, Command::Plot(_))
                    );
                    assert!(same, "{argv:?}");
                }
            }
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
