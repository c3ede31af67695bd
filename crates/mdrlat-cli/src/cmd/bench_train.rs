//! `mdrlat bench train`: the GEMM reference, learner speed per variant, inference latency
//! (one decision, and a batch of 64), replay memory.

use super::bench::cpu_model;
use super::train::DeviceKind;
use anyhow::Result;
use mdrlat_nn::Variant;
use mdrlat_train::bench::{
    BenchSettings, forward_stages_ms, gemm_reference_gflops, measure_variant,
    observation_inputs_ms, policy_batch_ms, profile, update_gflops,
};
use std::time::Duration;

/// Rows per network forward in `mdrlat eval` (its `--forward-batch` default).
pub const EVAL_FORWARD_BATCH: usize = 16;

/// Arguments of `mdrlat bench train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// Variants to measure, comma-separated (default: all six).
    #[arg(long, value_delimiter = ',')]
    variants: Vec<Variant>,
    /// Batch size of the gradient step.
    #[arg(long, default_value_t = 32)]
    batch: usize,
    /// Seconds per measurement.
    #[arg(long, default_value_t = 3.0)]
    seconds: f64,
    /// Compute device.
    #[arg(long, value_enum, default_value = "cpu")]
    device: DeviceKind,
    /// Print one JSON object per line instead of a table.
    #[arg(long)]
    json: bool,
    /// Also break the step down: forward time per network stage, target forwards, and
    /// forward + backward + Adam.
    #[arg(long)]
    profile: bool,
    /// Also time each gradient step with burn's autodiff instead of the host kernels (the
    /// learner before them), side by side in the same run (`cpu` only).
    #[arg(long)]
    compare_autodiff: bool,
}

