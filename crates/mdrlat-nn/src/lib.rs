//! The MDRLAT networks (SPEC §3, the authors' code), on burn.
//!
//! One module, [`QNet`], covers all six variants of the paper (laser-only, depth-only,
//! multi, multi-AT, multi-BF, MDRLAT) and the goal-conditioned navigation input: each part
//! is an `Option` switched on by the [`Variant`] and the config, as burn's examples do. The
//! library takes a `&Device` and never picks one.
//!
//! ```text
//! depth [B,4,128,160] ─ conv 16@10x14/8 ─ conv 32@4x4/2 ─ conv 32@3x3/1 ─ flatten 2560 ─┐
//!                                                  (BF) Linear 2560→128 = d ─┐          │
//! laser [B,4,512] ─ conv1d 16@5/4 ─ 32@3/2 ─ 32@3/2 ─ flatten 1024 ──────────┼──────────┤
//!                                                  (BF) Linear 1024→64  = l ─┤          │
//!                                   f = ReLU(Linear 8192→512 (vec(d lᵀ))) ───┴─ concat h (4096)
//! h ─ V: Linear→512→1, A: Linear→512→10, Q = V + A − mean(A)        (paper eq. 11)
//! h ─ (AT) Linear→512→6: (v, ω) at t−2, t−1, t                     (paper eq. 12)
//! ```
//! Every convolution uses TensorFlow "SAME" padding and is followed by a ReLU.

#![forbid(unsafe_code)] // the kernels' unsafe code lives in `mdrlat-kernels`

mod average;
pub mod host;
mod init;
mod net;

/// The variants are named in `mdrlat-core` (every crate can name one without the networks).
pub use mdrlat_core::{Variant, VariantParseError};
pub use net::{
    DepthInput, QNet, QNetConfig, QOutput, StageTime, bilinear, depth_conv1_geometry, depth_input,
    depth_patches, dueling, is_flex, is_libtorch, is_libtorch_gpu, prefers_depth_patches,
};

/// The burn re-exports the rest of mdrlat builds on, so every crate uses the same version.
pub use burn;

#[cfg(test)]
mod portable {
    /// The host network's tests (against burn's autodiff) once more with
    /// `MDRLAT_PORTABLE_KERNELS=1`: on a machine with AVX-512 the network never runs on the
    /// portable kernels otherwise (`mdrlat-kernels` reruns its own tests so too). The test
    /// binary runs its own `host::` tests in a child process.
    #[test]
    fn the_host_tests_pass_on_the_portable_kernels() {
        let Some((passed, text)) = mdrlat_kernels::testing::rerun_on_portable_kernels(&["host::"])
        else {
            return; // already the portable run
        };
        assert!(passed, "host tests on the portable kernels failed:\n{text}");
        assert!(text.contains("test result: ok") && !text.contains("running 0 tests"), "{text}");
    }
}
