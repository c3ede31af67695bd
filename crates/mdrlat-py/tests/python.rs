//! The Python package's own tests (`python/tests`, pytest), run from `cargo test`: builds
//! and installs the package with `pip install ./python` into a virtual environment under
//! `target/python/` (kept between runs, so later runs only rebuild what changed), then runs
//! pytest. Without a Python ≥ 3.10 with `venv`, or without PyPI, it says why and skips —
//! unless `MDRLAT_REQUIRE_PYTHON=1` (CI), where that is a failure.

use std::path::{Path, PathBuf};
use std::process::Command;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").canonicalize().expect("workspace root")
}

/// Runs `cmd`, returning its combined output on failure.
fn run(cmd: &mut Command) -> Result<(), String> {
    let out = cmd.output().map_err(|e| format!("{cmd:?}: {e}"))?;
    if out.status.success() {
        return Ok(());
    }
    Err(format!(
        "{cmd:?} failed ({}):\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    ))
}

/// What the environment lacks, if anything: skip (or fail in CI) with the reason.
fn unavailable(why: String) {
    if std::env::var("MDRLAT_REQUIRE_PYTHON").is_ok_and(|v| v == "1") {
        panic!("MDRLAT_REQUIRE_PYTHON=1 but the Python tests cannot run: {why}");
    }
    eprintln!("skipping the Python package's tests: {why}");
}

#[test]
fn the_python_package_builds_installs_and_passes_its_tests() {
    let root = workspace();
    let base = root.join("target/python");
    let venv = base.join("venv");
    let python = std::env::var("MDRLAT_PYTHON").unwrap_or_else(|_| "python3".into());
    let bin = venv.join("bin");
    // The interpreter and the packages the build and the tests need (from PyPI).
    let setup = || -> Result<(), String> {
        run(Command::new(&python)
            .args(["-c", "import sys; assert sys.version_info >= (3, 10), sys.version"]))?;
        if !bin.join("python").exists() {
            std::fs::create_dir_all(&base).map_err(|e| format!("{}: {e}", base.display()))?;
            run(Command::new(&python).arg("-m").arg("venv").arg(&venv))?;
        }
        run(Command::new(bin.join("python")).args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "maturin>=1.8,<2",
            "numpy>=1.24",
            "gymnasium>=1.0",
            "pytest>=7",
        ]))
    };
    if let Err(why) = setup() {
        unavailable(why);
        return;
    }
    // From here on every failure is the package's. Its own target folder: the outer
    // `cargo test` may hold the workspace's.
    run(Command::new(bin.join("python"))
        .args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "--force-reinstall",
            "--no-deps",
        ])
        .arg(root.join("python"))
        .env("CARGO_TARGET_DIR", base.join("cargo"))
        .current_dir(&root))
    .unwrap_or_else(|e| panic!("pip install ./python: {e}"));
    // Run from outside the source tree, so `import mdrlat` is the installed package.
    run(Command::new(bin.join("pytest"))
        .args(["-q", "-p", "no:cacheprovider"])
        .arg(root.join("python/tests"))
        .current_dir(&base))
    .unwrap_or_else(|e| panic!("{e}"));
}
