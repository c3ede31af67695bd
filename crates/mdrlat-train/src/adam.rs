//! Adam in one pass over memory.
//!
//! burn's `Adam` issues about a dozen element-wise tensor operations per parameter (scale the first
//! moment, scale the gradient, add, square, …), each a full pass over the parameter and most a
//! fresh allocation: for MDRLAT's 10.9 M parameters that is a large share of a step on two cores
//! (`docs/performance.md`). [`FusedAdam`] does the same arithmetic, in the same order and in `f32`,
//! in a single pass that reads the parameter, its gradient and both moments once and writes the
//! parameter and the moments in place: seven streams of 44 MB instead of about thirty.
//!
//! It writes in place only where that is safe and possible: on the CPU backends (`flex`, and
//! LibTorch on the CPU), for contiguous `f32` tensors whose memory nothing else holds; on a
//! LibTorch GPU, the same arithmetic runs in place as LibTorch's own element-wise kernels
//! (without the host pass's flush of subnormal moments to 0: as burn's Adam). Every other
//! case — the first step (the moments do not exist yet), a CubeCL device (`wgpu`, `cuda`), a
//! parameter whose weights another network still shares, a strided gradient on the CPU — goes
//! to burn's `Adam`, with the same state. The state *is* burn's [`AdamState`], so `optimizer.bpk` files are the same
//! whichever of the two paths wrote them.

use mdrlat_nn::burn::backend::{BackendTensor, DispatchTensor, DispatchTensorKind};
use mdrlat_nn::burn::optim::{
    Adam, AdamConfig, AdamState, AdaptiveMomentumState, LearningRate, ModuleOptimizer, Optimizer,
};
use mdrlat_nn::burn::prelude::*;
use mdrlat_nn::burn::tensor::DType;
use rayon::prelude::*;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// Elements per parallel work item of the fused pass (256 KiB of each stream).
const CHUNK: usize = 1 << 16;

/// How many parameter updates took each path, since the optimiser was made.
#[derive(Debug, Default)]
pub struct AdamCounts {
    fused: AtomicU64,
    fallback: AtomicU64,
}

impl AdamCounts {
    /// Parameter updates done in one fused pass.
    pub fn fused(&self) -> u64 {
        self.fused.load(Ordering::Relaxed)
    }

    /// Parameter updates handed to burn's `Adam`.
    pub fn fallback(&self) -> u64 {
        self.fallback.load(Ordering::Relaxed)
    }
}

/// Adam (Kingma & Ba) with burn's arithmetic and state, fused and in place where the backend
/// allows (see the module documentation). No weight decay, no AMSGrad: the paper uses neither.
#[derive(Clone)]
pub struct FusedAdam {
    reference: Adam,
    beta_1: f32,
    beta_2: f32,
    epsilon: f32,
    counts: Arc<AdamCounts>,
}

impl FusedAdam {
    /// Adam with β₁ = 0.9, β₂ = 0.999 and the given ε.
    pub fn new(epsilon: f32) -> Self {
        let (beta_1, beta_2) = (0.9, 0.999);
        let config =
            AdamConfig::new().with_beta_1(beta_1).with_beta_2(beta_2).with_epsilon(epsilon);
        Self { reference: config.build(), beta_1, beta_2, epsilon, counts: Arc::default() }
    }

    /// The counters of this optimiser and of its clones.
    pub fn counts(&self) -> Arc<AdamCounts> {
        Arc::clone(&self.counts)
    }

    /// A module optimiser that steps every parameter with this rule.
    pub fn into_module_optimizer(self) -> ModuleOptimizer {
        ModuleOptimizer::from(self)
    }

    /// The step's constants, exactly as burn's `Adam` computes them at step `time` (1-based).
    fn coefficients(&self, lr: LearningRate, time: usize) -> Coefficients {
        let time = i32::try_from(time).unwrap_or(i32::MAX);
        let bias_correction2_sqrt = (1.0 - self.beta_2.powi(time)).sqrt();
        Coefficients {
            beta_1: self.beta_1,
            beta_2: self.beta_2,
            factor: bias_correction2_sqrt / (1.0 - self.beta_1.powi(time)),
            epsilon: self.epsilon * bias_correction2_sqrt,
            // burn scales by the learning rate as a tensor scalar of the tensor's type.
            lr: lr as f32,
        }
    }
}

