//! What the CLI's end-to-end tests share: running the binary, temporary folders, and the
//! check that bad input gives one clear error line and a non-zero exit (never a panic).

#![allow(dead_code)]

use std::path::PathBuf;
use std::process::{Command, Output};

/// The `mdrlat` binary under test.
pub const EXE: &str = env!("CARGO_BIN_EXE_mdrlat");

/// Runs `mdrlat ARGS` to the end.
pub fn mdrlat(args: &[&str]) -> Output {
    Command::new(EXE).args(args).output().expect("run mdrlat")
}

/// A fresh temporary folder for one test (`group` keeps test binaries apart).
pub fn tmp(group: &str, name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("mdrlat-{group}-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

/// The process's stderr as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A failure with one `error: …` line that holds every needle, and no panic.
pub fn assert_clean_failure(o: &Output, needles: &[&str]) {
    let e = stderr(o);
    assert!(!o.status.success(), "expected failure, got success; stderr: {e}");
    assert!(!e.contains("panicked"), "panic instead of an error: {e}");
    assert!(e.starts_with("error: "), "one clear error line: {e}");
    for n in needles {
        assert!(e.contains(n), "stderr lacks '{n}': {e}");
    }
}

/// A child process killed on drop (so a failing test leaves nothing running).
pub struct Guard(pub std::process::Child);

impl Drop for Guard {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Sends `signal` to a process (or, with a negative id, a process group).
pub fn kill(signal: &str, id: i64) {
    let _ = Command::new("kill").arg(format!("-{signal}")).arg("--").arg(id.to_string()).status();
}

/// Waits for `child` to exit; panics after `within`.
pub fn wait_exit(
    child: &mut std::process::Child,
    within: std::time::Duration,
) -> std::process::ExitStatus {
    let deadline = std::time::Instant::now() + within;
    loop {
        if let Some(s) = child.try_wait().expect("wait") {
            return s;
        }
        assert!(std::time::Instant::now() < deadline, "process did not exit within {within:?}");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// Seconds since the epoch (the probes' clock).
pub fn now_s() -> f64 {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).expect("clock").as_secs_f64()
}

/// A velocity command as a probe recorded it: (time, v, ω).
pub type Twist = (f64, f64, f64);

/// Whether a command moves the robot.
pub fn moving(t: &Twist) -> bool {
    t.1 != 0.0 || t.2 != 0.0
}

/// Checks a policy node against a probe's report (`tests/ros/probe.py`,
/// `tests/ros2/probe.py`: scripted phases of good, silent and malformed sensor data and every
/// command received): 5 Hz, driving on good data with commands from Table 1 only, zero when
/// stale or malformed from the next tick on, zero after SIGTERM as the last word, and each
/// incident logged once (`needles`: one line each in the node's `log`).
pub fn check_probe_report(
    report: &serde_json::Value,
    sigterm_at: f64,
    log: &str,
    needles: &[&str],
) {
    let f = |v: &serde_json::Value| v.as_f64().expect("number");
    let twists: Vec<Twist> = report["twists"]
        .as_array()
        .expect("twists")
        .iter()
        .map(|t| (f(&t[0]), f(&t[1]), f(&t[2])))
        .collect();
    let phases: Vec<(String, f64, f64)> = report["phases"]
        .as_array()
        .expect("phases")
        .iter()
        .map(|p| (p["name"].as_str().expect("name").to_string(), f(&p["start"]), f(&p["end"])))
        .collect();
    let within = |from: f64, to: f64| -> Vec<Twist> {
        twists.iter().copied().filter(|t| t.0 >= from && t.0 <= to).collect()
    };
    // 5 Hz ± 10 % over the first good phase.
    let (_, s, e) = &phases[0];
    let w = within(*s, *e);
    let rate = (w.len() - 1) as f64 / (w[w.len() - 1].0 - w[0].0);
    assert!((4.5..=5.5).contains(&rate), "rate {rate:.2} Hz over {} twists", w.len());
    // Every driving command is one of Table 1's ten actions.
    for t in twists.iter().filter(|t| moving(t)) {
        let known = mdrlat_core::TABLE_1
            .iter()
            .any(|a| (f64::from(a.v) - t.1).abs() < 1e-6 && (f64::from(a.w) - t.2).abs() < 1e-6);
        assert!(known, "command {t:?} is not in Table 1");
    }
    for (name, start, end) in &phases {
        match name.as_str() {
            // Driving once fresh data has had a tick to arrive.
            "good" | "depth-16uc1" => {
                let w = within(start + 0.45, *end);
                assert!(w.len() >= 3, "{name} at {start}: {} twists", w.len());
                assert!(w.iter().all(moving), "{name} at {start}: a zero twist: {w:?}\n{log}");
            }
            // Stale after 0.5 s (+ one tick + margin).
            "silent" => {
                let w = within(start + 0.8, *end);
                assert!(w.len() >= 2 && !w.iter().any(moving), "stale sensors: {w:?}");
            }
            // Malformed: zero from the next tick on.
            _ => {
                let w = within(start + 0.35, *end);
                assert!(w.len() >= 3 && !w.iter().any(moving), "{name}: {w:?}\n{log}");
            }
        }
    }
    // SIGTERM: driving right before it, a zero after it, and the zero is the last word.
    let before = within(sigterm_at - 0.5, sigterm_at);
    assert!(before.len() >= 2 && before.iter().all(moving), "driving before SIGTERM: {before:?}");
    let last = twists[twists.len() - 1];
    assert!(last.0 >= sigterm_at && !moving(&last), "last twist {last:?}, SIGTERM at {sigterm_at}");
    // One log line per incident, not per tick: each malformed kind logged once.
    for needle in needles {
        assert_eq!(log.matches(needle).count(), 1, "{needle:?} in\n{log}");
    }
    assert_eq!(log.matches("laser scan is stale").count(), 1, "{log}");
    assert!(log.contains("stopping: zero velocity sent"), "{log}");
}

/// Runs a policy node (`node`) against a probe (`probe`: `tests/ros/probe.py`,
/// `tests/ros2/probe.py`) to the probe's `PHASES_DONE`, sends the node SIGTERM while the
/// probe keeps its sensors fresh, and returns the probe's report, when SIGTERM was sent and
/// the node's log. The node must exit 0.
pub fn run_probe(mut node: Command, mut probe: Command) -> (serde_json::Value, f64, String) {
    use std::io::{BufRead, Write};
    use std::process::Stdio;
    let mut node = Guard(node.stdout(Stdio::null()).stderr(Stdio::piped()).spawn().expect("node"));
    let mut probe =
        Guard(probe.stdin(Stdio::piped()).stdout(Stdio::piped()).spawn().expect("probe"));
    let mut out = std::io::BufReader::new(probe.0.stdout.take().expect("probe stdout"));
    let mut line = String::new();
    out.read_line(&mut line).expect("probe line");
    assert_eq!(line.trim(), "PHASES_DONE", "probe failed");
    std::thread::sleep(std::time::Duration::from_millis(600));
    let sigterm_at = now_s();
    kill("TERM", i64::from(node.0.id()));
    let status = wait_exit(&mut node.0, std::time::Duration::from_secs(5));
    let mut log = String::new();
    std::io::Read::read_to_string(node.0.stderr.as_mut().expect("node stderr"), &mut log)
        .expect("node log");
    assert!(status.success(), "SIGTERM must end the node with 0, got {status}\n{log}");
    writeln!(probe.0.stdin.as_mut().expect("probe stdin")).expect("probe stdin");
    line.clear();
    out.read_line(&mut line).expect("probe report");
    let report = serde_json::from_str(&line).expect("probe JSON");
    (report, sigterm_at, log)
}

/// Checks `mdrlat bench ros|ros2 --samples 10 --json`'s output: the latency line of `bench`
/// (10 samples, 0 < p50 ≤ p99 < 1 s), then the one-thread inference line.
pub fn check_bench_latency(out: &Output, bench: &str) {
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}{}", stderr(out));
    let lines: Vec<serde_json::Value> =
        text.lines().map(|l| serde_json::from_str(l).expect("a JSON line")).collect();
    assert_eq!(lines[0]["bench"], bench);
    assert_eq!(lines[0]["samples"], 10);
    let ms = |k: &str| lines[0][k].as_f64().expect("milliseconds");
    let (p50, p99) = (ms("p50_ms"), ms("p99_ms"));
    assert!(0.0 < p50 && p50 <= p99 && p99 < 1000.0, "{text}");
    assert_eq!(lines[1]["bench"], "infer");
    assert_eq!(lines[1]["threads"], 1);
}
