//! The network's forward and backward passes in host memory, for burn's `flex` CPU backend.
//!
//! burn's autodiff on `flex` ran an MDRLAT gradient step at 0.15–0.25 of the machine's own
//! GEMM rate: every operation allocates, element-wise passes are single-threaded, the
//! convolutions are not matrix products, and the graph is recorded for forwards that are never
//! differentiated. On the CPU the whole pass is a chain of matrix products, so these kernels
//! compute it directly on the weights' own memory (no copy): each convolution is a product
//! of patches with its weight, each linear layer one product, the backward pass the
//! transposed products, written out by hand and tested against burn's autodiff for every
//! variant (`tests` below). The network, its parameters, their ids and the optimiser are
//! still burn's — [`HostNet`] only reads the weights of a [`QNet`] and returns gradients
//! keyed by parameter id — so checkpoints, exports and every other backend are unchanged.

use crate::net::{QNet, QNetConfig};
use burn::backend::{BackendTensor, DispatchTensor, DispatchTensorKind};
use burn::module::{Param, ParamId};
use burn::prelude::*;
use burn::tensor::DType;
use mdrlat_kernels::conv::{
    self, ConvGeometry, column_sums, patch_product_backward, relu_backward, relu_in_place,
};
use mdrlat_kernels::gemm::{
    self, Conv16, Mat, conv16, conv16_weight_grad, gemm_new, gemm_short_by_long, gemm_tall,
};
use mdrlat_kernels::{transpose_into, transposed};
use rayon::prelude::*;

/// Width of the heads' hidden layers, and the bilinear fusion's `L_d`, `L_l`.
use crate::net::{FUSION_DEPTH as FUSION_D, FUSION_LASER as FUSION_L, HIDDEN};

/// `(a(), b())`, side by side through rayon where work may split (not on a one-thread pool,
/// nor in a forward of [`HostNet::on_calling_thread`]).
fn both<A: Send, B: Send>(a: impl FnOnce() -> A + Send, b: impl FnOnce() -> B + Send) -> (A, B) {
    if gemm::may_split() { rayon::join(a, b) } else { (a(), b()) }
}

/// Row-wise concatenation of `pieces` (each `[b, width_i]`) into `[b, width]`.
fn concat_columns(pieces: &[(&[f32], usize)], b: usize, width: usize) -> Vec<f32> {
    let mut out = vec![0.0; b * width];
    let mut offset = 0;
    for &(piece, w) in pieces {
        for r in 0..b {
            out[r * width + offset..r * width + offset + w]
                .copy_from_slice(&piece[r * w..(r + 1) * w]);
        }
        offset += w;
    }
    debug_assert_eq!(offset, width);
    out
}

/// The `f32` elements of a `flex` tensor, when they are one contiguous host slice.
pub fn flex_f32(kind: &DispatchTensorKind) -> Option<&[f32]> {
    match kind {
        DispatchTensorKind::Flex(BackendTensor::Float(t)) if t.dtype() == DType::F32 => {
            let (start, end) = t.layout().contiguous_offsets()?;
            t.storage::<f32>().get(start..end)
        }
        _ => None,
    }
}

/// One parameter, held (shared, not copied) for reading.
struct HostTensor {
    id: ParamId,
    dims: Vec<usize>,
    tensor: DispatchTensor,
}

impl HostTensor {
    fn new<const D: usize>(param: &Param<Tensor<D>>) -> Option<Self> {
        let tensor = param.val().inner();
        let dims = tensor.dims().to_vec();
        let tensor = tensor.into_dispatch();
        let len = flex_f32(&tensor.kind)?.len();
        (len == dims.iter().product::<usize>()).then_some(Self { id: param.id, dims, tensor })
    }

    fn data(&self) -> &[f32] {
        flex_f32(&self.tensor.kind).unwrap_or(&[])
    }
}

/// A linear layer's weight (`[in, out]`, burn's layout) and bias.
struct HostLinear {
    weight: HostTensor,
    bias: HostTensor,
    /// The weight rounded to bfloat16, when inference was asked to read it so
    /// ([`HostNet::with_bf16_weights`]).
    bf16: Option<gemm::Bf16Matrix>,
}

impl HostLinear {
    fn new(l: &burn::nn::Linear) -> Option<Self> {
        Some(Self {
            weight: HostTensor::new(&l.weight)?,
            bias: HostTensor::new(l.bias.as_ref()?)?,
            bf16: None,
        })
    }

    fn round_to_bf16(&mut self) {
        let (din, dout) = self.dims();
        self.bf16 = Some(gemm::Bf16Matrix::new(din, dout, self.weight.data()));
    }

    fn dims(&self) -> (usize, usize) {
        (self.weight.dims[0], self.weight.dims[1])
    }

    /// `x · W + b`, `[batch, out]` (with bfloat16 weights, row by row).
    fn forward(&self, x: &[f32], batch: usize) -> Vec<f32> {
        let (din, dout) = self.dims();
        let mut y = self.bias.data().repeat(batch);
        if let Some(w) = &self.bf16 {
            let mut rows = x.chunks_exact(din).zip(y.chunks_exact_mut(dout));
            if rows.all(|(x, y)| w.vec_mul(x, y)) {
                return y;
            }
            unreachable!("bfloat16 weights exist only where their kernel does");
        }
        gemm_short_by_long(batch, dout, din, x, self.weight.data(), &mut y, true);
        y
    }

    /// Gradients of the weight and bias from `dy`; with `dx`, adds (`accumulate`) or
    /// writes the input gradient `dy · Wᵀ`.
    fn backward(
        &self,
        x: &[f32],
        dy: &[f32],
        batch: usize,
        dx: Option<(&mut [f32], bool)>,
        grads: &mut Vec<HostGrad>,
    ) {
        let (din, dout) = self.dims();
        let weight = self.weight.data();
        let (dw, ()) = rayon::join(
            || gemm_tall(din, dout, batch, Mat::t(x), Mat::n(dy)),
            || {
                if let Some((dx, accumulate)) = dx {
                    // dx = dy · Wᵀ, computed as its transpose W · dyᵀ: the weight's rows
                    // are streamed once, in order (and the `gemm` crate, where it is used,
                    // runs faster with the long dimension first).
                    let dxt = gemm_tall(din, batch, dout, Mat::n(weight), Mat::t(dy));
                    transpose_into(&dxt, din, batch, dx, accumulate);
                }
            },
        );
        grads.push(HostGrad::of(&self.weight, dw));
        grads.push(HostGrad::of(&self.bias, column_sums(dy, dout)));
    }
}

/// A convolution's weight (`[out, in, kh, kw]` or `[out, in, k]`) and bias.
struct HostConv {
    weight: HostTensor,
    bias: HostTensor,
    geometry: ConvGeometry,
    /// The weight in the layouts the kernels read, made at first use and kept while the
    /// network is (a `HostNet` holds its weights' storage, so they cannot change under it):
    /// `[out, kh, kw, in]`, the patches' order (`ConvGeometry::permute_weight`), and
    /// transposed, `[kh·kw·in, out]` (the batch's patch product reads it so); for the first
    /// depth convolution, `Wᵀ` (`[in·kh·kw, out]`).
    patch_order: std::sync::OnceLock<Vec<f32>>,
    patch_order_t: std::sync::OnceLock<Vec<f32>>,
    transposed: std::sync::OnceLock<Vec<f32>>,
}