/// Per-step constants of the fused pass.
#[derive(Debug, Clone, Copy)]
struct Coefficients {
    beta_1: f32,
    beta_2: f32,
    factor: f32,
    epsilon: f32,
    lr: f32,
}

/// One Adam step over contiguous slices, in place, in burn's order of operations:
/// `m ← β₁m + (1−β₁)g`, `v ← β₂v + (1−β₂)g²`, `p ← p − lr · (m·c)/(√v + ε')`.
fn adam_pass(p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32], c: Coefficients) {
    let (one_minus_b1, one_minus_b2) = (1.0 - c.beta_1, 1.0 - c.beta_2);
    let serial = |p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32]| {
        for (((p, &g), m), v) in p.iter_mut().zip(g).zip(m.iter_mut()).zip(v.iter_mut()) {
            *m = flush_subnormal(*m * c.beta_1 + g * one_minus_b1);
            *v = flush_subnormal(*v * c.beta_2 + (g * g) * one_minus_b2);
            let step = (*m * c.factor) / (v.sqrt() + c.epsilon);
            *p -= step * c.lr;
        }
    };
    if p.len() <= CHUNK {
        serial(p, g, m, v);
        return;
    }
    p.par_chunks_mut(CHUNK)
        .zip(g.par_chunks(CHUNK))
        .zip(m.par_chunks_mut(CHUNK))
        .zip(v.par_chunks_mut(CHUNK))
        .for_each(|(((p, g), m), v)| serial(p, g, m, v));
}

/// `x`, or 0 where it is subnormal. The moments of a weight whose gradient has vanished decay
/// geometrically into the subnormal range (below 1.2e-38), where every further multiplication costs
/// a microcode assist of ~100 cycles: in a real MDRLAT run that made the Adam pass much slower.
/// Stored as 0 they cost nothing; the weight's step is the same (a subnormal moment's step is ~30
/// orders of magnitude below `f32` resolution), so the fused pass stays bit-identical to burn's
/// Adam in the weights, and in the moments wherever burn's are normal numbers (tested).
#[inline(always)]
fn flush_subnormal(x: f32) -> f32 {
    if x.abs() < f32::MIN_POSITIVE { 0.0 } else { x }
}

/// The `f32` elements of a backend tensor, for reading; `None` where they are not one
/// contiguous host slice.
fn host_slice(kind: &DispatchTensorKind) -> Option<&[f32]> {
    match kind {
        DispatchTensorKind::Flex(BackendTensor::Float(t)) if t.dtype() == DType::F32 => {
            let (start, end) = t.layout().contiguous_offsets()?;
            t.storage::<f32>().get(start..end)
        }
        #[cfg(feature = "tch")]
        DispatchTensorKind::LibTorch(BackendTensor::Float(t)) => libtorch::host_slice(t),
        _ => None,
    }
}

/// The `f32` elements of a backend tensor, for writing in place; `None` unless they are one
/// contiguous host slice that no other tensor shares.
fn host_slice_mut(kind: &mut DispatchTensorKind) -> Option<&mut [f32]> {
    match kind {
        DispatchTensorKind::Flex(BackendTensor::Float(t)) if t.dtype() == DType::F32 => {
            let (start, end) = t.layout().contiguous_offsets()?;
            t.try_storage_mut::<f32>()?.get_mut(start..end)
        }
        #[cfg(feature = "tch")]
        DispatchTensorKind::LibTorch(BackendTensor::Float(t)) => libtorch::host_slice_mut(t),
        _ => None,
    }
}

/// One Adam step in place where all four are tensors of one GPU (see
/// `libtorch::device_step`); `false` elsewhere.
fn device_step(
    p: &mut DispatchTensorKind,
    g: &DispatchTensorKind,
    m: &mut DispatchTensorKind,
    v: &mut DispatchTensorKind,
    c: Coefficients,
) -> bool {
    match (p, g, m, v) {
        #[cfg(feature = "tch")]
        (
            DispatchTensorKind::LibTorch(BackendTensor::Float(p)),
            DispatchTensorKind::LibTorch(BackendTensor::Float(g)),
            DispatchTensorKind::LibTorch(BackendTensor::Float(m)),
            DispatchTensorKind::LibTorch(BackendTensor::Float(v)),
        ) if libtorch::on_gpu(p) => libtorch::device_step(p, g, m, v, c),
        _ => {
            let _ = c;
            false
        }
    }
}

