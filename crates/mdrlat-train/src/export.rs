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
    net.save_into(&mut store).map_err(|e| format!("{}: {e}", path.display()))?;
    canonical_header(path)
}

/// A JSON value with every object's keys in sorted order.
fn sorted(v: serde_json::Value) -> serde_json::Value {
    match v {
        serde_json::Value::Object(map) => {
            let mut entries: Vec<(String, serde_json::Value)> = map.into_iter().collect();
            entries.sort_by(|a, b| a.0.cmp(&b.0));
            serde_json::Value::Object(entries.into_iter().map(|(k, v)| (k, sorted(v))).collect())
        }
        serde_json::Value::Array(items) => {
            serde_json::Value::Array(items.into_iter().map(sorted).collect())
        }
        other => other,
    }
}

/// Rewrites a safetensors file's JSON header with its keys sorted (burn writes the metadata
/// map in a different order in every process), padded with spaces so the data stays 8-byte
/// aligned: the same weights give the same file bytes. Tensor offsets are relative to the
/// data, so they hold as they are.
fn canonical_header(path: &Path) -> Result<(), String> {
    let err = |e: String| format!("{}: {e}", path.display());
    let bytes = std::fs::read(path).map_err(|e| err(e.to_string()))?;
    let len = bytes
        .get(..8)
        .and_then(|b| <[u8; 8]>::try_from(b).ok())
        .map(u64::from_le_bytes)
        .ok_or_else(|| err("shorter than a safetensors header".into()))?;
    let end =
        usize::try_from(len).ok().and_then(|l| l.checked_add(8)).filter(|&e| e <= bytes.len());
    let end = end.ok_or_else(|| err(format!("header length {len} beyond the file")))?;
    let header: serde_json::Value =
        serde_json::from_slice(&bytes[8..end]).map_err(|e| err(format!("header: {e}")))?;
    let mut text = serde_json::to_string(&sorted(header)).map_err(|e| err(e.to_string()))?;
    while (8 + text.len()) % 8 != 0 {
        text.push(' ');
    }
    let mut out = Vec::with_capacity(8 + text.len() + bytes.len() - end);
    out.extend_from_slice(&(text.len() as u64).to_le_bytes());
    out.extend_from_slice(text.as_bytes());
    out.extend_from_slice(&bytes[end..]);
    std::fs::write(path, out).map_err(|e| err(e.to_string()))
}
