//! `mdrlat ros` and `mdrlat ros-sim` against a real ROS 1 master (Debian's `rosmaster`) and
//! real rospy nodes — not a mock.
//!
//! Needs `apt-get install python3-rosmaster python3-rospy python3-sensor-msgs
//! python3-geometry-msgs python3-nav-msgs` (what `.ci/run` installs). Without them these
//! tests print why and pass, unless `MDRLAT_REQUIRE_ROS=1` (set by `.ci/run`) makes a missing
//! ROS a failure.

#![allow(clippy::unwrap_used)]

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::{Guard, check_probe_report, kill, run_probe, wait_exit};

const BIN: &str = env!("CARGO_BIN_EXE_mdrlat");
const PYTHON: &str = "/usr/bin/python3";

/// Whether ROS is installed; panics if it is required and missing.
fn ros_available() -> bool {
    let ok = Path::new("/usr/bin/rosmaster").exists()
        && Command::new(PYTHON)
            .args(["-c", "import rospy, sensor_msgs.msg, nav_msgs.msg, geometry_msgs.msg"])
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
    if !ok {
        assert!(
            std::env::var("MDRLAT_REQUIRE_ROS").as_deref() != Ok("1"),
            "MDRLAT_REQUIRE_ROS=1 but rosmaster or rospy is missing (see .ci/run for the packages)"
        );
        eprintln!("SKIPPED: no rosmaster/rospy on this machine (see .ci/run for the packages)");
    }
    ok
}

fn free_port() -> u16 {
    TcpListener::bind(("127.0.0.1", 0)).unwrap().local_addr().unwrap().port()
}

/// A `rosmaster` in its own session on a free port, stopped by process group on drop.
struct Master {
    child: Child,
    uri: String,
}

impl Master {
    fn start() -> Self {
        let port = free_port();
        let child = Command::new("setsid")
            .args(["rosmaster", "--core", "-p", &port.to_string()])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start rosmaster");
        let uri = format!("http://127.0.0.1:{port}/");
        let deadline = Instant::now() + Duration::from_secs(20);
        while mdrlat_ros::xmlrpc::call(&uri, "getPid", &[mdrlat_ros::xmlrpc::Value::str("/t")])
            .is_err()
        {
            assert!(Instant::now() < deadline, "rosmaster did not answer on {uri}");
            std::thread::sleep(Duration::from_millis(100));
        }
        Self { child, uri }
    }

    fn command(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        c.env("ROS_MASTER_URI", &self.uri).env("ROS_HOSTNAME", "127.0.0.1");
        c
    }
}

