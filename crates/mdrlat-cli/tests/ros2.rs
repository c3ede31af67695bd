//! `mdrlat ros2` and `mdrlat ros2-sim` against a DDS implementation we did not write:
//! Eclipse Cyclone DDS (a tier-1 ROS 2 middleware) through its Python binding, with the ROS 2
//! message types declared on the Python side (`tests/ros2/ros_types.py`).
//!
//! The binding (`cyclonedds` from PyPI, a wheel with the C library inside) is installed into
//! a virtual environment under the target folder on first use. Without Python's `venv` or
//! PyPI these tests print why and pass, unless `MDRLAT_REQUIRE_ROS2=1` (set by `.ci/run`)
//! makes that a failure. Every test runs on a DDS domain of its own (held by a lock file,
//! so two tests or two runs on one machine never see each other); every process started is
//! stopped by its PID. DDS discovery is multicast on every interface: run these tests where
//! no robot on the same network listens on domains 1–228.

#![allow(clippy::unwrap_used)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::Duration;

mod common;
use common::{Guard, check_probe_report, kill, run_probe, wait_exit};

const BIN: &str = env!("CARGO_BIN_EXE_mdrlat");
/// The Cyclone DDS binding's version the tests were written against.
const CYCLONEDDS: &str = "cyclonedds==11.0.1";

/// The virtual environment's Python with `cyclonedds`, made on first use; `None` (and a
/// SKIPPED line) where it cannot be made, a panic if `MDRLAT_REQUIRE_ROS2=1`.
fn cyclone_python() -> Option<PathBuf> {
    static PYTHON: OnceLock<Option<PathBuf>> = OnceLock::new();
    PYTHON
        .get_or_init(|| {
            let venv = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cyclonedds-venv");
            let python = venv.join("bin/python");
            let ready = || {
                Command::new(&python)
                    .args(["-c", "import cyclonedds.domain"])
                    .stderr(Stdio::null())
                    .status()
                    .is_ok_and(|s| s.success())
            };
            if !ready() {
                let base = std::env::var("MDRLAT_PYTHON").unwrap_or_else(|_| "python3".into());
                let made = Command::new(&base)
                    .args(["-m", "venv"])
                    .arg(&venv)
                    .status()
                    .is_ok_and(|s| s.success())
                    && Command::new(venv.join("bin/pip"))
                        .args(["install", "-q", "--disable-pip-version-check", CYCLONEDDS])
                        .status()
                        .is_ok_and(|s| s.success());
                if !made || !ready() {
                    assert!(
                        std::env::var("MDRLAT_REQUIRE_ROS2").as_deref() != Ok("1"),
                        "MDRLAT_REQUIRE_ROS2=1 but {base} could not make a venv with {CYCLONEDDS}"
                    );
                    eprintln!("SKIPPED: no Python venv with {CYCLONEDDS} (see .ci/run)");
                    return None;
                }
            }
            Some(python)
        })
        .clone()
}

/// Held by the tests whose timing a CPU-heavy neighbour could upset (the probe's 5 Hz
/// phases) and by the CPU-heavy one (the hostile peers): they never overlap.
static TIMING: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn timing() -> std::sync::MutexGuard<'static, ()> {
    TIMING.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A DDS domain id held by one test: the first of 1..=228 that no other test holds, from a
/// start picked by the PID; a locked file in the temp folder marks it taken, so two tests,
/// or two test runs on one machine, never share one. Freed when dropped.
struct Domain {
    id: String,
    _lock: std::fs::File,
}

fn domain() -> Domain {
    let dir = std::env::temp_dir().join("mdrlat-ros2-domains");
    std::fs::create_dir_all(&dir).unwrap();
    let start = std::process::id() % 228;
    for i in 0..228 {
        let id = 1 + (start + i) % 228;
        let file = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(dir.join(format!("{id}.lock")))
            .unwrap();
        if file.try_lock().is_ok() {
            return Domain { id: id.to_string(), _lock: file };
        }
    }
    panic!("no free ROS 2 domain id in 1..=228 (lock files in {})", dir.display());
}

impl std::ops::Deref for Domain {
    type Target = str;
    fn deref(&self) -> &str {
        &self.id
    }
}

