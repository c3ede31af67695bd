//! Final weights as `.safetensors`, named and laid out for PyTorch.
//!
//! Tensor names follow the module tree: `depth.c1.weight` … `depth.c3.bias` (2D convs,
//! `[out, in, kh, kw]`), `laser.c1.weight` … (1D convs, `[out, in, k]`), `fusion.depth`,
//! `fusion.laser`, `fusion.out` (bilinear fusion), `value.hidden`, `value.out`,
//! `advantage.hidden`, `advantage.out`, `velocity.hidden`, `velocity.out` (heads), each with
//! `.weight` and `.bias`. Linear weights are stored `[out, in]` as `torch.nn.Linear` expects.
//! The metadata records the variant and the input layout. A model can be stored in f16 to
//! ship it (half the bytes) and is read back into f32 ([`load_safetensors`]).

use mdrlat_nn::burn::prelude::Device;
use mdrlat_nn::burn::store::{
    BurnToPyTorchAdapter, FloatCastAdapter, ModuleAdapter, ModuleSnapshot, PyTorchToBurnAdapter,
    SafetensorsStore,
};
use mdrlat_nn::burn::tensor::DType;
use mdrlat_nn::{QNet, QNetConfig, Variant};
use mdrlat_sim::config::Task;
use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

pub use crate::config::Precision;

/// The metadata key of a model trained on the scan with the camera's memory
/// (`sim.laser.depth_memory_frames`; absent: the laser's own scan).
pub const DEPTH_MEMORY_KEY: &str = "mdrlat_depth_memory_frames";

/// Writes `net` to `path` in safetensors format (f32).
///
/// # Errors
/// The file cannot be written.
pub fn save_safetensors(net: &QNet, config: &QNetConfig, path: &Path) -> Result<(), String> {
    save_safetensors_as(net, config, path, Precision::F32, &[])
}

/// Writes `net` to `path` in safetensors format in `precision`, with `extra` metadata
/// (e.g. `mdrlat_step`) beside the variant and the input layout. A navigation network
/// also records `mdrlat_task = nav`, one trained on the scan with the camera's memory
/// [`DEPTH_MEMORY_KEY`] (an obstacle-avoidance model of the laser's scan is as before).
///
/// # Errors
/// The file cannot be written.
pub fn save_safetensors_as(
    net: &QNet,
    config: &QNetConfig,
    path: &Path,
    precision: Precision,
    extra: &[(&str, String)],
) -> Result<(), String> {
    let mut store = SafetensorsStore::from_file(path).overwrite(true);
    store = match precision {
        Precision::F32 => store.with_to_adapter(BurnToPyTorchAdapter),
        Precision::F16 => {
            store.with_to_adapter(BurnToPyTorchAdapter.chain(FloatCastAdapter::to(DType::F16)))
        }
    };
    let mut inputs =
        String::from("laser [B,4,512] range/5.6; depth [B,4,128,160] clamp(0,10)/5; NCHW");
    if config.goal_dim > 0 {
        inputs.push_str("; goal [B,3] (distance/10 m, sin, cos of the bearing)");
    }
    if config.depth_memory_frames > 0 {
        inputs.push_str(&format!(
            "; the laser's scan with {} frames of the camera's memory ({DEPTH_MEMORY_KEY})",
            config.depth_memory_frames
        ));
    }
    let mut store =
        store.metadata("mdrlat_variant", config.variant.name()).metadata("mdrlat_inputs", inputs);
    if config.goal_dim > 0 {
        store = store.metadata("mdrlat_task", "nav");
    }
    if config.depth_memory_frames > 0 {
        store = store.metadata(DEPTH_MEMORY_KEY, config.depth_memory_frames.to_string());
    }
    let mut store = store.metadata(
        "mdrlat_outputs",
        "q [B,10] (Table 1 actions); velocity [B,6] (v,w at t-2,t-1,t)",
    );
    for (k, v) in extra {
        store = store.metadata(*k, v.clone());
    }
    net.save_into(&mut store).map_err(|e| format!("{}: {e}", path.display()))?;
    canonical_header(path)
}

/// The `__metadata__` map of a safetensors file.
///
/// # Errors
/// The file is missing or not safetensors.
pub fn safetensors_metadata(path: &Path) -> Result<BTreeMap<String, String>, String> {
    let err = |e: String| format!("{}: {e}", path.display());
    let mut file = std::fs::File::open(path).map_err(|e| err(e.to_string()))?;
    let mut len = [0u8; 8];
    file.read_exact(&mut len).map_err(|_| err("shorter than a safetensors header".into()))?;
    let len = u64::from_le_bytes(len);
    let size = file.metadata().map(|m| m.len()).unwrap_or(0);
    if len > size.saturating_sub(8) || len > 100_000_000 {
        return Err(err(format!("header length {len} beyond the file: not a safetensors file")));
    }
    let mut header = vec![0u8; len as usize];
    file.read_exact(&mut header).map_err(|e| err(e.to_string()))?;
    let header: serde_json::Value =
        serde_json::from_slice(&header).map_err(|e| err(format!("header: {e}")))?;
    Ok(header
        .get("__metadata__")
        .and_then(|m| m.as_object())
        .map(|m| {
            m.iter().filter_map(|(k, v)| v.as_str().map(|v| (k.clone(), v.to_string()))).collect()
        })
        .unwrap_or_default())
}