impl Drop for Master {
    fn drop(&mut self) {
        // setsid made rosmaster a session and group leader: its pid is the group id.
        let pgid = i64::from(self.child.id());
        kill("TERM", -pgid);
        let deadline = Instant::now() + Duration::from_secs(5);
        while Instant::now() < deadline {
            if self.child.try_wait().ok().flatten().is_some() {
                return;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        kill("KILL", -pgid);
        let _ = self.child.wait();
    }
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mdrlat-ros-test-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn node_rate_watchdog_malformed_messages_and_sigterm() {
    if !ros_available() {
        return;
    }
    let master = Master::start();
    let dir = tmp("node");
    let mut node = master.command(BIN);
    node.args(["ros", "--untrained", "--variant", "mdrlat", "--seed", "3"])
        .arg("--log")
        .arg(dir.join("node.csv"));
    let mut probe = master.command(PYTHON);
    probe.arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/ros/probe.py"));
    let (report, sigterm_at, log) = run_probe(node, probe);
    check_probe_report(
        &report,
        sigterm_at,
        &log,
        &[
            "non-finite ranges (first: NaN",
            "non-finite ranges (first: inf",
            "data has 1228796 bytes",
            "encoding \"rgb8\"",
            "the image is 0x480",
        ],
    );
    let csv = std::fs::read_to_string(dir.join("node.csv")).unwrap();
    assert!(csv.lines().count() > 50, "tick log");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn policy_drives_the_simulator_over_ros() {
    if !ros_available() {
        return;
    }
    let master = Master::start();
    let dir = tmp("e2e");
    let traj = dir.join("trajectory.csv");
    let mut sim = Guard(
        master
            .command(BIN)
            .args(["ros-sim", "--world", "train", "--seed", "1", "--duration-s", "6"])
            .args(["--depth-encoding", "16UC1"])
            .arg("--log")
            .arg(&traj)
            .arg("--picture")
            .arg(dir.join("sim.png"))
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let listen = master
        .command(PYTHON)
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/ros/listen.py"))
        .arg("4")
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut node = Guard(
        master
            .command(BIN)
            .args(["ros", "--untrained", "--variant", "multi", "--seed", "5"])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let heard = listen.wait_with_output().unwrap();
    let heard: serde_json::Value = serde_json::from_slice(&heard.stdout)
        .expect("listen.py JSON (did rospy accept our types?)");
    // rospy decoded the simulator's topics: 5 Hz for ~4 s, the simulator's geometry.
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
    let status = wait_exit(&mut sim.0, Duration::from_secs(30));
    assert!(status.success(), "ros-sim: {status}");
    let mut summary = String::new();
    std::io::Read::read_to_string(sim.0.stdout.as_mut().unwrap(), &mut summary).unwrap();
    kill("INT", i64::from(node.0.id())); // Ctrl-C
    let node_status = wait_exit(&mut node.0, Duration::from_secs(5));
    let mut log = String::new();
    std::io::Read::read_to_string(node.0.stderr.as_mut().unwrap(), &mut log).unwrap();
    assert!(node_status.success(), "{log}");
    let summary: serde_json::Value = serde_json::from_str(summary.trim()).expect("summary JSON");
    assert!(summary["steps"].as_u64().unwrap() >= 25, "{summary}");
    // The episode log: the robot obeyed non-zero commands and moved.
    let rows: Vec<Vec<f64>> = std::fs::read_to_string(&traj)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').take(10).map(|x| x.parse().unwrap()).collect())
        .collect();
    let commanded = rows.iter().filter(|r| r[8] != 0.0 || r[9] != 0.0).count();
    assert!(commanded >= rows.len() / 2, "{commanded} of {} steps commanded\n{log}", rows.len());
    let (first, last) = (&rows[0], rows.last().unwrap());
    let moved = (last[3] - first[3]).hypot(last[4] - first[4]) + (last[5] - first[5]).abs();
    assert!(
        moved > 0.2 || summary["episodes"].as_u64().unwrap() > 1,
        "pose barely changed: {first:?} -> {last:?}"
    );
    assert!(std::fs::metadata(dir.join("sim.png")).unwrap().len() > 1000);
    assert!(log.contains("all sensors valid and fresh: driving"), "{log}");
    let _ = std::fs::remove_dir_all(dir);
}

/// A publisher killed with SIGKILL (still listed by the master) and started again: the node
/// stops on stale data, then reconnects and drives again.
#[test]
fn node_survives_a_publisher_killed_and_restarted() {
    if !ros_available() {
        return;
    }
    let master = Master::start();
    let dir = tmp("restart");
    let csv = dir.join("node.csv");
    let mut node = Guard(
        master
            .command(BIN)
            .args(["ros", "--untrained", "--variant", "multi", "--seed", "2"])
            .arg("--log")
            .arg(&csv)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let feed = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/ros/feed.py");
    let mut first = Guard(master.command(PYTHON).arg(&feed).arg("60").spawn().unwrap());
    std::thread::sleep(Duration::from_secs(4));
    first.0.kill().unwrap(); // SIGKILL: no unregistration, the master still lists it
    let _ = first.0.wait();
    std::thread::sleep(Duration::from_secs(2));
    let mut second = master.command(PYTHON).arg(&feed).arg("4").spawn().unwrap();
    assert!(second.wait().unwrap().success());
    kill("TERM", i64::from(node.0.id()));
    assert!(wait_exit(&mut node.0, Duration::from_secs(5)).success());
    let mut log = String::new();
    std::io::Read::read_to_string(node.0.stderr.as_mut().unwrap(), &mut log).unwrap();
    // The tick log must read: driving, then stopped, then driving again.
    let driving: Vec<bool> = std::fs::read_to_string(&csv)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1) == Some("1"))
        .collect();
    let mut runs: Vec<(bool, usize)> = Vec::new();
    for d in driving {
        match runs.last_mut() {
            Some((v, n)) if *v == d => *n += 1,
            _ => runs.push((d, 1)),
        }
    }
    let long: Vec<(bool, usize)> = runs.into_iter().filter(|r| r.1 >= 3).collect();
    let pattern: Vec<bool> = long.iter().map(|r| r.0).collect();
    assert!(pattern.windows(3).any(|w| w == [true, false, true]), "driving runs {long:?}\n{log}");
    assert!(log.contains("is stale"), "{log}");
    let _ = std::fs::remove_dir_all(dir);
}

/// A laser that does not see the policy's 270° is a start-up error, not a silent guess.
#[test]
fn a_narrow_laser_is_a_startup_error() {
    if !ros_available() {
        return;
    }
    let master = Master::start();
    let feed = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/ros/feed.py");
    let _feed = Guard(master.command(PYTHON).arg(&feed).arg("30").arg("narrow").spawn().unwrap());
    let mut node = Guard(
        master
            .command(BIN)
            .args(["ros", "--untrained", "--variant", "laser-only"])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let status = wait_exit(&mut node.0, Duration::from_secs(20));
    let mut log = String::new();
    std::io::Read::read_to_string(node.0.stderr.as_mut().unwrap(), &mut log).unwrap();
    assert_eq!(status.code(), Some(1), "{log}");
    assert!(
        log.contains("the scan covers -90.0° to 90.0°, the policy needs −135° to 135°"),
        "{log}"
    );
    assert!(log.contains("--fill-scan-gaps"), "{log}");
}

#[test]
fn bench_ros_reports_latency_as_json() {
    if !ros_available() {
        return;
    }
    let master = Master::start();
    let out = master
        .command(BIN)
        .args(["bench", "ros", "--variant", "laser-only", "--samples", "10", "--json"])
        .arg("--rate-hz")
        .arg("20")
        .output()
        .unwrap();
    common::check_bench_latency(&out, "ros");
}

#[test]
fn node_errors_without_master_or_checkpoint() {
    // No ROS needed: a closed port and a missing checkpoint are clear errors, exit 1.
    let out = Command::new(BIN)
        .args(["ros", "--untrained", "--master", "http://127.0.0.1:9/"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("127.0.0.1:9") && err.contains("roscore"), "{err}");
    let out = Command::new(BIN).args(["ros", "--checkpoint", "/nonexistent/run"]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("/nonexistent/run: no such run directory or checkpoint"), "{err}");
    let out = Command::new(BIN)
        .args(["ros", "--untrained", "--rate-hz", "0", "--master", "http://127.0.0.1:9/"])
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&out.stderr).contains("--rate-hz 0"));
}
