//! The Q-network: two convolutional streams, optional bilinear fusion, a dueling head and an
//! optional auxiliary velocity head.

use burn::nn::conv::{Conv1d, Conv1dConfig, Conv2d, Conv2dConfig};
use burn::nn::{Linear, LinearConfig, PaddingConfig1d, PaddingConfig2d};
use burn::prelude::*;
use burn::tensor::activation::relu;
use mdrlat_core::Variant;
use mdrlat_kernels::ConvGeometry;

/// Settings of a [`QNet`]. Defaults are the paper's input sizes.
#[derive(Config, Debug)]
pub struct QNetConfig {
    /// Which sensors and modules.
    pub variant: Variant,
    /// Length of the goal vector appended to the representation (0: obstacle avoidance;
    /// 3 for navigation: distance, sin and cos of the bearing in the robot frame).
    #[config(default = 0)]
    pub goal_dim: usize,
    /// Number of discrete actions (paper Table 1).
    #[config(default = 10)]
    pub actions: usize,
    /// Stacked frames per sensor.
    #[config(default = 4)]
    pub frames: usize,
    /// Depth image rows.
    #[config(default = 128)]
    pub depth_rows: usize,
    /// Depth image columns.
    #[config(default = 160)]
    pub depth_cols: usize,
    /// Laser beams.
    #[config(default = 512)]
    pub beams: usize,
    /// Frames of the depth camera's hidden obstacles drawn into the laser input
    /// (`sim.laser.depth_memory_frames`; 0: the laser's own scan). It changes no weight,
    /// only what the laser input means: a model records it and whatever feeds the model
    /// must draw the same scan.
    #[config(default = 0)]
    pub depth_memory_frames: usize,
}

/// Output size of a TensorFlow-"SAME" convolution with `stride`.
fn same(len: usize, stride: usize) -> usize {
    len.div_ceil(stride)
}

impl QNetConfig {
    /// Length of the flattened depth features: 32 x 8 x 10 = 2560 at 128 x 160.
    pub fn depth_features(&self) -> usize {
        32 * same(same(self.depth_rows, 8), 2) * same(same(self.depth_cols, 8), 2)
    }

    /// Length of the flattened laser features: 32 x 32 = 1024 at 512 beams.
    pub fn laser_features(&self) -> usize {
        32 * same(same(same(self.beams, 4), 2), 2)
    }

    /// Length of the representation `h` fed to the heads (4096 for MDRLAT).
    pub fn representation(&self) -> usize {
        let v = self.variant;
        let mut h = self.goal_dim;
        if v.uses_depth() {
            h += self.depth_features();
        }
        if v.uses_laser() {
            h += self.laser_features();
        }
        if v.bilinear_fusion() {
            h += FUSION_OUT;
        }
        h
    }

    /// Floating-point operations of one forward pass for one observation (2 per
    /// multiply-add of every convolution and linear layer, plus the bilinear outer product):
    /// ~30.8 M for MDRLAT. The yardstick of the learner's and the evaluation's speed.
    pub fn forward_flops(&self) -> u64 {
        let v = self.variant;
        let (r, c) = (self.depth_rows, self.depth_cols);
        let mut macs = 0usize;
        if v.uses_depth() {
            let (r1, c1) = (same(r, 8), same(c, 8));
            let (r2, c2) = (same(r1, 2), same(c1, 2));
            macs += 16 * r1 * c1 * self.frames * 10 * 14;
            macs += 32 * r2 * c2 * 16 * 4 * 4;
            macs += 32 * r2 * c2 * 32 * 3 * 3;
        }
        if v.uses_laser() {
            let b1 = same(self.beams, 4);
            let (b2, b3) = (same(b1, 2), same(same(b1, 2), 2));
            macs += 16 * b1 * self.frames * 5 + 32 * b2 * 16 * 3 + 32 * b3 * 32 * 3;
        }
        if v.bilinear_fusion() {
            macs += self.depth_features() * FUSION_DEPTH
                + self.laser_features() * FUSION_LASER
                + FUSION_DEPTH * FUSION_LASER * (1 + FUSION_OUT);
        }
        let h = self.representation();
        let heads = if v.auxiliary_task() { 3 } else { 2 };
        macs += heads * h * HIDDEN + HIDDEN * (1 + self.actions);
        if v.auxiliary_task() {
            macs += HIDDEN * VELOCITY_OUT;
        }
        2 * macs as u64
    }

