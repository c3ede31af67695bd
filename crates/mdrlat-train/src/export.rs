//! Final weights as `.safetensors`, named and laid out for PyTorch.
//!
//! Tensor names follow the module tree: `depth.c1.weight` … `depth.c3.bias` (2D convs,
//! `[out, in, kh, kw]`), `laser.c1.weight` … (1D convs, `[out, in, k]`), `fusion.depth`,
//! `fusion.laser`, `fusion.out` (bilinear fusion), `value.hidden`, `value.out`,
//! `advantage.hidden`, `advantage.out`, `velocity.hidden`, `velocity.out` (heads), each with
//! `.weight` and `.bias`. Linear weights are stored `[out, in]` as `torch.nn.Linear` expects.
//! The metadata records the variant and the input layout.

use mdrlat_nn::QNet;
use mdrlat_nn::Variant;
use mdrlat_nn::burn::store::{BurnToPyTorchAdapter, ModuleSnapshot, SafetensorsStore};
use std::path::Path;

/// Writes `net` to `path` in safetensors format.
///
/// # Errors
/// The file cannot be written.
pub fn save_safetensors(net: &QNet, variant: Variant, path: &Path) -> Result<(), String> {
    let mut store = SafetensorsStore::from_file(path)
        .overwrite(true)
        .with_to_adapter(BurnToPyTorchAdapter)
        .metadata("mdrlat_variant", variant.name())
        .metadata(
            "mdrlat_inputs",
            "laser [B,4,512] range/5.6; depth [B,4,128,160] clamp(0,10)/5; NCHW",
        )
        .metadata(
            "mdrlat_outputs",
            "q [B,10] (Table 1 actions); velocity [B,6] (v,w at t-2,t-1,t)",
        );
    net.save_into(&mut store).map_err(|e| format!("{}: {e}", path.display()))
}