/// Reads a model file written by [`save_safetensors_as`] (f32 or f16; computed in f32) into
/// a fresh network of the variant and task its metadata names; returns the network's
/// settings, the network and the metadata.
///
/// # Errors
/// Not a safetensors file, no or an unknown `mdrlat_variant` or `mdrlat_task`, or tensors
/// that do not fit it.
pub fn load_safetensors(
    path: &Path,
    device: &Device,
) -> Result<(QNetConfig, QNet, BTreeMap<String, String>), String> {
    let meta = safetensors_metadata(path)?;
    let variant: Variant = meta
        .get("mdrlat_variant")
        .ok_or_else(|| {
            format!("{}: no mdrlat_variant in its metadata: not an mdrlat model", path.display())
        })?
        .parse()
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let task: Task = match meta.get("mdrlat_task") {
        None => Task::Avoid,
        Some(t) => t.parse().map_err(|e| format!("{}: mdrlat_task: {e}", path.display()))?,
    };
    let memory = match meta.get(DEPTH_MEMORY_KEY) {
        None => 0,
        Some(m) => m
            .parse::<u32>()
            .ok()
            .filter(|&m| m > 0 && m <= mdrlat_sim::sensors::MAX_MEMORY_FRAMES)
            .ok_or_else(|| {
                format!(
                    "{}: {DEPTH_MEMORY_KEY} = {m:?}: not 1 to {}",
                    path.display(),
                    mdrlat_sim::sensors::MAX_MEMORY_FRAMES
                )
            })?,
    };
    let config =
        crate::learner::net_config(variant, task).with_depth_memory_frames(memory as usize);
    let mut net = config.init(device);
    let mut store = SafetensorsStore::from_file(path)
        .with_from_adapter(PyTorchToBurnAdapter.chain(FloatCastAdapter::to(DType::F32)));
    crate::learner::load_all(&mut net, &mut store, path, variant)?;
    Ok((config, net, meta))
}

/// How far two networks' Q-values lie apart on the same observations (a model stored in f16
/// against its f32 original).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QDifference {
    /// Observations compared.
    pub observations: usize,
    /// Largest |ΔQ| over every action of every observation.
    pub max_abs: f64,
    /// Mean |ΔQ|.
    pub mean_abs: f64,
    /// Largest |Q| of the reference (the scale of the differences).
    pub max_q: f64,
    /// Observations where both choose the same greedy action.
    pub same_action: usize,
}

impl std::fmt::Display for QDifference {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "on {} observations: max |ΔQ| {:.2e}, mean |ΔQ| {:.2e} (largest |Q| {:.2}); the same greedy action in {} of {}",
            self.observations,
            self.max_abs,
            self.mean_abs,
            self.max_q,
            self.same_action,
            self.observations
        )
    }
}

/// Compares the Q-values of `a` (the reference) and `b` on `observations`, in forwards of 64.
///
/// # Errors
/// A network could not decide.
pub fn compare_q(
    a: &crate::GreedyPolicy,
    b: &crate::GreedyPolicy,
    observations: &[mdrlat_core::Observation],
) -> Result<QDifference, mdrlat_core::PolicyError> {
    let n = mdrlat_core::Action::COUNT;
    let mut d = QDifference {
        observations: observations.len(),
        max_abs: 0.0,
        mean_abs: 0.0,
        max_q: 0.0,
        same_action: 0,
    };
    let mut sum = 0.0;
    let (mut ia, mut ib) = (crate::Inputs::default(), crate::Inputs::default());
    for chunk in observations.chunks(64) {
        let refs: Vec<&mdrlat_core::Observation> = chunk.iter().collect();
        crate::observation_inputs(&refs, a.config(), &mut ia)?;
        crate::observation_inputs(&refs, b.config(), &mut ib)?;
        let (qa, qb) = (a.q_values(&ia)?, b.q_values(&ib)?);
        let (mut ga, mut gb) = (Vec::new(), Vec::new());
        mdrlat_core::greedy_actions(&qa, chunk.len(), &mut ga)?;
        mdrlat_core::greedy_actions(&qb, chunk.len(), &mut gb)?;
        d.same_action += ga.iter().zip(&gb).filter(|(x, y)| x == y).count();
        for (x, y) in qa.iter().zip(&qb).take(chunk.len() * n) {
            let e = f64::from((x - y).abs());
            d.max_abs = d.max_abs.max(e);
            d.max_q = d.max_q.max(f64::from(x.abs()));
            sum += e;
        }
    }
    d.mean_abs = sum / (observations.len() * n).max(1) as f64;
    Ok(d)
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
    // Written beside the file and renamed over it: a crash leaves the whole old file or the
    // whole new one, never a truncated model, and the model gets the process's default
    // permissions like every other file of a run (burn's store creates it owner-only).
    let name = path.file_name().map_or_else(|| "model".into(), |n| n.to_string_lossy());
    let tmp = path.with_file_name(format!(".{name}.tmp"));
    std::fs::write(&tmp, out).map_err(|e| format!("{}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, path)
        .map_err(|e| err(format!("replacing it with {}: {e}", tmp.display())))
}