    /// Floating-point operations of one observation's backward pass in a gradient step: for
    /// every layer the weight gradient and the input gradient (each as many multiply-adds as
    /// its forward), except the input gradient of the first layers, which no one needs.
    pub fn backward_flops(&self) -> u64 {
        let v = self.variant;
        let mut first = 0usize;
        if v.uses_depth() {
            let (r1, c1) = (same(self.depth_rows, 8), same(self.depth_cols, 8));
            first += 16 * r1 * c1 * self.frames * 10 * 14;
        }
        if v.uses_laser() {
            first += 16 * same(self.beams, 4) * self.frames * 5;
        }
        2 * self.forward_flops() - 2 * first as u64
    }

    /// Floating-point operations of one double-DQN gradient step per sample of its batch
    /// (paper eqs. 10–13): the online forward on `s` with the auxiliary head, two greedy
    /// forwards on `s'` (online and target) and the backward pass (~140 M for MDRLAT).
    pub fn update_flops(&self) -> u64 {
        self.forward_flops() + 2 * self.decision_flops() + self.backward_flops()
    }

    /// Floating-point operations of one greedy decision ([`QNet::q_values`]): the forward
    /// pass without the auxiliary head (~26.6 M for MDRLAT).
    pub fn decision_flops(&self) -> u64 {
        let aux = if self.variant.auxiliary_task() {
            2 * (self.representation() * HIDDEN + HIDDEN * VELOCITY_OUT) as u64
        } else {
            0
        };
        self.forward_flops() - aux
    }

    /// Builds the network on `device` with weights drawn from `seed` (the same on every
    /// backend and in every thread; see the `init` module).
    pub fn init_seeded(&self, device: &Device, seed: u64) -> QNet {
        self.init(device).map(&mut crate::init::SeededInit::new(seed))
    }

    /// Builds the network with burn's own initialisation on `device` (seeded by the backend,
    /// process-wide); prefer [`QNetConfig::init_seeded`] for reproducible runs.
    pub fn init(&self, device: &Device) -> QNet {
        let v = self.variant;
        let conv2 = |c: [usize; 2], k: [usize; 2], s: usize| {
            Conv2dConfig::new(c, k)
                .with_stride([s, s])
                .with_padding(PaddingConfig2d::Same)
                .init(device)
        };
        let conv1 = |c: [usize; 2], k: usize, s: usize| {
            Conv1dConfig::new(c[0], c[1], k)
                .with_stride(s)
                .with_padding(PaddingConfig1d::Same)
                .init(device)
        };
        let linear = |i: usize, o: usize| LinearConfig::new(i, o).init(device);
        let head = |out: usize| Head {
            hidden: linear(self.representation(), HIDDEN),
            out: linear(HIDDEN, out),
        };
        QNet {
            depth: v.uses_depth().then(|| DepthStream {
                c1: conv2([self.frames, 16], [10, 14], 8),
                c2: conv2([16, 32], [4, 4], 2),
                c3: conv2([32, 32], [3, 3], 1),
            }),
            laser: v.uses_laser().then(|| LaserStream {
                c1: conv1([self.frames, 16], 5, 4),
                c2: conv1([16, 32], 3, 2),
                c3: conv1([32, 32], 3, 2),
            }),
            fusion: v.bilinear_fusion().then(|| Fusion {
                depth: linear(self.depth_features(), FUSION_DEPTH),
                laser: linear(self.laser_features(), FUSION_LASER),
                out: linear(FUSION_DEPTH * FUSION_LASER, FUSION_OUT),
            }),
            value: head(1),
            advantage: head(self.actions),
            velocity: v.auxiliary_task().then(|| head(VELOCITY_OUT)),
        }
    }
}