impl HostConv {
    /// A SAME-padded 2D convolution on `h × w` inputs (`None` for strides, dilations or
    /// groups these kernels do not compute).
    fn conv2d(l: &burn::nn::conv::Conv2d, h: usize, w: usize) -> Option<Self> {
        let [out, c, kh, kw] = l.weight.val().dims();
        let plain = l.stride[0] == l.stride[1] && l.dilation == [1, 1] && l.groups == 1;
        let same = matches!(l.padding, burn::nn::PaddingConfig2d::Same);
        let stride = l.stride[0];
        let geometry = ConvGeometry { h, w, c, kh, kw, stride, out_channels: out };
        (plain && same).then_some(())?;
        Self::new(&l.weight, l.bias.as_ref(), geometry)
    }

    /// A SAME-padded 1D convolution on inputs of `len` (the `H = 1` case).
    fn conv1d(l: &burn::nn::conv::Conv1d, len: usize) -> Option<Self> {
        let [out, c, k] = l.weight.val().dims();
        let plain = l.dilation == 1 && l.groups == 1;
        let same = matches!(l.padding, burn::nn::PaddingConfig1d::Same);
        let geometry =
            ConvGeometry { h: 1, w: len, c, kh: 1, kw: k, stride: l.stride, out_channels: out };
        (plain && same).then_some(())?;
        Self::new(&l.weight, l.bias.as_ref(), geometry)
    }

    fn new<const D: usize>(
        weight: &Param<Tensor<D>>,
        bias: Option<&Param<Tensor<1>>>,
        geometry: ConvGeometry,
    ) -> Option<Self> {
        let (weight, bias) = (HostTensor::new(weight)?, HostTensor::new(bias?)?);
        let expected = geometry.out_channels * geometry.patch_len();
        (weight.data().len() == expected).then_some(Self {
            weight,
            bias,
            geometry,
            patch_order: std::sync::OnceLock::new(),
            patch_order_t: std::sync::OnceLock::new(),
            transposed: std::sync::OnceLock::new(),
        })
    }

    /// The weight in the patches' order, `[out, kh, kw, in]`.
    fn patch_weight(&self) -> &[f32] {
        self.patch_order.get_or_init(|| self.geometry.permute_weight(self.weight.data()))
    }

    /// The weight in the patches' order, transposed: `[kh, kw, in, out]`.
    fn patch_weight_t(&self) -> &[f32] {
        self.patch_order_t
            .get_or_init(|| transposed(self.patch_weight(), self.geometry.out_channels))
    }

    /// `Wᵀ`, `[in·kh·kw, out]`: each patch value's weight for every filter, side by side.
    fn transposed_weight(&self) -> &[f32] {
        self.transposed.get_or_init(|| transposed(self.weight.data(), self.geometry.out_channels))
    }
}

/// A gradient, in the parameter's own layout, for the parameter with `id`.
#[derive(Debug, Clone)]
pub struct HostGrad {
    /// The parameter.
    pub id: ParamId,
    /// Its shape.
    pub dims: Vec<usize>,
    /// `∂loss/∂parameter`, row-major.
    pub values: Vec<f32>,
}

impl HostGrad {
    fn of(t: &HostTensor, values: Vec<f32>) -> Self {
        Self { id: t.id, dims: t.dims.clone(), values }
    }

    /// As a tensor on `device` (for burn's optimiser).
    pub fn into_tensor<const D: usize>(self, device: &Device) -> Tensor<D> {
        Tensor::from_data(TensorData::new(self.values, self.dims), device)
    }
}

/// Network inputs of a batch, normalised, in the network's layout.
#[derive(Debug, Clone, Copy)]
pub struct HostInputs<'a> {
    /// Rows.
    pub batch: usize,
    /// `[B, frames, beams]` laser stacks (empty when the variant has no laser).
    pub laser: &'a [f32],
    /// `[B, frames, rows, cols]` depth stacks (empty when the variant has no depth camera).
    pub depth: &'a [f32],
    /// `[B, goal_dim]` goal vectors (empty without a goal input).
    pub goal: &'a [f32],
}

/// Milliseconds of named stages, in order (see [`Tape::times`]).
#[derive(Debug, Default, Clone)]
pub struct StageClock {
    last: Option<std::time::Instant>,
    /// Each stage and its milliseconds.
    pub stages: Vec<(&'static str, f64)>,
}

impl StageClock {
    /// A clock whose first stage starts now.
    pub fn start() -> Self {
        Self { last: Some(std::time::Instant::now()), stages: Vec::new() }
    }

    /// Ends the current stage as `name` and starts the next.
    fn lap(&mut self, name: &'static str) {
        let now = std::time::Instant::now();
        if let Some(last) = self.last {
            self.stages.push((name, (now - last).as_secs_f64() * 1e3));
        }
        self.last = Some(now);
    }
}

/// What a forward pass keeps for its backward pass.
#[derive(Debug, Default)]
pub struct Tape<'a> {
    /// Time of each forward stage.
    pub times: StageClock,
    batch: usize,
    /// Depth: the input images (the first layer's patches are cut again for its weight
    /// gradient, one image at a time, rather than kept: 23 MB a batch of 32), each layer's
    /// output (channel-last) and the next layer's patches.
    depth_images: Vec<&'a [f32]>,
    depth_act: [Vec<f32>; 3],
    depth_cols: [Vec<f32>; 2],
    /// Laser: the three layers' patches and outputs (channel-last).
    laser_cols: [Vec<f32>; 3],
    laser_act: [Vec<f32>; 3],
    /// Bilinear fusion: d, l, vec(d lᵀ) and the fusion output.
    fusion: [Vec<f32>; 4],
    /// The representation `h`, `[B, h]`.
    h: Vec<f32>,
    /// Hidden activations of the value, advantage and (with the auxiliary task) velocity
    /// heads.
    hidden: Vec<Vec<f32>>,
    /// Q-values, `[B, actions]`.
    q: Vec<f32>,
    /// Velocity estimates, `[velocity_rows, 6]` (empty without the auxiliary head).
    velocity: Vec<f32>,
    /// Rows the auxiliary head ran on (the first ones).
    velocity_rows: usize,
}

impl Tape<'_> {
    /// Q-values, `[B, actions]` row-major.
    pub fn q(&self) -> &[f32] {
        &self.q
    }

    /// The auxiliary head's `(v, ω)` estimates, `[B, 6]` (empty without it).
    pub fn velocity(&self) -> &[f32] {
        &self.velocity
    }
}