/// Lays a host tensor's elements out contiguously (a copy), where they are not.
fn make_contiguous(kind: &mut DispatchTensorKind) {
    match kind {
        DispatchTensorKind::Flex(BackendTensor::Float(t)) if !t.is_contiguous() => {
            *t = t.to_contiguous();
        }
        #[cfg(feature = "tch")]
        DispatchTensorKind::LibTorch(BackendTensor::Float(t)) => libtorch::make_contiguous(t),
        _ => {}
    }
}

#[cfg(feature = "tch")]
#[allow(unsafe_code, deprecated)] // burn-tch is deprecated upstream; it is our `tch` backend.
mod libtorch {
    //! LibTorch tensors on the CPU, seen as slices: the workspace's only `unsafe` code. tch
    //! offers no safe view of a tensor's memory, and copying it out and back would cost more
    //! than the fused pass saves. And the in-place step on LibTorch's GPUs, in its own
    //! kernels (safe code).
    use mdrlat_nn::burn::backend::libtorch::TchTensor;

    pub(super) fn make_contiguous(t: &mut TchTensor) {
        if t.tensor.device() == tch::Device::Cpu && !t.tensor.is_contiguous() {
            *t = TchTensor::new(t.tensor.contiguous());
        }
    }

    fn host_f32(t: &TchTensor) -> bool {
        t.tensor.device() == tch::Device::Cpu
            && t.tensor.kind() == tch::Kind::Float
            && t.tensor.is_contiguous()
    }

    /// Whether the tensor is on a GPU (not LibTorch's CPU).
    pub(super) fn on_gpu(t: &TchTensor) -> bool {
        t.tensor.device() != tch::Device::Cpu
    }

    /// One Adam step in place on a LibTorch device (a GPU: the CPU's tensors go through
    /// [`adam_pass`](super::adam_pass)), in LibTorch's element-wise kernels and in burn's order of
    /// operations, so with burn's values. burn's `Adam` made the same ~13 kernel launches a
    /// parameter through its own tensor layer, with a fresh tensor for each (a noticeable share of
    /// an MDRLAT step on a GPU; `docs/backends.md`). `false`, touching nothing, unless all four are
    /// `f32` on one device with the same shape and the parameter and moments are not shared
    /// (`can_mut`).
    pub(super) fn device_step(
        p: &mut TchTensor,
        g: &TchTensor,
        m: &mut TchTensor,
        v: &mut TchTensor,
        c: super::Coefficients,
    ) -> bool {
        let device = p.tensor.device();
        let size = p.tensor.size();
        let fits = |t: &TchTensor| {
            t.tensor.device() == device
                && t.tensor.kind() == tch::Kind::Float
                && t.tensor.size() == size
        };
        if !([&*p, g, &*m, &*v].into_iter().all(fits) && p.can_mut() && m.can_mut() && v.can_mut())
        {
            return false;
        }
        let (b1, b2) = (f64::from(c.beta_1), f64::from(c.beta_2));
        let (g, m, v) = (&g.tensor, &mut m.tensor, &mut v.tensor);
        // m ← β₁m + (1−β₁)g
        let _ = m.g_mul_scalar_(b1);
        let _ = m.g_add_(&g.g_mul_scalar(f64::from(1.0 - c.beta_1)));
        // v ← β₂v + (1−β₂)g²
        let _ = v.g_mul_scalar_(b2);
        let _ = v.g_add_(&g.square().g_mul_scalar(f64::from(1.0 - c.beta_2)));
        // p ← p − lr · (m·c)/(√v + ε')
        let mut denom = v.sqrt();
        let _ = denom.g_add_scalar_(f64::from(c.epsilon));
        let mut step = m.g_mul_scalar(f64::from(c.factor));
        let _ = step.g_div_(&denom);
        let _ = step.g_mul_scalar_(f64::from(c.lr));
        let _ = p.tensor.g_sub_(&step);
        true
    }

    pub(super) fn host_slice(t: &TchTensor) -> Option<&[f32]> {
        if !host_f32(t) {
            return None;
        }
        let (ptr, len) = (t.tensor.data_ptr().cast::<f32>(), t.tensor.numel());
        if len == 0 || ptr.is_null() {
            return Some(&[]);
        }
        // SAFETY: a contiguous f32 CPU tensor holds `numel` initialised floats from
        // `data_ptr` (which includes the storage offset); the borrow of `t` keeps it alive,
        // and nothing writes to it while we read (the optimiser runs alone).
        Some(unsafe { std::slice::from_raw_parts(ptr, len) })
    }