/// Width of the head's hidden layers.
pub(crate) const HIDDEN: usize = 512;
/// Bilinear fusion sizes of the paper: L_d = 128, L_l = 64, K = 512.
pub(crate) const FUSION_DEPTH: usize = 128;
pub(crate) const FUSION_LASER: usize = 64;
const FUSION_OUT: usize = 512;
/// (v, ω) at t−2, t−1, t.
const VELOCITY_OUT: usize = 6;

/// The depth stream: three 2D convolutions.
#[derive(Module, Debug)]
pub struct DepthStream {
    pub(crate) c1: Conv2d,
    pub(crate) c2: Conv2d,
    pub(crate) c3: Conv2d,
}

/// What the depth stream reads: a batch of depth stacks, or the first convolution's patches
/// of them. Both give the same features (tested); which is faster depends on the backend
/// (see [`depth_input`]).
#[derive(Debug, Clone)]
pub enum DepthInput {
    /// `[B, frames, rows, cols]` normalised depth stacks, which the first layer convolves.
    Stacks(Tensor<4>),
    /// `[B, out_rows, out_cols, frames·10·14]` SAME-padded patches of the stacks (see
    /// [`depth_patches`]), which the first layer multiplies by its weight.
    Patches(Tensor<4>),
}

impl DepthStream {
    /// # Shapes
    /// `x`: `Stacks [B, 4, 128, 160]` or `Patches [B, 16, 20, 560]` → `[B, 2560]`.
    ///
    /// # Panics
    /// If patches are not as long as the first layer's kernel.
    fn forward(&self, x: DepthInput) -> Tensor<2> {
        let x = match x {
            DepthInput::Stacks(x) => self.c1.forward(x), // [B, 16, 16, 20]
            DepthInput::Patches(x) => {
                let weight = self.c1.weight.val(); // [16, 4, 10, 14]
                let [filters, frames, kh, kw] = weight.dims();
                let [b, oh, ow, k] = x.dims();
                assert_eq!(k, frames * kh * kw, "depth patches of a {frames}x{kh}x{kw} kernel");
                let weight = weight.reshape([filters, k]).transpose(); // [560, 16]
                let x = x.reshape([b * oh * ow, k]).matmul(weight); // [B·16·20, 16]
                let x = match &self.c1.bias {
                    Some(bias) => x + bias.val().unsqueeze_dim::<2>(0), // [1, 16]
                    None => x,
                };
                x.reshape([b, oh, ow, filters]).permute([0, 3, 1, 2]) // [B, 16, 16, 20]
            }
        };
        let x = relu(self.c2.forward(relu(x))); // [B, 32, 8, 10]
        let x = relu(self.c3.forward(x)); // [B, 32, 8, 10]
        x.flatten(1, 3) // [B, 2560]
    }
}

/// Whether `device` (with or without autodiff) is burn's pure-Rust `flex` CPU backend, whose
/// kernels are single-threaded: the learner runs independent work side by side there, and
/// the depth stream is fed patches (see [`prefers_depth_patches`]).
pub fn is_flex(device: &Device) -> bool {
    device.clone().inner() == Device::flex()
}

/// Whether `device` is LibTorch's (its CPU or a CUDA GPU; always false in a build without
/// the `tch` feature).
pub fn is_libtorch(device: &Device) -> bool {
    #[cfg(feature = "tch")]
    {
        matches!(device.clone().inner().as_dispatch(), burn::backend::DispatchDevice::LibTorch(_))
    }
    #[cfg(not(feature = "tch"))]
    {
        let _ = device;
        false
    }
}

/// Whether `device` is a LibTorch GPU (CUDA, MPS, Vulkan; always false without `tch`).
#[allow(deprecated)] // burn-tch is deprecated upstream; it is our `tch` backend.
pub fn is_libtorch_gpu(device: &Device) -> bool {
    #[cfg(feature = "tch")]
    {
        matches!(
            device.clone().inner().as_dispatch(),
            burn::backend::DispatchDevice::LibTorch(d) if *d != burn::backend::libtorch::LibTorchDevice::Cpu
        )
    }
    #[cfg(not(feature = "tch"))]
    {
        let _ = device;
        false
    }
}