impl AsRef<std::ffi::OsStr> for Domain {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.id.as_ref()
    }
}

impl std::fmt::Display for Domain {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.id)
    }
}

/// What a helper script printed, once it exits (killed by its PID if it has not within
/// `within`: the `Guard`).
fn output_of(script: &mut Guard, within: Duration) -> Vec<u8> {
    let status = wait_exit(&mut script.0, within);
    let mut out = Vec::new();
    std::io::Read::read_to_end(script.0.stdout.as_mut().unwrap(), &mut out).unwrap();
    assert!(status.success(), "helper script: {status}");
    out
}

/// A script of `tests/ros2/` run by the Cyclone Python.
fn script(python: &Path, name: &str) -> Command {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/ros2");
    let mut c = Command::new(python);
    c.arg(dir.join(name)).current_dir(dir);
    c
}

fn stderr_of(child: &mut std::process::Child) -> String {
    let mut log = String::new();
    std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut log).unwrap();
    log
}

#[test]
fn ros2_node_rate_actions_watchdog_malformed_samples_and_sigterm() {
    let Some(python) = cyclone_python() else { return };
    let _alone = timing();
    let domain = domain();
    let dir = common::tmp("ros2", "node");
    let mut node = Command::new(BIN);
    node.args(["ros2", "--untrained", "--variant", "mdrlat", "--seed", "3"])
        .env("ROS_DOMAIN_ID", &domain) // the variable, as a ROS 2 user sets it
        .arg("--log")
        .arg(dir.join("node.csv"));
    let mut probe = script(&python, "probe.py");
    probe.arg(&domain);
    let (report, sigterm_at, log) = run_probe(node, probe);
    check_probe_report(
        &report,
        sigterm_at,
        &log,
        &[
            "non-finite ranges (first: NaN",
            "non-finite ranges (first: inf",
            "laser scan rejected: undecodable message",
            "data has 307196 bytes",
            "encoding \"rgb8\"",
            "the image is 0x240",
        ],
    );
    assert!(log.contains(&format!("on ROS 2 domain {domain}")), "{log}");
    let csv = std::fs::read_to_string(dir.join("node.csv")).unwrap();
    assert!(csv.lines().count() > 50, "tick log");
    let _ = std::fs::remove_dir_all(dir);
}