    pub(super) fn host_slice_mut(t: &mut TchTensor) -> Option<&mut [f32]> {
        // `can_mut`: this is the only burn tensor on its storage and no stride is zero — the
        // same test burn-tch makes before its own in-place operations. It rests on burn-tch
        // (pinned at 0.22.1) giving every view of a buffer (reshape, permute, slices) that
        // buffer's shared owner count; a miscount there would make this write visible
        // through another tensor.
        if !t.can_mut() || !host_f32(t) {
            return None;
        }
        let (ptr, len) = (t.tensor.data_ptr().cast::<f32>(), t.tensor.numel());
        if len == 0 || ptr.is_null() {
            return Some(&mut []);
        }
        // SAFETY: as in `host_slice`, and the storage is exclusively ours (`can_mut`), so
        // no other tensor observes the writes; the mutable borrow of `t` keeps this unique.
        Some(unsafe { std::slice::from_raw_parts_mut(ptr, len) })
    }
}

impl Optimizer for FusedAdam {
    type State<const D: usize> = AdamState<D>;

    fn step<const D: usize>(
        &self,
        lr: LearningRate,
        tensor: Tensor<D>,
        grad: Tensor<D>,
        state: Option<Self::State<D>>,
    ) -> (Tensor<D>, Option<Self::State<D>>) {
        let Some(AdamState {
            momentum: AdaptiveMomentumState { time, moment_1, moment_2, max_moment_2: None },
        }) = state
        else {
            // The first step creates the moments (and AMSGrad state never occurs here).
            self.counts.fallback.fetch_add(1, Ordering::Relaxed);
            return self.reference.step(lr, tensor, grad, state);
        };
        let [mut p, mut g, mut m, mut v]: [DispatchTensor; 4] =
            [tensor, grad, moment_1, moment_2].map(Tensor::into_dispatch);
        // Convolution weight gradients come out of the backward pass permuted, and on LibTorch
        // the moments burn's first step made from them keep that layout (copied once here).
        for t in [&mut g, &mut m, &mut v] {
            make_contiguous(&mut t.kind);
        }
        let fused = match (
            host_slice_mut(&mut p.kind),
            host_slice(&g.kind),
            host_slice_mut(&mut m.kind),
            host_slice_mut(&mut v.kind),
        ) {
            (Some(ps), Some(gs), Some(ms), Some(vs))
                if gs.len() == ps.len() && ms.len() == ps.len() && vs.len() == ps.len() =>
            {
                adam_pass(ps, gs, ms, vs, self.coefficients(lr, time + 1));
                true
            }
            _ => device_step(
                &mut p.kind,
                &g.kind,
                &mut m.kind,
                &mut v.kind,
                self.coefficients(lr, time + 1),
            ),
        };
        let [tensor, grad, moment_1, moment_2] = [p, g, m, v].map(Tensor::<D>::from_dispatch);
        if fused {
            self.counts.fused.fetch_add(1, Ordering::Relaxed);
            let momentum = AdaptiveMomentumState::new(time + 1, moment_1, moment_2);
            (tensor, Some(AdamState::new(momentum)))
        } else {
            self.counts.fallback.fetch_add(1, Ordering::Relaxed);
            let state = AdamState::new(AdaptiveMomentumState::new(time, moment_1, moment_2));
            self.reference.step(lr, tensor, grad, Some(state))
        }
    }