/// Whether the depth stream's first layer should be fed patches cut on the host (burn's
/// `flex` CPU backend, whose direct convolution is slow) rather than the stacks themselves
/// (LibTorch and the GPUs convolve well, and patches are 2.2× the bytes to move).
pub fn prefers_depth_patches(device: &Device) -> bool {
    is_flex(device)
}

/// The depth network input of a batch of normalised `[B, frames, rows, cols]` depth
/// stacks on `device`: on `flex` the first convolution's SAME-padded patches, elsewhere the
/// stacks (see [`prefers_depth_patches`]).
pub fn depth_input(
    stacks: &[f32],
    batch: usize,
    rows: usize,
    cols: usize,
    device: &Device,
) -> DepthInput {
    if prefers_depth_patches(device) {
        DepthInput::Patches(depth_patches(stacks, batch, rows, cols, device))
    } else {
        let frames = stacks.len() / (batch * rows * cols).max(1);
        let shape = [batch, frames, rows, cols];
        DepthInput::Stacks(Tensor::from_data(TensorData::new(stacks.to_vec(), shape), device))
    }
}

/// The first convolution's SAME-padded patches of a batch of normalised
/// `[B, frames, rows, cols]` depth stacks, as `[B, out_rows, out_cols, 560]`
/// (`[B, 16, 20, 560]` at 128 x 160). See `mdrlat_kernels::patches` for why.
pub fn depth_patches(
    stacks: &[f32],
    batch: usize,
    rows: usize,
    cols: usize,
    device: &Device,
) -> Tensor<4> {
    let frames = stacks.len() / (batch * rows * cols).max(1);
    let g = depth_conv1_geometry(frames, rows, cols);
    let mut buf = Vec::new();
    g.extract(stacks, batch, &mut buf);
    let [oh, ow] = g.out();
    Tensor::from_data(TensorData::new(buf, [batch, oh, ow, g.patch_len()]), device)
}

/// The paper's first depth convolution (16 filters of `frames` × 10 × 14 at stride 8) on
/// `[frames, rows, cols]` stacks.
pub fn depth_conv1_geometry(frames: usize, rows: usize, cols: usize) -> ConvGeometry {
    ConvGeometry { h: rows, w: cols, c: frames, kh: 10, kw: 14, stride: 8, out_channels: 16 }
}

/// The laser stream: three 1D convolutions.
#[derive(Module, Debug)]
pub struct LaserStream {
    pub(crate) c1: Conv1d,
    pub(crate) c2: Conv1d,
    pub(crate) c3: Conv1d,
}

impl LaserStream {
    /// # Shapes
    /// `[B, 4, 512]` → `[B, 1024]`.
    fn forward(&self, x: Tensor<3>) -> Tensor<2> {
        let x = relu(self.c1.forward(x)); // [B, 16, 128]
        let x = relu(self.c2.forward(x)); // [B, 32, 64]
        let x = relu(self.c3.forward(x)); // [B, 32, 32]
        x.flatten(1, 2) // [B, 1024]
    }
}

/// Bilinear fusion (paper eqs. 7–8).
#[derive(Module, Debug)]
pub struct Fusion {
    pub(crate) depth: Linear,
    pub(crate) laser: Linear,
    pub(crate) out: Linear,
}

/// `vec(d lᵀ)` of paper eq. (7), batched: entry `i·L_l + j` is `d_i · l_j`, so a linear
/// layer on it computes eq. (8), `Σ_ij w_ijk d_i l_j`.
///
/// # Shapes
/// `d: [B, L_d]`, `l: [B, L_l]` → `[B, L_d·L_l]`.
#[doc(alias = "eq7")]
#[doc(alias = "eq8")]
pub fn bilinear(d: Tensor<2>, l: Tensor<2>) -> Tensor<2> {
    let outer = d.unsqueeze_dim::<3>(2).matmul(l.unsqueeze_dim::<3>(1)); // [B, L_d, L_l]
    outer.flatten(1, 2) // [B, L_d·L_l]
}