/// A [`QNet`]'s weights, read in place, with forward and backward passes on the host.
pub struct HostNet {
    config: QNetConfig,
    depth: Option<[HostConv; 3]>,
    laser: Option<[HostConv; 3]>,
    fusion: Option<[HostLinear; 3]>,
    /// value, advantage, velocity: hidden and output layers.
    heads: Vec<[HostLinear; 2]>,
    /// Forward passes run every stage on the calling thread (see
    /// [`HostNet::on_calling_thread`]).
    sequential: bool,
    /// The value head's norms ([`HostNet::value_bound`]), made at the first single decision.
    value_bound: std::sync::OnceLock<ValueBound>,
}

impl std::fmt::Debug for HostNet {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HostNet").field("variant", &self.config.variant).finish()
    }
}

/// `[B, C, L]` → `[B, L, C]` (a transpose per image).
fn channels_last(x: &[f32], batch: usize, c: usize, l: usize) -> Vec<f32> {
    let mut out = vec![0.0; x.len()];
    for b in 0..batch {
        for ch in 0..c {
            for p in 0..l {
                out[(b * l + p) * c + ch] = x[(b * c + ch) * l + p];
            }
        }
    }
    out
}

/// Channel-last `[B, P, C]` activations flattened like burn's `[B, C, P]` (`c·P + p`), into
/// columns `offset..` of rows of `width`.
fn flatten_into(
    x: &[f32],
    batch: usize,
    p: usize,
    c: usize,
    out: &mut [f32],
    width: usize,
    offset: usize,
) {
    for b in 0..batch {
        let row = &mut out[b * width + offset..b * width + offset + c * p];
        for pos in 0..p {
            for ch in 0..c {
                row[ch * p + pos] = x[(b * p + pos) * c + ch];
            }
        }
    }
}

/// The adjoint of [`flatten_into`]: columns `offset..` of `dh` back to channel-last.
fn unflatten(
    dh: &[f32],
    batch: usize,
    p: usize,
    c: usize,
    width: usize,
    offset: usize,
) -> Vec<f32> {
    let mut out = vec![0.0; batch * p * c];
    for b in 0..batch {
        let row = &dh[b * width + offset..b * width + offset + c * p];
        for pos in 0..p {
            for ch in 0..c {
                out[(b * p + pos) * c + ch] = row[ch * p + pos];
            }
        }
    }
    out
}

/// Image `i` and the one after it (empty after the last), which the first convolution
/// fetches while it works on image `i` (see `conv16`).
fn with_next<'a>(images: &[&'a [f32]], i: usize) -> (&'a [f32], &'a [f32]) {
    (images[i], images.get(i + 1).copied().unwrap_or_default())
}

/// Columns `offset..offset + n` of each row of `m` (`width` wide).
fn columns(m: &[f32], batch: usize, width: usize, offset: usize, n: usize) -> Vec<f32> {
    (0..batch).flat_map(|b| m[b * width + offset..b * width + offset + n].iter().copied()).collect()
}

impl HostNet {
    /// Reads the weights of `net` (a `config` network), or `None` where they do not all lie
    /// in host memory as contiguous `f32` (any backend but `flex`).
    pub(crate) fn new(net: &QNet, config: &QNetConfig) -> Option<Self> {
        let depth = match &net.depth {
            Some(s) => {
                let c1 = HostConv::conv2d(&s.c1, config.depth_rows, config.depth_cols)?;
                let [r1, w1] = c1.geometry.out();
                let c2 = HostConv::conv2d(&s.c2, r1, w1)?;
                let [r2, w2] = c2.geometry.out();
                Some([c1, c2, HostConv::conv2d(&s.c3, r2, w2)?])
            }
            None => None,
        };
        let laser = match &net.laser {
            Some(s) => {
                let c1 = HostConv::conv1d(&s.c1, config.beams)?;
                let c2 = HostConv::conv1d(&s.c2, c1.geometry.out()[1])?;
                let c3 = HostConv::conv1d(&s.c3, c2.geometry.out()[1])?;
                Some([c1, c2, c3])
            }
            None => None,
        };
        let fusion = match &net.fusion {
            Some(fu) => Some([
                HostLinear::new(&fu.depth)?,
                HostLinear::new(&fu.laser)?,
                HostLinear::new(&fu.out)?,
            ]),
            None => None,
        };
        let head =
            |h: &crate::net::Head| Some([HostLinear::new(&h.hidden)?, HostLinear::new(&h.out)?]);
        let mut heads = vec![head(&net.value)?, head(&net.advantage)?];
        if let Some(v) = &net.velocity {
            heads.push(head(v)?);
        }
        let value_bound = std::sync::OnceLock::new();
        Some(Self {
            config: config.clone(),
            depth,
            laser,
            fusion,
            heads,
            sequential: false,
            value_bound,
        })
    }

    /// This network with forward passes that run every stage on the calling thread, none
    /// through rayon: for a policy that decides on one thread. Its streams and heads, and
    /// its products and patch cuts, would otherwise go through rayon, which, called from a
    /// thread outside a pool, runs them on the global pool and waits for it (a cost on
    /// every decision, larger when that pool sleeps; on every core where a product is
    /// large enough to split). The results are the same.
    pub fn on_calling_thread(mut self) -> Self {
        self.sequential = true;
        self
    }