    fn to_device<const D: usize>(state: Self::State<D>, device: &Device) -> Self::State<D> {
        <Adam as Optimizer>::to_device(state, device)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mdrlat_nn::burn::module::{Module, Param};
    use mdrlat_nn::burn::nn::{Linear, LinearConfig};
    use mdrlat_nn::burn::optim::GradientsParams;

    fn linear(device: &Device) -> Linear {
        let mut rng = mdrlat_core::Rng::seed_from_u64(7);
        let mut l = LinearConfig::new(300, 400).init(device);
        let w: Vec<f32> = (0..300 * 400).map(|_| rng.normal() * 0.1).collect();
        let b: Vec<f32> = (0..400).map(|_| rng.normal() * 0.1).collect();
        l.weight = Param::from_tensor(Tensor::from_data(TensorData::new(w, [300, 400]), device));
        l.bias = Some(Param::from_tensor(Tensor::from_data(TensorData::new(b, [400]), device)));
        l
    }

    /// `steps` steps of a least-squares fit of `net` with `optim` (inputs drawn from `seed`).
    fn fit(net: Linear, optim: &mut ModuleOptimizer, steps: usize, seed: u64) -> Linear {
        fit_on(&Device::flex().autodiff(), net, optim, steps, seed)
    }

    fn fit_on(
        device: &Device,
        mut net: Linear,
        optim: &mut ModuleOptimizer,
        steps: usize,
        seed: u64,
    ) -> Linear {
        let mut rng = mdrlat_core::Rng::seed_from_u64(seed);
        for _ in 0..steps {
            let x: Vec<f32> = (0..8 * 300).map(|_| rng.normal()).collect();
            let x = Tensor::<2>::from_data(TensorData::new(x, [8, 300]), device);
            let loss = net.forward(x).square().mean();
            let grads = GradientsParams::from_grads(loss.backward(), &net);
            drop(loss);
            net = optim.step(1e-3, net, grads);
        }
        net
    }

    fn weights(net: &Linear) -> Vec<f32> {
        net.weight.val().into_data().try_to_vec::<f32>().expect("f32")
    }

    /// How many elements differ, and by how much at most.
    fn differences(a: &[f32], b: &[f32]) -> (usize, f32) {
        assert_eq!(a.len(), b.len());
        a.iter()
            .zip(b)
            .filter(|(x, y)| x.to_bits() != y.to_bits())
            .fold((0, 0.0), |(n, d), (x, y)| (n + 1, d.max((x - y).abs())))
    }

    /// Subnormal moments are stored as 0, which changes no weight.
    #[test]
    fn subnormal_moments_are_flushed_without_changing_the_weights() {
        let n = 3 * CHUNK + 5; // several work items and a tail
        let tiny = 1e-39f32;
        assert!(tiny.is_subnormal());
        let (mut p, g) = (vec![0.5f32; n], vec![0.0f32; n]);
        let (mut m, mut v) = (vec![tiny; n], vec![tiny; n]);
        let c = FusedAdam::new(1e-8).coefficients(1e-4, 10);
        adam_pass(&mut p, &g, &mut m, &mut v, c);
        // Unflushed, element by element, as burn's Adam computes it.
        let (mr, vr) = (tiny * c.beta_1, tiny * c.beta_2);
        let step = (mr * c.factor) / (vr.sqrt() + c.epsilon);
        let want = 0.5f32 - step * c.lr;
        assert!(mr.is_subnormal(), "burn's Adam would store a subnormal");
        assert!(p.iter().all(|x| x.to_bits() == want.to_bits()), "the weights are burn's");
        assert!(m.iter().chain(&v).all(|x| *x == 0.0), "the subnormal moments are flushed");
        assert!(vr.is_subnormal());
    }

    fn burn_adam() -> ModuleOptimizer {
        AdamConfig::new().with_epsilon(1e-8).init()
    }

    #[test]
    fn fused_steps_equal_burns_adam_bit_for_bit() {
        let device = Device::flex().autodiff();
        let reference = fit(linear(&device), &mut burn_adam(), 6, 1);
        let fused = FusedAdam::new(1e-8);
        let counts = fused.counts();
        let ours = fit(linear(&device), &mut fused.into_module_optimizer(), 6, 1);
        assert_eq!(differences(&weights(&ours), &weights(&reference)), (0, 0.0));
        // Step 1 creates the moments through burn; steps 2–6 are fused for weight and bias.
        assert_eq!((counts.fused(), counts.fallback()), (10, 2));
    }

    /// On LibTorch's CPU tensors too (`cargo test --features tch`, with LibTorch set up).
    #[cfg(feature = "tch")]
    #[test]
    #[allow(deprecated)] // burn-tch is deprecated upstream; it is our `tch` backend.
    fn fused_steps_equal_burns_adam_on_libtorch() {
        let device = Device::libtorch().autodiff();
        let reference = fit_on(&device, linear(&device), &mut burn_adam(), 6, 1);
        let fused = FusedAdam::new(1e-8);
        let counts = fused.counts();
        let ours = fit_on(&device, linear(&device), &mut fused.into_module_optimizer(), 6, 1);
        let (_, worst) = differences(&weights(&ours), &weights(&reference));
        assert!(worst < 1e-6, "max difference {worst}");
        assert_eq!((counts.fused(), counts.fallback()), (10, 2));
    }

    /// The in-place step for LibTorch's GPUs (run here on LibTorch's CPU tensors) is the
    /// host pass's arithmetic, bit for bit, and leaves a shared parameter alone.
    #[cfg(feature = "tch")]
    #[test]
    #[allow(deprecated)] // burn-tch is deprecated upstream; it is our `tch` backend.
    fn the_gpu_step_is_the_host_arithmetic() {
        use mdrlat_nn::burn::backend::libtorch::TchTensor;
        let n = 1000;
        let mut rng = mdrlat_core::Rng::seed_from_u64(5);
        let mut draw = |scale: f32| (0..n).map(|_| rng.normal() * scale).collect::<Vec<f32>>();
        let (p, g, m) = (draw(0.1), draw(0.01), draw(1e-3));
        let v: Vec<f32> = draw(1e-3).iter().map(|x| x * x).collect();
        let c = FusedAdam::new(1e-8).coefficients(1e-4, 7);
        let (mut hp, mut hm, mut hv) = (p.clone(), m.clone(), v.clone());
        adam_pass(&mut hp, &g, &mut hm, &mut hv, c);
        let tensor = |x: &[f32]| TchTensor::new(tch::Tensor::from_slice(x));
        let (mut tp, tg, mut tm, mut tv) = (tensor(&p), tensor(&g), tensor(&m), tensor(&v));
        assert!(libtorch::device_step(&mut tp, &tg, &mut tm, &mut tv, c));
        let bits = |t: &TchTensor| {
            Vec::<f32>::try_from(&t.tensor)
                .expect("f32")
                .iter()
                .map(|x| x.to_bits())
                .collect::<Vec<_>>()
        };
        let host_bits = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert!(bits(&tp) == host_bits(&hp), "weights");
        assert!(bits(&tm) == host_bits(&hm), "first moments");
        assert!(bits(&tv) == host_bits(&hv), "second moments");
        let shared = tp.clone();
        assert!(!libtorch::device_step(&mut tp, &tg, &mut tm, &mut tv, c), "shared weights");
        assert!(bits(&shared) == host_bits(&hp));
    }

    #[test]
    fn shared_weights_are_not_written_in_place() {
        let device = Device::flex().autodiff();
        let fused = FusedAdam::new(1e-8);
        let counts = fused.counts();
        let mut optim = fused.into_module_optimizer();
        let mut net = linear(&device);
        let mut snapshots = Vec::new();
        for _ in 0..3 {
            let x = Tensor::<2>::ones([2, 300], &device);
            let loss = net.forward(x).sum();
            let grads = GradientsParams::from_grads(loss.backward(), &net);
            drop(loss);
            // Another holder of the weights (like a target network): it must keep its values.
            let kept = net.valid();
            let before = kept.weight.val().into_data();
            net = optim.step(1e-2, net, grads);
            snapshots.push((kept, before));
        }
        for (kept, before) in snapshots {
            assert_eq!(kept.weight.val().into_data(), before);
        }
        assert_eq!(counts.fused(), 0);
    }

    #[test]
    fn the_state_file_is_burns() {
        let dir = std::env::temp_dir().join(format!("mdrlat-adam-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("optimizer.bpk");
        let device = Device::flex().autodiff();
        let start = linear(&device);
        let mut uninterrupted = burn_adam();
        let net = fit(start.clone(), &mut uninterrupted, 3, 3);
        let straight = weights(&fit(net, &mut uninterrupted, 2, 3));
        // Three steps (two fused), saved, resumed by burn's Adam for two more; and the reverse.
        let counting = FusedAdam::new(1e-8);
        let counts = counting.counts();
        let mut fused = counting.into_module_optimizer();
        let net = fit(start.clone(), &mut fused, 3, 3);
        assert_eq!((counts.fused(), counts.fallback()), (4, 2));
        fused.save(&path).expect("save");
        let mut resumed = burn_adam().load(&path).expect("load");
        assert_eq!(differences(&weights(&fit(net, &mut resumed, 2, 3)), &straight), (0, 0.0));
        let mut plain = burn_adam();
        let net = fit(start.clone(), &mut plain, 3, 3);
        plain.save(&path).expect("save");
        let counting = FusedAdam::new(1e-8);
        let counts = counting.counts();
        let mut resumed = counting.into_module_optimizer().load(&path).expect("load");
        assert_eq!(differences(&weights(&fit(net, &mut resumed, 2, 3)), &straight), (0, 0.0));
        // The loaded moments were used in place from the first step on.
        assert_eq!((counts.fused(), counts.fallback()), (4, 0));
        std::fs::remove_dir_all(&dir).ok();
    }
}