impl Fusion {
    /// # Shapes
    /// `depth: [B, 2560]`, `laser: [B, 1024]` → `[B, 512]`.
    fn forward(&self, depth: Tensor<2>, laser: Tensor<2>) -> Tensor<2> {
        let d = self.depth.forward(depth); // [B, 128]
        let l = self.laser.forward(laser); // [B, 64]
        relu(self.out.forward(bilinear(d, l))) // [B, 512]
    }
}

/// Linear → ReLU → Linear.
#[derive(Module, Debug)]
pub struct Head {
    pub(crate) hidden: Linear,
    pub(crate) out: Linear,
}

impl Head {
    /// # Shapes
    /// `[B, h]` → `[B, out]`.
    fn forward(&self, h: Tensor<2>) -> Tensor<2> {
        self.out.forward(relu(self.hidden.forward(h)))
    }
}

/// Paper eq. (11): `Q(s, a) = V(s) + A(s, a) − mean_a' A(s, a')`.
///
/// # Shapes
/// `value: [B, 1]`, `advantage: [B, A]` → `[B, A]`.
#[doc(alias = "eq11")]
pub fn dueling(value: Tensor<2>, advantage: Tensor<2>) -> Tensor<2> {
    let mean = advantage.clone().mean_dim(1); // [B, 1]
    value + advantage - mean
}

/// The network of SPEC §3, configured by [`QNetConfig`].
#[derive(Module, Debug)]
pub struct QNet {
    pub(crate) depth: Option<DepthStream>,
    pub(crate) laser: Option<LaserStream>,
    pub(crate) fusion: Option<Fusion>,
    pub(crate) value: Head,
    pub(crate) advantage: Head,
    pub(crate) velocity: Option<Head>,
}

/// Time of one network stage (see [`QNet::stage_times`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageTime {
    /// The stage.
    pub name: &'static str,
    /// Forward milliseconds.
    pub forward_ms: f64,
    /// Backward milliseconds (when measured).
    pub backward_ms: Option<f64>,
}

/// What [`QNet::forward`] returns.
#[derive(Debug, Clone)]
pub struct QOutput {
    /// Q-values, `[B, actions]`.
    pub q: Tensor<2>,
    /// Estimated `(v_{t−2}, ω_{t−2}, v_{t−1}, ω_{t−1}, v_t, ω_t)`, `[B, 6]`, with the
    /// auxiliary task.
    pub velocity: Option<Tensor<2>>,
}

impl QNet {
    /// The representation `h = concat(depth features, fusion, laser features, goal)`.
    ///
    /// # Shapes
    /// `laser: [B, 4, 512]`, `depth`: stacks `[B, 4, 128, 160]` or their patches
    /// `[B, 16, 20, 560]` (see [`DepthInput`]; each when the variant reads it),
    /// `goal: [B, goal_dim]` → `[B, h]`.
    ///
    /// # Panics
    /// If an input the variant needs is missing.
    pub fn representation(
        &self,
        laser: Option<Tensor<3>>,
        depth: Option<DepthInput>,
        goal: Option<Tensor<2>>,
    ) -> Tensor<2> {
        let d = self
            .depth
            .as_ref()
            .map(|s| s.forward(depth.expect("this variant reads the depth camera")));
        let l =
            self.laser.as_ref().map(|s| s.forward(laser.expect("this variant reads the laser")));
        let f = match (&self.fusion, &d, &l) {
            (Some(fusion), Some(d), Some(l)) => Some(fusion.forward(d.clone(), l.clone())),
            _ => None,
        };
        let parts: Vec<Tensor<2>> = [d, f, l, goal].into_iter().flatten().collect();
        Tensor::cat(parts, 1)
    }