    /// The forward pass; `velocity`: also run the auxiliary head (training), else only the
    /// Q-values (acting, eq. 10 targets).
    ///
    /// # Panics
    /// If an input the variant reads has the wrong size.
    pub fn forward<'a>(&self, x: &HostInputs<'a>, velocity: bool) -> Tape<'a> {
        self.forward_parts(&[*x], if velocity { x.batch } else { 0 })
    }

    /// The forward pass of `parts` stacked into one batch (the weights are read once for
    /// all of them), with the auxiliary head on the first `velocity_rows` rows (0: none).
    ///
    /// # Panics
    /// If an input the variant reads has the wrong size.
    pub fn forward_parts<'a>(&self, parts: &[HostInputs<'a>], velocity_rows: usize) -> Tape<'a> {
        if self.sequential {
            return gemm::on_this_thread(|| self.forward_stages(parts, velocity_rows));
        }
        self.forward_stages(parts, velocity_rows)
    }

    /// [`HostNet::forward_parts`]' stages.
    fn forward_stages<'a>(&self, parts: &[HostInputs<'a>], velocity_rows: usize) -> Tape<'a> {
        let mut t = self.trunk(parts);
        let (b, width) = (t.batch, self.config.representation());
        let heads: Vec<(usize, usize)> = (0..self.heads.len())
            .map(|i| (i, if i < 2 { b } else { velocity_rows.min(b) }))
            .filter(|&(_, rows)| rows > 0)
            .collect();
        let h = &t.h;
        let head = |&(i, rows): &(usize, usize)| self.head_forward(i, &h[..rows * width], rows);
        let outs: Vec<(Vec<f32>, Vec<f32>)> = if gemm::may_split() {
            heads.par_iter().map(head).collect()
        } else {
            heads.iter().map(head).collect()
        };
        t.times.lap("heads");
        t.q = dueling(&outs[0].1, &outs[1].1, b);
        for (i, (u, o)) in outs.into_iter().enumerate() {
            if i == 2 {
                t.velocity = o;
            }
            t.hidden.push(u);
        }
        t.velocity_rows = velocity_rows.min(b);
        t
    }

    /// Head `i` (value, advantage, velocity) on `rows` rows of the representation `h`: its
    /// hidden activations and its outputs.
    fn head_forward(&self, i: usize, h: &[f32], rows: usize) -> (Vec<f32>, Vec<f32>) {
        let [hidden, out] = &self.heads[i];
        let mut u = hidden.forward(h, rows);
        relu_in_place(&mut u);
        let o = out.forward(&u, rows);
        (u, o)
    }

    /// The forward pass up to the heads: the streams, the fusion and the representation
    /// `h` of the stacked `parts`, on a new tape.
    fn trunk<'a>(&self, parts: &[HostInputs<'a>]) -> Tape<'a> {
        assert!(
            !self.heads_released() && !self.fusion_released(),
            "forward pass of a network after release_heads / release_fusion"
        );
        let b: usize = parts.iter().map(|p| p.batch).sum();
        let cfg = &self.config;
        let mut t = Tape { batch: b, times: StageClock::start(), ..Tape::default() };
        let ((depth, dfeat), (laser, lfeat)) = both(
            || self.depth.as_ref().map(|layers| self.depth_forward(layers, parts, b)).unzip(),
            || self.laser.as_ref().map(|layers| self.laser_forward(layers, parts, b)).unzip(),
        );
        if let Some((images, act, cols)) = depth {
            (t.depth_images, t.depth_act, t.depth_cols) = (images, act, cols);
        }
        if let Some((cols, act)) = laser {
            (t.laser_cols, t.laser_act) = (cols, act);
        }
        t.times.lap("streams (depth beside laser)");
        let width = cfg.representation();
        let mut pieces: Vec<(&[f32], usize)> = Vec::new();
        if let Some(d) = &dfeat {
            pieces.push((d, cfg.depth_features()));
        }
        if let Some([fd, fl, fo]) = &self.fusion {
            let (dfeat, lfeat) = (dfeat.as_deref().unwrap_or(&[]), lfeat.as_deref().unwrap_or(&[]));
            let (d, l) = both(|| fd.forward(dfeat, b), || fl.forward(lfeat, b));
            let z = outer(&d, &l, b);
            let mut f = fo.forward(&z, b);
            relu_in_place(&mut f);
            t.fusion = [d, l, z, f];
            t.times.lap("bilinear fusion");
        }
        if self.fusion.is_some() {
            pieces.push((&t.fusion[3], t.fusion[3].len() / b.max(1)));
        }
        if let Some(l) = &lfeat {
            pieces.push((l, cfg.laser_features()));
        }
        let goal: Vec<f32> = parts.iter().flat_map(|p| p.goal.iter().copied()).collect();
        if cfg.goal_dim > 0 {
            assert_eq!(goal.len(), b * cfg.goal_dim, "goal input size");
            pieces.push((&goal, cfg.goal_dim));
        }
        t.h = concat_columns(&pieces, b, width);
        t
    }

    /// The depth stream on the stacked `parts`: the images, each layer's (channel-last)
    /// output, the second and third layers' patches, and the flattened features.
    #[allow(clippy::type_complexity)]
    fn depth_forward<'a>(
        &self,
        [c1, c2, c3]: &[HostConv; 3],
        parts: &[HostInputs<'a>],
        b: usize,
    ) -> ((Vec<&'a [f32]>, [Vec<f32>; 3], [Vec<f32>; 2]), Vec<f32>) {
        let cfg = &self.config;
        let image = cfg.frames * cfg.depth_rows * cfg.depth_cols;
        let mut images = Vec::with_capacity(b);
        for p in parts {
            assert_eq!(p.depth.len(), p.batch * image, "depth input size");
            images.extend(p.depth.chunks_exact(image.max(1)));
        }
        let a1 = self.depth_conv1(c1, &images);
        let mut cols = [Vec::new(), Vec::new()];
        let a2 = self.conv_relu(c2, &a1, b, &mut cols[0]);
        let a3 = self.conv_relu(c3, &a2, b, &mut cols[1]);
        let (p, c) = (c3.geometry.positions(), c3.geometry.out_channels);
        let mut dfeat = vec![0.0; b * p * c];
        flatten_into(&a3, b, p, c, &mut dfeat, p * c, 0);
        ((images, [a1, a2, a3], cols), dfeat)
    }

    /// The first depth convolution + ReLU, one image at a time, channel-last
    /// (`[B·positions, 16]`): with AVX-512 straight from the zero-padded image (16 filters in
    /// one register), else from its patches cut into a buffer that stays in the core's
    /// cache, `P · Wᵀ + b` by the short-by-long product.
    fn depth_conv1(&self, c1: &HostConv, images: &[&[f32]]) -> Vec<f32> {
        let g = c1.geometry;
        let (positions, filters, k) = (g.positions(), c1.geometry.out_channels, g.patch_len());
        // Wᵀ, [560, 16]: each patch value's weight for the 16 filters, one vector.
        let (wt, bias) = (c1.transposed_weight(), c1.bias.data());
        let mut out = bias.repeat(images.len() * positions);
        // Straight from each zero-padded image where the CPU has AVX-512 and there are 16
        // filters; else from its patches.
        let direct = Conv16::padded(&g);
        let one = |(padded, patches): &mut (Vec<f32>, Vec<f32>), (i, out): (usize, &mut [f32])| {
            let (image, next) = with_next(images, i);
            let done = filters == 16
                && direct.pad(&g, image, padded)
                && conv16(&direct, padded, wt, out, next);
            if !done {
                g.extract(image, 1, patches);
                gemm_short_by_long(positions, filters, k, patches, wt, out, true);
            }
            relu_in_place(out);
        };
        // One image (a single decision), or inside `gemm::on_this_thread`, on the calling
        // thread, as in `im2col`.
        if images.len() == 1 || !gemm::may_split() {
            let mut scratch = Default::default();
            for item in out.chunks_mut(positions * filters).enumerate() {
                one(&mut scratch, item);
            }
        } else {
            out.par_chunks_mut(positions * filters)
                .enumerate()
                .for_each_init(|| (Vec::new(), Vec::new()), one);
        }
        out
    }

    /// The first depth layer's weight gradient `Σ_images dyᵀ · P`, summed in image order,
    /// and its bias gradient: with AVX-512 and 16 filters straight from each zero-padded
    /// image ([`conv16_weight_grad`]), else from its patches cut again, one image at a time
    /// into a buffer that stays in cache.
    fn depth_conv1_backward(
        &self,
        c1: &HostConv,
        images: &[&[f32]],
        dy: &[f32],
    ) -> (Vec<f32>, Vec<f32>) {
        let g = c1.geometry;
        let (positions, filters, k) = (g.positions(), c1.geometry.out_channels, g.patch_len());
        let direct = Conv16::padded(&g);
        // Each image's share, `[560 × 16]` (transposed) when computed directly, else
        // `[16 × 560]`.
        let partial: Vec<(Vec<f32>, bool)> = dy
            .par_chunks(positions * filters)
            .enumerate()
            .map_init(
                || (Vec::new(), Vec::new()),
                |(padded, patches), (i, dy)| {
                    let (image, next) = with_next(images, i);
                    let mut dwt = vec![0.0; filters * k];
                    if filters == 16
                        && direct.pad(&g, image, padded)
                        && conv16_weight_grad(&direct, padded, dy, &mut dwt, next)
                    {
                        return (dwt, true);
                    }
                    g.extract(image, 1, patches);
                    // dW [16 × 560] = dyᵀ [16 × 320] · P [320 × 560].
                    (gemm_new(filters, k, positions, Mat::t(dy), Mat::n(patches)), false)
                },
            )
            .collect();
        let mut dw = vec![0.0; filters * k];
        for (p, _) in &partial {
            for (d, v) in dw.iter_mut().zip(p) {
                *d += v;
            }
        }
        if partial.first().is_some_and(|&(_, transposed)| transposed) {
            let dwt = std::mem::take(&mut dw);
            dw = vec![0.0; filters * k];
            transpose_into(&dwt, k, filters, &mut dw, false);
        }
        (dw, column_sums(dy, filters))
    }

    /// The laser stream on the stacked `parts`: each layer's patches and (channel-last)
    /// output, and the flattened features.
    #[allow(clippy::type_complexity)]
    fn laser_forward(
        &self,
        layers: &[HostConv; 3],
        parts: &[HostInputs<'_>],
        b: usize,
    ) -> (([Vec<f32>; 3], [Vec<f32>; 3]), Vec<f32>) {
        let cfg = &self.config;
        let mut a = Vec::with_capacity(b * cfg.frames * cfg.beams);
        for p in parts {
            assert_eq!(p.laser.len(), p.batch * cfg.frames * cfg.beams, "laser input size");
            a.extend(channels_last(p.laser, p.batch, cfg.frames, cfg.beams));
        }
        let mut cols: [Vec<f32>; 3] = Default::default();
        let mut act: [Vec<f32>; 3] = Default::default();
        for (i, layer) in layers.iter().enumerate() {
            a = self.conv_relu(layer, &a, b, &mut cols[i]);
            act[i] = a.clone();
        }
        let g = layers[2].geometry;
        let (p, c) = (g.positions(), g.out_channels);
        let mut lfeat = vec![0.0; b * p * c];
        flatten_into(&a, b, p, c, &mut lfeat, p * c, 0);
        ((cols, act), lfeat)
    }

    /// The same network reading its linear layers' weights rounded to bfloat16 (half the
    /// bytes; products summed in f32): an opt-in for inference where memory bounds a
    /// single decision. `None` where the CPU lacks the kernel (AVX-512). Only inference:
    /// [`HostNet::backward`] of such a network is not the f32 network's gradient.
    pub fn with_bf16_weights(mut self) -> Option<Self> {
        if !gemm::bf16_available() {
            return None;
        }
        for l in self.fusion.iter_mut().flatten().chain(self.heads.iter_mut().flatten()) {
            l.round_to_bf16();
        }
        Some(self)
    }

    /// Q-values alone, `[B, actions]` (no auxiliary head, nothing kept).
    pub fn q_values(&self, x: &HostInputs<'_>) -> Vec<f32> {
        self.forward(x, false).q
    }

    /// The value head's norms that [`HostNet::decide_one`] bounds its output by: one pass
    /// over its f32 weights (~8 MB for MDRLAT; kept by bfloat16 networks too) at the first
    /// call, kept while the network is (its weights cannot change under it).
    pub fn value_bound(&self) -> &ValueBound {
        self.value_bound.get_or_init(|| self.compute_value_bound())
    }

    fn compute_value_bound(&self) -> ValueBound {
        let [hidden, out] = &self.heads[0];
        // Rounding to bfloat16 moves a weight by at most 2⁻⁸ of itself, unless it rounds a
        // weight beyond bfloat16's range to infinity: no bound then.
        let bf16 = |w: &[f32]| {
            let fits = w.iter().all(|v| v.abs() < 3.38e38);
            if fits { norm(w) * (1.0 + 2f64.powi(-8)) } else { f64::INFINITY }
        };
        ValueBound {
            hidden_w: bf16(hidden.weight.data()),
            hidden_b: norm(hidden.bias.data()),
            hidden_k: hidden.dims().0 + 1,
            out_w: bf16(out.weight.data()),
            out_b: norm(out.bias.data()),
            out_k: out.dims().0 + 1,
        }
    }

    /// One observation's decision (`x.batch` = 1): its advantages alone where the action
    /// [`mdrlat_core::greedy_actions`] picks from them is provably the one it picks from
    /// the Q-values (by [`HostNet::value_bound`]), else its Q-values, the same bits as
    /// [`HostNet::q_values`] (the value head then runs on the representation already
    /// computed). Eq. (11) adds the same `V − mean(A)` to every
    /// advantage, so only the rounding of those two f32 operations could reorder actions;
    /// the value head, a third of a decision's weight bytes after the fusion, is skipped
    /// whenever the best advantage leads by more than that rounding can move (see
    /// [`ValueBound::decides`]).
    ///
    /// # Panics
    /// If `x` holds more than one row, or an input has the wrong size.
    pub fn decide_one(&self, x: &HostInputs<'_>) -> OneDecision {
        self.decide_one_with(x, self.value_bound())
    }

    /// [`HostNet::decide_one`] with another `bound` (tests).
    fn decide_one_with(&self, x: &HostInputs<'_>, bound: &ValueBound) -> OneDecision {
        assert_eq!(x.batch, 1, "decide_one: one observation");
        let run = || {
            let t = self.trunk(std::slice::from_ref(x));
            let advantage = self.head_forward(1, &t.h, 1).1;
            if bound.decides(norm(&t.h), &advantage) {
                return OneDecision::Advantages(advantage);
            }
            OneDecision::QValues(dueling(&self.head_forward(0, &t.h, 1).1, &advantage, 1))
        };
        if self.sequential { gemm::on_this_thread(run) } else { run() }
    }

    /// One convolution + ReLU on channel-last activations; keeps its patches in `cols`.
    fn conv_relu(
        &self,
        layer: &HostConv,
        x: &[f32],
        batch: usize,
        cols: &mut Vec<f32>,
    ) -> Vec<f32> {
        let weight = (layer.patch_weight(), layer.patch_weight_t());
        conv::conv_relu(&layer.geometry, x, batch, weight, layer.bias.data(), cols)
    }

    /// The backward pass of `tape` for the loss gradients `dq` (`[R, actions]`) and, with the
    /// auxiliary head, `dvelocity` (`[R, 6]`), where the loss depends on the first `R` rows of
    /// the forward pass only (`R` = its velocity rows when `dvelocity` is given): every
    /// parameter's gradient, in the network's parameter order.
    ///
    /// # Panics
    /// If a gradient does not fit the tape.
    pub fn backward(&self, tape: &Tape, dq: &[f32], dvelocity: Option<&[f32]>) -> Vec<HostGrad> {
        self.backward_timed(tape, dq, dvelocity).0
    }

    /// [`HostNet::backward`], and the time of each of its stages.
    ///
    /// # Panics
    /// As [`HostNet::backward`].
    pub fn backward_timed(
        &self,
        tape: &Tape,
        dq: &[f32],
        dvelocity: Option<&[f32]>,
    ) -> (Vec<HostGrad>, StageClock) {
        let mut clock = StageClock::start();
        let (head_grads, dh) = self.backward_heads(tape, dq, dvelocity);
        clock.lap("heads");
        let (fusion_grads, d_feat) = self.backward_fusion(tape, &dh, &mut clock);
        let mut grads = self.backward_streams(tape, &d_feat, &mut clock);
        grads.extend(fusion_grads);
        grads.extend(head_grads);
        (grads, clock)
    }

    /// The first part of [`HostNet::backward`]: the heads' parameter gradients (in
    /// parameter order) and the gradient of the representation `h` (`[B, width]`), from
    /// which [`HostNet::backward_fusion`] goes on. Split so that a learner can update the
    /// heads while the rest of the backward pass runs (see [`HostNet::release_heads`]).
    ///
    /// # Panics
    /// As [`HostNet::backward`].
    pub fn backward_heads(
        &self,
        tape: &Tape,
        dq: &[f32],
        dvelocity: Option<&[f32]>,
    ) -> (Vec<HostGrad>, Vec<f32>) {
        let (mut head_grads, mut dh, velocity) = self.backward_heads_parts(tape, dq, dvelocity);
        if let Some((grads, part)) = velocity {
            for (d, p) in dh.iter_mut().zip(&part) {
                *d += p;
            }
            head_grads.extend(grads);
        }
        (head_grads, dh)
    }

    /// [`HostNet::backward_heads`] with the Q-value heads' and the auxiliary head's parts
    /// apart: the Q heads' parameter gradients and their share of the gradient of `h`, then,
    /// given a velocity gradient, the auxiliary head's parameter gradients and its share. A
    /// learner that gives each loss its own optimiser carries the two shares through
    /// [`HostNet::backward_fusion`] and [`HostNet::backward_streams`] apart. The sum of the
    /// two shares is [`HostNet::backward_heads`]' `dh`, bit for bit.
    ///
    /// # Panics
    /// As [`HostNet::backward`].
    #[allow(clippy::type_complexity)]
    pub fn backward_heads_parts(
        &self,
        tape: &Tape,
        dq: &[f32],
        dvelocity: Option<&[f32]>,
    ) -> (Vec<HostGrad>, Vec<f32>, Option<(Vec<HostGrad>, Vec<f32>)>) {
        let cfg = &self.config;
        let width = cfg.representation();
        let actions = cfg.actions;
        let b = dq.len() / actions;
        assert!(dq.len() == b * actions && b <= tape.batch, "dq size");
        // Paper eq. (11): Q = V + A − mean(A).
        let dv: Vec<f32> = dq.chunks_exact(actions).map(|r| r.iter().sum()).collect();
        let da: Vec<f32> = dq
            .chunks_exact(actions)
            .flat_map(|r| {
                let mean = r.iter().sum::<f32>() / actions as f32;
                r.iter().map(move |g| g - mean)
            })
            .collect();
        let mut douts = vec![dv, da];
        if let Some(dvel) = dvelocity {
            assert!(
                tape.hidden.len() == 3 && tape.velocity_rows == b,
                "a velocity gradient needs the auxiliary head's forward on the same rows"
            );
            douts.push(dvel.to_vec());
        }
        assert!(!self.heads_released(), "backward_heads after release_heads");
        // Heads, side by side: the output layer, then the hidden layer and its share of dh.
        let h = &tape.h[..b * width];
        let mut per_head: Vec<(Vec<HostGrad>, Vec<f32>)> = self
            .heads
            .par_iter()
            .zip(douts.par_iter())
            .enumerate()
            .map(|(i, ([hidden, out], dout))| {
                let u = &tape.hidden[i][..b * HIDDEN];
                let mut du = vec![0.0; u.len()];
                let mut g = Vec::new();
                out.backward(u, dout, b, Some((&mut du, false)), &mut g);
                relu_backward(&mut du, u);
                let mut dh = vec![0.0; b * width];
                let mut gh = Vec::new();
                hidden.backward(h, &du, b, Some((&mut dh, false)), &mut gh);
                gh.extend(g);
                (gh, dh)
            })
            .collect();
        let velocity = (per_head.len() > 2).then(|| per_head.remove(2));
        let mut dh = vec![0.0; b * width];
        let mut head_grads = Vec::new();
        for (g, part) in per_head {
            for (d, p) in dh.iter_mut().zip(&part) {
                *d += p;
            }
            head_grads.extend(g);
        }
        (head_grads, dh, velocity)
    }

    /// Drops this network's references to the heads' weights, after
    /// [`HostNet::backward_heads`]: an optimiser may then update them in place while
    /// [`HostNet::backward_fusion`] and [`HostNet::backward_streams`] (which do not read
    /// them) run. Forward passes and [`HostNet::backward_heads`] panic afterwards.
    pub fn release_heads(&mut self) {
        self.heads.clear();
    }

    /// Whether [`HostNet::release_heads`] has dropped the heads (every network has two).
    fn heads_released(&self) -> bool {
        self.heads.is_empty()
    }

    /// Whether [`HostNet::release_fusion`] has dropped a fusion the variant has.
    fn fusion_released(&self) -> bool {
        self.config.variant.bilinear_fusion() && self.fusion.is_none()
    }

    /// The bilinear fusion's part of the backward pass from `dh` (`[B, width]`): its
    /// parameter gradients (none without a fusion), and the gradients of the depth and the
    /// laser features (`[B, depth_features]`, `[B, laser_features]`: their direct share of
    /// `dh` plus the fusion's) for [`HostNet::backward_streams`]. After it, an optimiser may
    /// update the fusion's weights in place while the streams go back
    /// ([`HostNet::release_fusion`]).
    ///
    /// # Panics
    /// If `dh` does not fit the tape, or after [`HostNet::release_fusion`].
    pub fn backward_fusion(
        &self,
        tape: &Tape,
        dh: &[f32],
        clock: &mut StageClock,
    ) -> (Vec<HostGrad>, [Vec<f32>; 2]) {
        assert!(!self.fusion_released(), "backward_fusion after release_fusion");
        let cfg = &self.config;
        let width = cfg.representation();
        let b = dh.len() / width.max(1);
        assert!(dh.len() == b * width && b <= tape.batch, "dh size");
        let h = &tape.h[..b * width];
        let depth_width = self.depth.as_ref().map_or(0, |_| cfg.depth_features());
        let fusion_width = self.fusion.as_ref().map_or(0, |f| f[2].dims().1);
        let laser_width = self.laser.as_ref().map_or(0, |_| cfg.laser_features());
        let laser_at = depth_width + fusion_width;
        let mut d_dfeat = columns(dh, b, width, 0, depth_width);
        let mut d_lfeat = columns(dh, b, width, laser_at, laser_width);
        let mut fusion_grads = Vec::new();
        if let Some([fd, fl, fo]) = &self.fusion {
            let [d, l, z, f] = &tape.fusion;
            let (d, l, z, f) = (
                &d[..b * FUSION_D],
                &l[..b * FUSION_L],
                &z[..b * FUSION_D * FUSION_L],
                &f[..b * fusion_width],
            );
            let mut df = columns(dh, b, width, depth_width, fusion_width);
            relu_backward(&mut df, f);
            let mut dz = vec![0.0; z.len()];
            let mut g_out = Vec::new();
            fo.backward(z, &df, b, Some((&mut dz, false)), &mut g_out);
            clock.lap("bilinear fusion: 8192→512 layer");
            let (dd, dl) = outer_backward(&dz, d, l, b);
            clock.lap("bilinear fusion: outer product");
            let dfeat = columns(h, b, width, 0, depth_width);
            let lfeat = columns(h, b, width, laser_at, laser_width);
            let (g_d, g_l) = rayon::join(
                || {
                    let mut g = Vec::new();
                    fd.backward(&dfeat, &dd, b, Some((&mut d_dfeat, true)), &mut g);
                    g
                },
                || {
                    let mut g = Vec::new();
                    fl.backward(&lfeat, &dl, b, Some((&mut d_lfeat, true)), &mut g);
                    g
                },
            );
            fusion_grads = [g_d, g_l, g_out].into_iter().flatten().collect();
            clock.lap("bilinear fusion: input layers");
        }
        (fusion_grads, [d_dfeat, d_lfeat])
    }

    /// Drops this network's references to the fusion's weights, after
    /// [`HostNet::backward_fusion`] (as [`HostNet::release_heads`] for the heads).
    pub fn release_fusion(&mut self) {
        self.fusion = None;
    }

    /// The streams' part of the backward pass from the gradients of their features
    /// (`d_feat`, from [`HostNet::backward_fusion`]): their parameter gradients, depth then
    /// laser, the two streams side by side.
    ///
    /// # Panics
    /// If the gradients do not fit the tape.
    pub fn backward_streams(
        &self,
        tape: &Tape,
        d_feat: &[Vec<f32>; 2],
        clock: &mut StageClock,
    ) -> Vec<HostGrad> {
        let cfg = &self.config;
        let [d_dfeat, d_lfeat] = d_feat;
        let b = if self.depth.is_some() {
            d_dfeat.len() / cfg.depth_features().max(1)
        } else {
            d_lfeat.len() / cfg.laser_features().max(1)
        };
        assert!(b <= tape.batch, "feature gradients of {b} rows, the tape has {}", tape.batch);
        let (depth_grads, laser_grads) = rayon::join(
            || self.depth.as_ref().map(|layers| self.depth_backward(layers, tape, d_dfeat, b)),
            || self.laser.as_ref().map(|layers| self.laser_backward(layers, tape, d_lfeat, b)),
        );
        clock.lap("streams (depth beside laser)");
        let mut grads: Vec<HostGrad> = depth_grads.unwrap_or_default();
        grads.extend(laser_grads.unwrap_or_default());
        grads
    }

    /// The depth stream's gradients from its features' (first `b` rows of the tape).
    fn depth_backward(
        &self,
        layers: &[HostConv; 3],
        tape: &Tape,
        d_dfeat: &[f32],
        b: usize,
    ) -> Vec<HostGrad> {
        let g3 = layers[2].geometry;
        let (p3, c3) = (g3.positions(), g3.out_channels);
        let mut d3 = unflatten(d_dfeat, b, p3, c3, p3 * c3, 0);
        relu_backward(&mut d3, &tape.depth_act[2]);
        let mut dcols = Vec::new();
        let rows = |g: ConvGeometry| b * g.positions() * g.patch_len();
        let cols3 = &tape.depth_cols[1][..rows(g3)];
        let (w3, b3) = self.conv_backward(&layers[2], cols3, &d3, b, Some(&mut dcols));
        let mut d2 = Vec::new();
        g3.col2im(&dcols, b, &mut d2);
        relu_backward(&mut d2, &tape.depth_act[1]);
        let g2 = layers[1].geometry;
        let cols2 = &tape.depth_cols[0][..rows(g2)];
        let (w2, b2) = self.conv_backward(&layers[1], cols2, &d2, b, Some(&mut dcols));
        let mut d1 = Vec::new();
        g2.col2im(&dcols, b, &mut d1);
        relu_backward(&mut d1, &tape.depth_act[0]);
        let (w1, b1) = self.depth_conv1_backward(&layers[0], &tape.depth_images[..b], &d1);
        vec![
            HostGrad::of(&layers[0].weight, w1),
            HostGrad::of(&layers[0].bias, b1),
            HostGrad::of(&layers[1].weight, w2),
            HostGrad::of(&layers[1].bias, b2),
            HostGrad::of(&layers[2].weight, w3),
            HostGrad::of(&layers[2].bias, b3),
        ]
    }

    /// The laser stream's gradients from its features' (first `b` rows of the tape).
    fn laser_backward(
        &self,
        layers: &[HostConv; 3],
        tape: &Tape,
        d_lfeat: &[f32],
        b: usize,
    ) -> Vec<HostGrad> {
        let g3 = layers[2].geometry;
        let (p3, c3) = (g3.positions(), g3.out_channels);
        let mut dy = unflatten(d_lfeat, b, p3, c3, p3 * c3, 0);
        let mut layer_grads = Vec::new();
        for i in (0..3).rev() {
            let g = layers[i].geometry;
            relu_backward(&mut dy, &tape.laser_act[i]);
            let mut dcols = Vec::new();
            let wants_input = i > 0;
            let cols = &tape.laser_cols[i][..b * g.positions() * g.patch_len()];
            let (w, bias) =
                self.conv_backward(&layers[i], cols, &dy, b, wants_input.then_some(&mut dcols));
            layer_grads
                .push([HostGrad::of(&layers[i].weight, w), HostGrad::of(&layers[i].bias, bias)]);
            if wants_input {
                let mut dx = Vec::new();
                g.col2im(&dcols, b, &mut dx);
                dy = dx;
            }
        }
        layer_grads.into_iter().rev().flatten().collect()
    }

    /// A convolution's weight (in its own `[out, in, k…]` layout) and bias gradients, and
    /// with `dcols` its patches' gradient.
    fn conv_backward(
        &self,
        layer: &HostConv,
        cols: &[f32],
        dy: &[f32],
        batch: usize,
        dcols: Option<&mut Vec<f32>>,
    ) -> (Vec<f32>, Vec<f32>) {
        let g = layer.geometry;
        let (dw, db) =
            patch_product_backward(cols, layer.patch_weight(), dy, batch * g.positions(), dcols);
        (g.unpermute_weight(&dw), db)
    }
}

/// Batched `vec(d lᵀ)` (paper eq. 7): entry `i·L_l + j` of row `b` is `d_bi · l_bj`.
fn outer(d: &[f32], l: &[f32], batch: usize) -> Vec<f32> {
    let (nd, nl) = (d.len() / batch.max(1), l.len() / batch.max(1));
    let mut z = vec![0.0; batch * nd * nl];
    for b in 0..batch {
        for i in 0..nd {
            let di = d[b * nd + i];
            let row = &mut z[(b * nd + i) * nl..(b * nd + i + 1) * nl];
            for (z, lj) in row.iter_mut().zip(&l[b * nl..(b + 1) * nl]) {
                *z = di * lj;
            }
        }
    }
    z
}

/// Gradients of [`outer`]'s inputs from its output's: `∂d_i = Σ_j ∂z_ij l_j`,
/// `∂l_j = Σ_i ∂z_ij d_i`.
fn outer_backward(dz: &[f32], d: &[f32], l: &[f32], batch: usize) -> (Vec<f32>, Vec<f32>) {
    let (nd, nl) = (d.len() / batch.max(1), l.len() / batch.max(1));
    let (mut dd, mut dl) = (vec![0.0; d.len()], vec![0.0; l.len()]);
    if nd == 0 || nl == 0 {
        return (dd, dl);
    }
    // One row of the batch per work item.
    dd.par_chunks_mut(nd)
        .zip(dl.par_chunks_mut(nl))
        .zip(dz.par_chunks(nd * nl).zip(d.par_chunks(nd).zip(l.par_chunks(nl))))
        .for_each(|((dd, dl), (dz, (d, l)))| {
            for ((dd, &di), row) in dd.iter_mut().zip(d).zip(dz.chunks_exact(nl)) {
                *dd = dot(row, l);
                for (acc, g) in dl.iter_mut().zip(row) {
                    *acc += g * di;
                }
            }
        });
    (dd, dl)
}

/// `Σ a_i b_i` in eight interleaved partial sums (so that it vectorises), added in a fixed
/// order.
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut acc = [0.0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f32 = ca.remainder().iter().zip(cb.remainder()).map(|(x, y)| x * y).sum();
    for (x, y) in ca.zip(cb) {
        for i in 0..8 {
            acc[i] += x[i] * y[i];
        }
    }
    acc.iter().sum::<f32>() + tail
}

/// What [`HostNet::decide_one`] found: values (`[actions]`) whose greedy action is the
/// Q-values'.
#[derive(Debug, Clone, PartialEq)]
pub enum OneDecision {
    /// The advantages, whose lead decides the action without the value head.
    Advantages(Vec<f32>),
    /// The Q-values.
    QValues(Vec<f32>),
}

impl OneDecision {
    /// The values, for the caller's greedy rule ([`mdrlat_core::greedy_actions`]).
    pub fn into_values(self) -> Vec<f32> {
        match self {
            Self::Advantages(v) | Self::QValues(v) => v,
        }
    }
}

/// The Euclidean norm of `v`, in f64.
fn norm(v: &[f32]) -> f64 {
    v.iter().map(|&x| f64::from(x) * f64::from(x)).sum::<f64>().sqrt()
}

/// Norms of a network's value head (hidden layer `u = relu(W h + b)`, output `V = w · u +
/// c`) that bound `|V|` for a representation of a given norm; see [`ValueBound::decides`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ValueBound {
    /// `‖W‖_F` (with room for bfloat16 rounding), `‖b‖`, and the hidden layer's inputs + 1.
    hidden_w: f64,
    hidden_b: f64,
    hidden_k: usize,
    /// `‖w‖`, `|c|`, and the output layer's inputs + 1.
    out_w: f64,
    out_b: f64,
    out_k: usize,
}