/// `ros2` drives `ros2-sim` over DDS with TwistStamped commands, while Cyclone decodes the
/// simulator's topics.
#[test]
fn ros2_policy_drives_the_simulator() {
    let Some(python) = cyclone_python() else { return };
    let domain = domain();
    let dir = common::tmp("ros2", "e2e");
    let traj = dir.join("trajectory.csv");
    let mut sim = Guard(
        Command::new(BIN)
            .args(["ros2-sim", "--world", "train", "--seed", "1", "--duration-s", "8"])
            .args(["--domain-id", &domain, "--stamped", "--depth-encoding", "16UC1"])
            .arg("--log")
            .arg(&traj)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    // Listen once the simulator is up (its start-up line), so it hears its announcement.
    let mut sim_err = BufReader::new(sim.0.stderr.take().unwrap());
    let mut first = String::new();
    sim_err.read_line(&mut first).unwrap();
    assert!(first.contains(&format!("on ROS 2 domain {domain}")), "{first}");
    let mut listen = Guard(
        script(&python, "listen.py").args([&domain, "6"]).stdout(Stdio::piped()).spawn().unwrap(),
    );
    let mut node = Guard(
        Command::new(BIN)
            .args(["ros2", "--untrained", "--variant", "multi", "--seed", "5", "--stamped"])
            .args(["--domain-id", &domain])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let heard = output_of(&mut listen, Duration::from_secs(30));
    let heard: serde_json::Value =
        serde_json::from_slice(&heard).expect("listen.py JSON (did Cyclone decode?)");
    for topic in ["scan", "depth", "odom"] {
        assert!(heard[topic]["count"].as_u64().unwrap() >= 10, "{heard}");
    }
    assert_eq!(heard["scan"]["last"]["n"], 512);
    assert!((heard["scan"]["last"]["angle_max"].as_f64().unwrap() - 2.356).abs() < 1e-3);
    assert_eq!(heard["depth"]["last"]["h"], 128);
    assert_eq!(heard["depth"]["last"]["w"], 160);
    assert_eq!(heard["depth"]["last"]["enc"], "16UC1");
    assert_eq!(heard["depth"]["last"]["bytes"], 128 * 320);
    assert_eq!(heard["odom"]["last"]["child"], "base_footprint");
    // Both nodes as `ros2 node list` would show them, with at least their topics' readers
    // and writers (ros2-client adds writers of its own, e.g. ros_discovery_info's).
    let nodes: Vec<(String, usize, usize)> = heard["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| {
            let p: Vec<&str> = n.as_str().unwrap().split('|').collect();
            (format!("{}{}", p[0], p[1]), p[2].parse().unwrap(), p[3].parse().unwrap())
        })
        .collect();
    assert!(nodes.iter().any(|n| n.0 == "/mdrlat_sim" && n.1 >= 1 && n.2 >= 3), "{nodes:?}");
    assert!(nodes.iter().any(|n| n.0 == "/mdrlat" && n.1 >= 3 && n.2 >= 1), "{nodes:?}");
    let status = wait_exit(&mut sim.0, Duration::from_secs(30));
    let mut sim_log = String::new();
    std::io::Read::read_to_string(&mut sim_err, &mut sim_log).unwrap();
    assert!(status.success(), "ros2-sim: {status}\n{sim_log}");
    let mut summary = String::new();
    std::io::Read::read_to_string(sim.0.stdout.as_mut().unwrap(), &mut summary).unwrap();
    kill("INT", i64::from(node.0.id())); // Ctrl-C
    let node_status = wait_exit(&mut node.0, Duration::from_secs(5));
    let log = stderr_of(&mut node.0);
    assert!(node_status.success(), "{log}");
    let summary: serde_json::Value = serde_json::from_str(summary.trim()).expect("summary JSON");
    assert_eq!(summary["ros2_sim"], "train", "{summary}");
    assert!(summary["steps"].as_u64().unwrap() >= 25, "{summary}");
    assert_eq!(summary["malformed_cmd"], 0, "{summary}");
    // The robot obeyed non-zero commands (Table 1's, after the base's clamping) and moved.
    let rows: Vec<Vec<f64>> = std::fs::read_to_string(&traj)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').take(10).map(|x| x.parse().unwrap()).collect())
        .collect();
    let commanded = rows.iter().filter(|r| r[8] != 0.0 || r[9] != 0.0).count();
    assert!(commanded >= rows.len() / 2, "{commanded} of {} steps commanded\n{log}", rows.len());
    assert!(log.contains("all sensors valid and fresh: driving"), "{log}");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn bench_ros2_reports_latency_as_json() {
    // Needs no Python: both ends are this binary, on a domain of its own.
    let out = Command::new(BIN)
        .args(["bench", "ros2", "--variant", "laser-only", "--samples", "10", "--json"])
        .args(["--rate-hz", "20", "--domain-id", &domain()])
        .output()
        .unwrap();
    common::check_bench_latency(&out, "ros2");
}

#[test]
fn ros2_bad_input_is_a_clear_error() {
    let run = |args: &[&str], env: Option<&str>| {
        let mut c = Command::new(BIN);
        c.args(args);
        if let Some(v) = env {
            c.env("ROS_DOMAIN_ID", v);
        }
        c.output().unwrap()
    };
    let domain = domain();
    let o = run(&["ros2", "--untrained"], Some("500"));
    common::assert_clean_failure(&o, &["ROS_DOMAIN_ID=500", "0..=232"]);
    let o = run(&["ros2", "--untrained", "--domain-id", "233"], None);
    assert!(!o.status.success() && common::stderr(&o).contains("0..=232"));
    let o =
        run(&["ros2", "--untrained", "--scan-topic", "/bad topic", "--domain-id", &domain], None);
    common::assert_clean_failure(&o, &["\"/bad topic\"", "not a ROS 2 name"]);
    let o = run(&["ros2", "--checkpoint", "/nonexistent/run", "--domain-id", &domain], None);
    common::assert_clean_failure(&o, &["/nonexistent/run: no such run directory or checkpoint"]);
    let o = run(&["ros2-sim", "--world", "nowhere", "--domain-id", &domain], None);
    assert!(!o.status.success() && !common::stderr(&o).contains("panicked"));
}

/// Resident memory of a process, MB.
fn rss_mb(pid: u32) -> f64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next()?.parse::<f64>().ok())
        .map_or(0.0, |kb| kb / 1024.0)
}