    /// Milliseconds of each stage of one forward pass and, with `backward` (on an autodiff
    /// device only), of its backward pass: each stage's inputs are detached, so a stage's
    /// backward time is its own; `goal` joins the representation as in the forward pass
    /// (the navigation task). For `mdrlat bench train --profile`.
    pub fn stage_times(
        &self,
        laser: Option<Tensor<3>>,
        depth: Option<DepthInput>,
        goal: Option<Tensor<2>>,
        backward: bool,
    ) -> Vec<StageTime> {
        let mut times = Vec::new();
        let mut timed = |name: &'static str, f: &mut dyn FnMut() -> Tensor<2>| {
            let t = std::time::Instant::now();
            let out = f();
            let _ = out.clone().into_data(); // make sure the work is done
            let forward_ms = t.elapsed().as_secs_f64() * 1e3;
            let backward_ms = backward.then(|| {
                let t = std::time::Instant::now();
                drop(out.clone().sum().backward());
                t.elapsed().as_secs_f64() * 1e3
            });
            times.push(StageTime { name, forward_ms, backward_ms });
            out.detach()
        };
        let d = self
            .depth
            .as_ref()
            .zip(depth)
            .map(|(s, x)| timed("depth stream (3 conv)", &mut || s.forward(x.clone())));
        let l = self
            .laser
            .as_ref()
            .zip(laser)
            .map(|(s, x)| timed("laser stream (3 conv1d)", &mut || s.forward(x.clone())));
        let f = match (&self.fusion, &d, &l) {
            (Some(fu), Some(d), Some(l)) => {
                Some(timed("bilinear fusion", &mut || fu.forward(d.clone(), l.clone())))
            }
            _ => None,
        };
        let h = Tensor::cat([d, f, l, goal].into_iter().flatten().collect(), 1);
        timed("value head", &mut || self.value.forward(h.clone()));
        timed("advantage head", &mut || self.advantage.forward(h.clone()));
        if let Some(v) = &self.velocity {
            timed("velocity head (AT)", &mut || v.forward(h.clone()));
        }
        times
    }

    /// Q-values alone (paper eq. 11), without the auxiliary head: what acting and the
    /// double-DQN targets (eq. 10) need; the same values as `forward(…).q`.
    ///
    /// # Shapes
    /// As [`QNet::forward`]; `[B, actions]`.
    ///
    /// # Panics
    /// If an input the variant needs is missing.
    pub fn q_values(
        &self,
        laser: Option<Tensor<3>>,
        depth: Option<DepthInput>,
        goal: Option<Tensor<2>>,
    ) -> Tensor<2> {
        let h = self.representation(laser, depth, goal);
        dueling(self.value.forward(h.clone()), self.advantage.forward(h))
    }

    /// Q-values and, with the auxiliary task, the velocity estimate.
    ///
    /// # Shapes
    /// As [`QNet::representation`]; `q: [B, actions]`, `velocity: [B, 6]`.
    ///
    /// # Panics
    /// If an input the variant needs is missing.
    pub fn forward(
        &self,
        laser: Option<Tensor<3>>,
        depth: Option<DepthInput>,
        goal: Option<Tensor<2>>,
    ) -> QOutput {
        let h = self.representation(laser, depth, goal);
        let q = dueling(self.value.forward(h.clone()), self.advantage.forward(h.clone()));
        let velocity = self.velocity.as_ref().map(|head| head.forward(h));
        QOutput { q, velocity }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The patch product is the same convolution burn computes directly (SAME padding).
    #[test]
    fn patch_product_equals_the_direct_convolution() {
        let dev = Device::flex();
        let net = QNetConfig::new(Variant::DepthOnly).init_seeded(&dev, 5);
        let stream = net.depth.as_ref().expect("depth stream");
        let mut rng = mdrlat_core::Rng::seed_from_u64(1);
        let raw: Vec<f32> = (0..2 * 4 * 128 * 160).map(|_| rng.uniform() as f32).collect();
        let x = Tensor::<4>::from_data(TensorData::new(raw.clone(), [2, 4, 128, 160]), &dev);
        let direct = stream.c1.forward(x); // [2, 16, 16, 20]
        let patches = depth_patches(&raw, 2, 128, 160, &dev);
        let [b, oh, ow, k] = patches.dims();
        let w = stream.c1.weight.val().reshape([16, k]).transpose();
        let bias = stream.c1.bias.as_ref().expect("bias").val().unsqueeze_dim::<2>(0);
        let product = (patches.reshape([b * oh * ow, k]).matmul(w) + bias)
            .reshape([b, oh, ow, 16])
            .permute([0, 3, 1, 2]);
        let (d, p) = (
            direct.into_data().try_to_vec::<f32>().expect("f32"),
            product.into_data().try_to_vec::<f32>().expect("f32"),
        );
        assert_eq!(d.len(), p.len());
        let worst = d.iter().zip(&p).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "max difference {worst}");
    }

    /// The network gives the same Q-values whichever depth input form it is fed.
    #[test]
    fn stacks_and_patches_give_the_same_q_values() {
        let dev = Device::flex();
        let net = QNetConfig::new(Variant::Mdrlat).init_seeded(&dev, 3);
        let mut rng = mdrlat_core::Rng::seed_from_u64(2);
        let raw: Vec<f32> = (0..2 * 4 * 128 * 160).map(|_| rng.uniform() as f32).collect();
        let laser: Vec<f32> = (0..2 * 4 * 512).map(|_| rng.uniform() as f32).collect();
        let laser = Tensor::<3>::from_data(TensorData::new(laser, [2, 4, 512]), &dev);
        let stacks = Tensor::<4>::from_data(TensorData::new(raw.clone(), [2, 4, 128, 160]), &dev);
        let stacks = DepthInput::Stacks(stacks);
        assert!(prefers_depth_patches(&dev) && prefers_depth_patches(&dev.clone().autodiff()));
        let patches = depth_input(&raw, 2, 128, 160, &dev);
        assert!(matches!(&patches, DepthInput::Patches(p) if p.dims() == [2, 16, 20, 560]));
        let q = |d: DepthInput| {
            let out = net.forward(Some(laser.clone()), Some(d), None).q;
            out.into_data().try_to_vec::<f32>().expect("f32")
        };
        let (a, b) = (q(stacks), q(patches));
        let worst = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "max difference {worst}");
    }

    /// LibTorch gets the stacks themselves (`cargo test --features tch`).
    #[cfg(feature = "tch")]
    #[test]
    #[allow(deprecated)] // burn-tch is deprecated upstream; it is our `tch` backend.
    fn libtorch_gets_the_stacks() {
        let dev = Device::libtorch();
        assert!(!prefers_depth_patches(&dev) && !prefers_depth_patches(&dev.clone().autodiff()));
        let input = depth_input(&vec![0.5; 4 * 128 * 160], 1, 128, 160, &dev);
        assert!(matches!(&input, DepthInput::Stacks(s) if s.dims() == [1, 4, 128, 160]));
    }

    /// Which devices are LibTorch's, and which of those a GPU (naming a CUDA device needs
    /// no GPU).
    #[cfg(feature = "tch")]
    #[test]
    #[allow(deprecated)] // burn-tch is deprecated upstream; it is our `tch` backend.
    fn libtorch_devices_are_told_apart() {
        let (cpu, gpu) = (Device::libtorch(), Device::libtorch_cuda(0));
        assert!(is_libtorch(&cpu) && is_libtorch(&gpu) && is_libtorch(&gpu.clone().autodiff()));
        assert!(!is_libtorch_gpu(&cpu) && is_libtorch_gpu(&gpu));
        assert!(!is_libtorch(&Device::flex()) && !is_libtorch_gpu(&Device::flex()));
    }

    #[test]
    fn flex_is_not_libtorch() {
        assert!(!is_libtorch(&Device::flex()) && !is_libtorch_gpu(&Device::flex().autodiff()));
        assert!(is_flex(&Device::flex()) && is_flex(&Device::flex().autodiff()));
        // In a build with LibTorch the test can tell the two apart the other way too.
        #[cfg(feature = "tch")]
        #[allow(deprecated)]
        {
            assert!(is_libtorch(&Device::libtorch()) && !is_flex(&Device::libtorch()));
            assert!(!is_libtorch_gpu(&Device::libtorch()));
        }
    }
}
