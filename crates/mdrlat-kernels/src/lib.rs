//! The CPU kernels mdrlat's learner and policies run on: dense matrix products (the `gemm`
//! crate, plus AVX-512 kernels for the shapes the networks need most), convolutions as
//! patch products, and the layout helpers between them. Plain `f32` slices in, plain `f32`
//! slices out: no tensors, no networks, no burn. `mdrlat-nn`'s host network composes these
//! into the MDRLAT forward and backward passes.
//!
//! Every `unsafe` block of mdrlat's CPU path lives here (the crate's one exception to the
//! workspace's `unsafe_code = "deny"`), each with a `SAFETY:` comment stating the contract
//! it relies on. The AVX-512 kernels are chosen at run time; `MDRLAT_PORTABLE_KERNELS=1`
//! forces the portable paths ([`gemm::portable_forced`]) so that they are tested on CPUs
//! that have AVX-512 too (the `portable` test below reruns this crate's tests so).
//!
//! - [`gemm`]: products `C (+)= A·B` with either operand transposed; the short-by-long and
//!   tall shapes of a batch-32 learner; a bfloat16 vector-matrix product for one decision;
//!   the first depth convolution straight from its zero-padded image ([`gemm::conv16`]).
//! - [`conv`]: SAME-padded convolutions on channel-last images (`im2col`, its adjoint, the
//!   patch product with its ReLU and their gradients), described by one [`ConvGeometry`].
//! - [`patches`]: the patches of channel-first images (the depth stacks as they arrive).
//! - [`transpose_into`], [`transposed`]: the blocked transpose the input gradients use.

pub mod conv;
pub mod gemm;
pub mod patches;

pub use conv::ConvGeometry;

/// `dx` (`[batch, din]`) = (or `+=` where `accumulate`) the transpose of `dxt` (`[din,
/// batch]`), a block of 16 columns of `dx` at a time: each row's 16 values are written
/// together. Column by column, the rows of a batch lie `din` floats apart; for the fusion's
/// and the heads' widths (8192, 4096, 2560) they fall in one or two sets of L1 and evict
/// each other between columns: that loop stood out in the profile of an MDRLAT step.
pub fn transpose_into(dxt: &[f32], din: usize, batch: usize, dx: &mut [f32], accumulate: bool) {
    const BLOCK: usize = 16;
    assert!(dxt.len() >= din * batch && dx.len() >= din * batch, "transpose_into: sizes");
    for j0 in (0..din).step_by(BLOCK) {
        let cols = BLOCK.min(din - j0);
        let src = &dxt[j0 * batch..(j0 + cols) * batch];
        for r in 0..batch {
            let row = &mut dx[r * din + j0..r * din + j0 + cols];
            for (c, d) in row.iter_mut().enumerate() {
                let v = src[c * batch + r];
                *d = if accumulate { *d + v } else { v };
            }
        }
    }
}

/// `w` (`[rows, len / rows]`) transposed, as a new matrix.
pub fn transposed(w: &[f32], rows: usize) -> Vec<f32> {
    let mut wt = vec![0.0; w.len()];
    transpose_into(w, rows, w.len() / rows.max(1), &mut wt, false);
    wt
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The blocked transpose of the input gradients against the definition, with a tail
    /// block, written and accumulated.
    #[test]
    fn transpose_into_matches_the_definition() {
        for (din, batch) in [(1, 1), (16, 3), (37, 32), (100, 5)] {
            let dxt: Vec<f32> = (0..din * batch).map(|v| v as f32 * 0.5 - 3.0).collect();
            let want: Vec<f32> =
                (0..batch * din).map(|i| dxt[(i % din) * batch + i / din]).collect();
            let mut dx = vec![f32::NAN; batch * din];
            transpose_into(&dxt, din, batch, &mut dx, false);
            assert_eq!(dx, want, "{din}x{batch}");
            let base: Vec<f32> = (0..batch * din).map(|i| (i % 7) as f32).collect();
            let mut dx = base.clone();
            transpose_into(&dxt, din, batch, &mut dx, true);
            let sum: Vec<f32> = want.iter().zip(&base).map(|(w, b)| b + w).collect();
            assert_eq!(dx, sum, "{din}x{batch} accumulated");
        }
        assert_eq!(transposed(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], 2), [1.0, 4.0, 2.0, 5.0, 3.0, 6.0]);
    }
}

/// For the tests of this crate and of the crates built on it: rerun the calling test
/// binary's tests on the portable kernels.
#[doc(hidden)]
pub mod testing {
    /// Runs the current test binary again with `args` (test filters, `--skip …`) and
    /// `MDRLAT_PORTABLE_KERNELS=1` (the portable paths forced), returning whether it passed
    /// and what it printed. `None` when this already is such a run (or its child): nothing
    /// to repeat.
    ///
    /// # Panics
    /// The test binary cannot be found or started.
    pub fn rerun_on_portable_kernels(args: &[&str]) -> Option<(bool, String)> {
        if crate::gemm::portable_forced() {
            return None;
        }
        let exe = std::env::current_exe().expect("the test binary's path");
        let out = std::process::Command::new(exe)
            .args(args)
            .arg("--nocapture")
            .env("MDRLAT_PORTABLE_KERNELS", "1")
            .env("MDRLAT_REQUIRE_AVX512", "0")
            .output()
            .expect("run the test binary");
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        Some((out.status.success(), text))
    }
}

#[cfg(test)]
mod portable {
    /// This crate's tests once more with `MDRLAT_PORTABLE_KERNELS=1`: on a machine with
    /// AVX-512 the portable branches (the `gemm` crate's paths, the plain loops) never run
    /// otherwise. The test binary runs its own tests in a child process.
    #[test]
    fn the_kernel_tests_pass_on_the_portable_kernels() {
        let Some((passed, text)) =
            crate::testing::rerun_on_portable_kernels(&["--skip", "portable::"])
        else {
            return; // already the portable run
        };
        assert!(passed, "kernel tests on the portable kernels failed:\n{text}");
        // The child ran the kernel tests, and the AVX-512-only ones said they were skipped.
        assert!(text.contains("test result: ok"), "{text}");
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx512f") {
            assert!(text.contains("SKIPPED"), "AVX-512 tests ran on the portable kernels:\n{text}");
        }
    }
}