/// Garbage RTPS datagrams, fragment bombs (1 kB datagrams announcing 256 MB samples to the
/// builtin readers), 8 MB scans and 16 MB images, and a discovery flood on the node's domain
/// (`tests/ros2/hostile.py`), against the MDRLAT node (laser and depth subscriptions): it
/// keeps its 5 Hz command stream and its memory levels off.
#[test]
fn ros2_node_survives_hostile_peers() {
    let Some(python) = cyclone_python() else { return };
    let _alone = timing();
    let domain = domain();
    let dir = common::tmp("ros2", "hostile");
    let csv = dir.join("node.csv");
    let mut node = Guard(
        Command::new(BIN)
            .args(["ros2", "--untrained", "--variant", "mdrlat", "--domain-id", &domain])
            .arg("--log")
            .arg(&csv)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let attack_s = 16.0;
    let mut hostile = Guard(
        script(&python, "hostile.py").args([&domain, "16"]).stdout(Stdio::piped()).spawn().unwrap(),
    );
    // Resident memory every second while the peers rage.
    let mut rss = Vec::new();
    let start = std::time::Instant::now();
    while start.elapsed().as_secs_f64() < 3.0 + attack_s {
        std::thread::sleep(Duration::from_secs(1));
        rss.push(rss_mb(node.0.id()));
    }
    let report = output_of(&mut hostile, Duration::from_secs(30));
    let report: serde_json::Value = serde_json::from_slice(&report).expect("hostile.py JSON");
    kill("TERM", i64::from(node.0.id()));
    let status = wait_exit(&mut node.0, Duration::from_secs(5));
    let log = stderr_of(&mut node.0);
    assert!(status.success(), "the node must survive and exit 0 on SIGTERM: {status}\n{log}");
    let (calm_end, end) = (report["calm_end"].as_f64().unwrap(), report["end"].as_f64().unwrap());
    // The node's own clock: its tick log (seconds since it started) through the attack.
    let ticks: Vec<f64> = std::fs::read_to_string(&csv)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    let (first, last) = (ticks[0], ticks[ticks.len() - 1]);
    let gaps: Vec<f64> = ticks.windows(2).map(|w| w[1] - w[0]).collect();
    let worst = gaps.iter().copied().fold(0.0, f64::max);
    let rate = (ticks.len() - 1) as f64 / (last - first);
    assert!((4.5..=5.5).contains(&rate), "tick rate {rate:.2} Hz\n{log}");
    assert!(worst < 0.6, "a {worst:.2} s gap in the command stream\n{log}");
    // The commands reached the well-behaved base through the attack.
    let heard = report["twists"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| (calm_end..end).contains(&t[0].as_f64().unwrap()))
        .count();
    assert!(
        heard as f64 >= 0.6 * 5.0 * (end - calm_end),
        "{heard} commands heard in {:.1} s",
        end - calm_end
    );
    // Memory: bounded by the subscriptions' history depth times the largest sample, so it
    // levels off: the last third of the attack adds little.
    let peak = rss.iter().copied().fold(0.0, f64::max);
    let third = rss.len() / 3;
    let (mid, late) = (rss[rss.len() - 1 - third], rss[rss.len() - 1]);
    assert!(peak < 600.0, "resident memory peaked at {peak:.0} MB: {rss:?}");
    assert!(late - mid < 64.0, "memory still growing late in the attack: {rss:?}");
    eprintln!(
        "hostile peers: {rate:.2} Hz, worst gap {worst:.2} s, {heard} commands heard, RSS {rss:?} MB"
    );
    let _ = std::fs::remove_dir_all(dir);
}