/// `mdrlat bench train`.
pub fn run(a: &TrainArgs) -> Result<()> {
    let variants = if a.variants.is_empty() { Variant::ALL.to_vec() } else { a.variants.clone() };
    if !(a.seconds.is_finite() && (0.0..=3600.0).contains(&a.seconds)) {
        anyhow::bail!("--seconds {}: must be between 0 and 3600", a.seconds);
    }
    if a.batch == 0 || a.batch > 4096 {
        anyhow::bail!("--batch {}: must be 1 to 4096", a.batch);
    }
    let time = Duration::from_secs_f64(a.seconds.max(0.05));
    let device = a.device.device();
    let backend = a.device.name();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    // The limit, measured in the same run: the same GEMM library (burn-flex's, whatever
    // --device is) on every core. Measured again before each variant and the highest figure
    // so far kept: the limit is what the machine can do, and on a shared VM a neighbour can
    // halve one measurement (seen on a Zen 4 VM: 106 GFLOP/s at the start of a run whose
    // other measurements gave 183–205, which read as an "efficiency" of 0.85).
    let settings = BenchSettings {
        batch: a.batch,
        time,
        threads,
        forward_batch: EVAL_FORWARD_BATCH,
        compare_autodiff: a.compare_autodiff,
        // Opt-in bfloat16 weights, beside f32 through the same policy path (cpu only).
        precision: a.device == DeviceKind::Cpu,
    };
    let reference_time = time.min(Duration::from_secs(2));
    let mut reference = gemm_reference_gflops(2048, threads, reference_time);
    if a.json {
        out!(
            "{}",
            serde_json::json!({"bench": "gemm_reference", "library": "burn-flex (gemm crate)",
                "n": 2048, "threads": threads, "gflops": (reference * 10.0).round() / 10.0})
        );
    } else {
        out!(
            "reference: fp32 GEMM 2048^3 through burn-flex (the gemm crate), one per core on {threads} threads: {reference:.1} GFLOP/s"
        );
    }
    if !a.json {
        out!(
            "learner speed on {backend} (cpu: {}, {} threads)",
            cpu_model(),
            std::thread::available_parallelism().map_or(1, |n| n.get())
        );
        out!(
            "{:<11} {:>30} {:>22} {:>33} {:>13}",
            "variant",
            "train step (ms, GFLOP/s, /ref)",
            "inference, 1 core (ms)",
            "64 obs, all cores (GFLOP/s, /ref)",
            "replay (MiB)"
        );
    }
    for v in variants {
        let again =
            gemm_reference_gflops(2048, threads, reference_time.min(Duration::from_secs(1)));
        if again > reference * 1.05 && !a.json {
            out!(
                "reference: {again:.1} GFLOP/s now (was {reference:.1}); ratios from here on use it"
            );
        }
        reference = reference.max(again);
        let f = measure_variant(v, &device, &settings);
        let ((train, n_train), autodiff, (infer, n_infer)) = (f.train, f.autodiff, f.infer);
        let train_gflops = update_gflops(v, a.batch, train);
        let (bf16, replay, (batch_ms, batch_gflops)) = (f.precision, f.replay_mib, f.batch);
        if a.json {
            out!(
                "{}",
                serde_json::json!({"bench": "train", "variant": v.name(), "backend": backend, "batch": a.batch,
                    "ms_per_step": (train * 100.0).round() / 100.0, "samples": n_train,
                    "gflop_per_step": (mdrlat_nn::QNetConfig::new(v).update_flops() as f64 * a.batch as f64 / 1e7).round() / 100.0,
                    "gflops": (train_gflops * 10.0).round() / 10.0,
                    "reference_gflops": (reference * 10.0).round() / 10.0,
                    "efficiency": (train_gflops / reference * 1000.0).round() / 1000.0})
            );
            if let Some((ms, samples)) = autodiff {
                let gflops = update_gflops(v, a.batch, ms);
                out!(
                    "{}",
                    serde_json::json!({"bench": "train_autodiff", "variant": v.name(), "backend": backend, "batch": a.batch,
                        "ms_per_step": (ms * 100.0).round() / 100.0, "samples": samples,
                        "gflops": (gflops * 10.0).round() / 10.0,
                        "efficiency": (gflops / reference * 1000.0).round() / 1000.0})
                );
            }
            out!(
                "{}",
                serde_json::json!({"bench": "infer", "variant": v.name(), "backend": backend,
                    "threads": 1,
                    "ms": (infer * 1000.0).round() / 1000.0, "samples": n_infer})
            );
            if let Some((Ok((f, nf)), Ok((b, nb)))) = &bf16 {
                for (precision, ms, n) in [("f32", f, nf), ("bf16", b, nb)] {
                    out!(
                        "{}",
                        serde_json::json!({"bench": "infer_policy", "variant": v.name(), "backend": backend,
                            "threads": 1, "precision": precision,
                            "ms": (ms * 1000.0).round() / 1000.0, "samples": n})
                    );
                }
            }
            out!(
                "{}",
                serde_json::json!({"bench": "infer_batch", "variant": v.name(), "backend": backend,
                    "observations": 64, "forward_batch": EVAL_FORWARD_BATCH, "threads": threads,
                    "ms": (batch_ms * 1000.0).round() / 1000.0,
                    "gflops": (batch_gflops * 10.0).round() / 10.0,
                    "efficiency": (batch_gflops / reference * 1000.0).round() / 1000.0})
            );
            out!(
                "{}",
                serde_json::json!({"bench": "replay", "variant": v.name(), "capacity": 20_000, "mib": (replay * 10.0).round() / 10.0})
            );
        } else {
            let batched =
                format!("{batch_ms:.1} ms, {batch_gflops:.1} ({:.2})", batch_gflops / reference);
            let step = format!("{train:.1}, {train_gflops:.1} ({:.2})", train_gflops / reference);
            out!("{:<11} {:>30} {:>22.2} {:>33} {:>13.0}", v.name(), step, infer, batched, replay);
            match &bf16 {
                Some((Ok((f, _)), Ok((b, _)))) => {
                    let pair = format!("f32 {f:.2} / bf16 {b:.2}");
                    out!("{:<11} {:>30} {:>22}", "  --bf16", "", pair);
                }
                Some((_, Err(e))) => out!("{:<11} {:>30} {e}", "  --bf16", ""),
                _ => {}
            }
            if let Some((ms, _)) = autodiff {
                let gflops = update_gflops(v, a.batch, ms);
                let step = format!("{ms:.1}, {gflops:.1} ({:.2})", gflops / reference);
                out!("{:<11} {:>30}", "  autodiff", step);
            }
        }
    }
    if a.profile {
        let v = a.variants.first().copied().unwrap_or(Variant::Mdrlat);
        let rows = profile(v, a.batch, &device, time);
        if a.json {
            for (stage, ms) in &rows {
                out!(
                    "{}",
                    serde_json::json!({"bench": "profile", "variant": v.name(), "stage": stage, "ms": (ms * 100.0).round() / 100.0})
                );
            }
        } else {
            out!("\nwhere a {} step goes (batch {}):", v.name(), a.batch);
            for (stage, ms) in &rows {
                out!("  {stage:<52} {ms:>8.1} ms");
            }
        }
        // A batched decision of 64 observations by forward size (eval's --forward-batch).
        if !a.json {
            out!("\n{} decisions for 64 observations on {threads} threads:", v.name());
        }
        let normalising = observation_inputs_ms(v, 64, time);
        if a.json {
            out!(
                "{}",
                serde_json::json!({"bench": "observation_inputs", "variant": v.name(),
                    "observations": 64, "threads": 1,
                    "ms": (normalising * 1000.0).round() / 1000.0})
            );
        } else {
            let label = "their network inputs (normalised stacks), one thread";
            out!("  {label:<52} {normalising:>8.1} ms");
            for (stage, ms) in forward_stages_ms(v, 16, time) {
                out!("  {:<52} {ms:>8.1} ms", format!("a forward of 16 on one thread: {stage}"));
            }
        }
        for fb in [None, Some(8), Some(16), Some(32)] {
            let (ms, gflops) = policy_batch_ms(v, &device, 64, fb, threads, time);
            let label = fb.map_or("one forward of 64".to_string(), |f| format!("forwards of {f}"));
            if a.json {
                out!(
                    "{}",
                    serde_json::json!({"bench": "infer_batch_profile", "variant": v.name(),
                        "observations": 64, "forward_batch": fb.unwrap_or(64), "threads": threads,
                        "ms": (ms * 1000.0).round() / 1000.0, "gflops": (gflops * 10.0).round() / 10.0})
                );
            } else {
                out!("  {label:<52} {ms:>8.1} ms {gflops:>6.1} GFLOP/s");
            }
        }
        // One decision (batch 1, as a robot makes them) by stage: what its weight reads cost.
        if !a.json {
            out!("\none {} decision on one thread, by stage:", v.name());
            for (stage, ms) in forward_stages_ms(v, 1, time) {
                out!("  {stage:<52} {ms:>8.3} ms");
            }
        }
    }
    Ok(())
}
