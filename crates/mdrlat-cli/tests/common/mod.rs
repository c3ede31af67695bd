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
