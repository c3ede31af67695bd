//! The Python package's own tests (`python/tests`, pytest), run from `cargo test`: builds
//! and installs the package with `pip install ./python` into a virtual environment under
//! `target/python/` (kept between runs, so later runs only rebuild what changed), then runs
//! pytest. Without a Python ≥ 3.10 with `venv`, or without PyPI, it says why and skips —
//! unless `MDRLAT_REQUIRE_PYTHON=1` (CI), where that is a failure. `MDRLAT_PYTHON` picks the
//! interpreter (CI: Debian's, whose `python3-torch` the venv sees); with
//! `MDRLAT_REQUIRE_TORCH=1` the PyTorch parity test fails instead of skipping without torch.
//!
//! It first writes reference networks for the PyTorch module's test: every variant (and a
//! navigation MDRLAT) freshly initialised from a seed, as `model.safetensors`, with inputs
//! in metres and the Rust network's Q-values on them (`target/python/qnet/`).

use mdrlat_core::{DEPTH_LEN, FRAME_STACK, GOAL_DIM, LASER_BEAMS, Rng};
use mdrlat_nn::Variant;
use mdrlat_nn::burn::prelude::Device;
use mdrlat_sim::config::Task;
use mdrlat_train::{GreedyPolicy, Inputs};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Rows of the reference inputs.
const ROWS: usize = 5;

fn write_npy(path: &Path, shape: &[usize], data: &[f32]) {
    let file = std::fs::File::create(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    mdrlat_core::npy::write_f32(std::io::BufWriter::new(file), shape, data)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
}

/// Reference networks, inputs (metres) and Rust Q-values under `dir`, one folder each.
fn write_references(dir: &Path) {
    let device = Device::flex();
    let mut rng = Rng::seed_from_u64(21);
    let mut cases: Vec<(Variant, Task)> = Variant::ALL.iter().map(|&v| (v, Task::Avoid)).collect();
    cases.push((Variant::Mdrlat, Task::Nav));
    for (i, (variant, task)) in cases.into_iter().enumerate() {
        let case = dir.join(format!("{variant}-{task}"));
        std::fs::create_dir_all(&case).expect("reference folder");
        let policy = GreedyPolicy::untrained(variant, task, 100 + i as u64, &device, 1)
            .expect("untrained network");
        mdrlat_train::export::save_safetensors(
            policy.net(),
            policy.config(),
            &case.join("model.safetensors"),
        )
        .expect("model");
        let laser: Vec<f32> =
            (0..ROWS * FRAME_STACK * LASER_BEAMS).map(|_| rng.range_f32(0.1, 5.6)).collect();
        // Some pixels without a return (0) and some beyond the 10 m clamp.
        let depth: Vec<f32> = (0..ROWS * FRAME_STACK * DEPTH_LEN)
            .map(|k| if k % 17 == 0 { 0.0 } else { rng.range_f32(0.3, 11.0) })
            .collect();
        let goal: Vec<f32> = (0..ROWS)
            .flat_map(|_| {
                let (d, a) = (rng.range_f32(0.0, 12.0), rng.range_f32(-3.1, 3.1));
                [d, a.sin(), a.cos()]
            })
            .collect();
        let mut inputs = Inputs { size: ROWS, ..Inputs::default() };
        if variant.uses_laser() {
            inputs.laser = vec![0.0; laser.len()];
            mdrlat_core::normalize_laser(&laser, &mut inputs.laser);
        }
        if variant.uses_depth() {
            inputs.depth = vec![0.0; depth.len()];
            mdrlat_core::normalize_depth(&depth, &mut inputs.depth);
        }
        if task == Task::Nav {
            inputs.goal = goal
                .chunks_exact(GOAL_DIM)
                .flat_map(|g| mdrlat_core::normalize_goal(&[g[0], g[1], g[2]]))
                .collect();
        }
        let q = policy.q_values(&inputs).expect("Q-values");
        write_npy(&case.join("laser.npy"), &[ROWS, FRAME_STACK, LASER_BEAMS], &laser);
        write_npy(&case.join("depth.npy"), &[ROWS, FRAME_STACK, 128, 160], &depth);
        write_npy(&case.join("goal.npy"), &[ROWS, GOAL_DIM], &goal);
        write_npy(&case.join("q.npy"), &[ROWS, 10], &q);
    }
}

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
            // The interpreter's own packages stay visible: where the only CPU build of
            // PyTorch at hand is the system's (Debian's python3-torch in CI, PyPI's wheels
            // bring CUDA), the parity test finds it there.
            run(Command::new(&python).args(["-m", "venv", "--system-site-packages"]).arg(&venv))?;
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
    let references = base.join("qnet");
    write_references(&references);
    // Run from outside the source tree, so `import mdrlat` is the installed package.
    run(Command::new(bin.join("pytest"))
        .args(["-q", "-p", "no:cacheprovider", "-rs"])
        .arg(root.join("python/tests"))
        .env("MDRLAT_QNET_REFERENCES", &references)
        .current_dir(&base))
    .unwrap_or_else(|e| panic!("{e}"));
}