impl ValueBound {
    /// Whether, for a representation of norm `h_norm`, eq. (11) in f32 — `q_a = (V + A_a)
    /// − mean(A)` — must make the largest of `advantage` the strictly largest Q-value,
    /// whatever `V` is within the bound.
    ///
    /// The bound: `‖W h + b‖ ≤ ‖W‖_F ‖h‖ + ‖b‖`, and f32 sums of `k` products are off by at
    /// most `γ_k = k·u / (1 − k·u)` of the sum of their magnitudes (`u = 2⁻²⁴`), so the
    /// computed `|u|` and `|V|` stay below `Vb` (ReLU only shrinks; 1 % on top). Rounding
    /// is monotone, so `A_i > A_j` gives `q_i ≥ q_j`; `q_i > q_j` for certain once `A_i −
    /// A_j` exceeds the two roundings, `2u(|V| + |A|)` for `V + A` and `2u(|V + A| +
    /// |mean|)` for the subtraction — at most `4u(Vb + 3·max|A|)`; the margin asked is twice
    /// that. Non-finite advantages or a non-finite or huge bound (on `V` or on the hidden
    /// layer, where an f32 sum could overflow) give `false`, so a network
    /// whose Q-values would not be finite still takes the path that reports them.
    pub fn decides(&self, h_norm: f64, advantage: &[f32]) -> bool {
        const U: f64 = 1.0 / 16_777_216.0;
        let gamma = |k: usize| {
            let ku = k as f64 * U;
            ku / (1.0 - ku)
        };
        let hidden = (1.0 + gamma(self.hidden_k)) * (self.hidden_w * h_norm + self.hidden_b);
        let vb = 1.01 * (1.0 + gamma(self.out_k)) * (self.out_w * hidden + self.out_b);
        if !advantage.iter().all(|a| a.is_finite()) {
            return false;
        }
        let amax = advantage.iter().fold(0.0f64, |m, &a| m.max(f64::from(a).abs()));
        let scale = vb + 3.0 * amax;
        // The rounding bounds hold only where no f32 sum overflows: the hidden layer's
        // too, whatever the output layer then makes of it.
        if !(hidden < 1e37 && scale < 1e37) {
            return false;
        }
        let margin = 8.0 * U * scale + 1e-37;
        let top = advantage.iter().fold(f32::NEG_INFINITY, |m, &a| m.max(a));
        // The largest alone within the margin of the top: every other lies below it by more.
        advantage.iter().filter(|&&a| f64::from(top) - f64::from(a) <= margin).count() == 1
    }
}

/// Paper eq. (11) on host rows: `(V + A) − mean(A)`, burn's order of operations.
fn dueling(value: &[f32], advantage: &[f32], batch: usize) -> Vec<f32> {
    let actions = advantage.len() / batch.max(1);
    let mut q = Vec::with_capacity(advantage.len());
    for (v, a) in value.iter().zip(advantage.chunks_exact(actions.max(1))) {
        let mean = a.iter().sum::<f32>() / actions as f32;
        q.extend(a.iter().map(|a| (v + a) - mean));
    }
    q
}

impl QNet {
    /// This network's weights for the host kernels (see the `host` module), or `None` on a
    /// backend whose tensors do not lie in host memory (everything but `flex`).
    pub fn host(&self, config: &QNetConfig) -> Option<HostNet> {
        HostNet::new(self, config)
    }
}

#[cfg(test)]
mod tests;
