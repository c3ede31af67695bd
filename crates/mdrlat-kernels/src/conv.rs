//! SAME-padded convolutions on channel-last (`[B, H, W, C]`) activations as matrix products:
//! patches ("im2col") ordered kernel row, kernel column, channel, and the convolution weight
//! `[out, in, kh, kw]` permuted to `[out, kh, kw, in]` to match. A 1D convolution is the
//! `H = 1` case.

use crate::gemm::{Mat, gemm, gemm_tall};
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// Geometry of one SAME-padded convolution layer (TensorFlow's and burn's `Same`): the one
/// description of a convolution here, whether its images are channel-last ([`im2col`],
/// [`conv_relu`]) or channel-first ([`ConvGeometry::extract`]), and what the direct kernel's
/// [`crate::gemm::Conv16`] is derived from. A 1D convolution has `h = 1`, `kh = 1`.
///
/// [`im2col`]: ConvGeometry::im2col
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConvGeometry {
    /// Input rows.
    pub h: usize,
    /// Input columns.
    pub w: usize,
    /// Input channels.
    pub c: usize,
    /// Kernel rows.
    pub kh: usize,
    /// Kernel columns.
    pub kw: usize,
    /// Stride (both axes).
    pub stride: usize,
    /// Output channels (filters).
    pub out_channels: usize,
}

impl ConvGeometry {
    /// Output rows and columns (TensorFlow SAME: `ceil(in / stride)`).
    pub fn out(&self) -> [usize; 2] {
        [self.h.div_ceil(self.stride), self.w.div_ceil(self.stride)]
    }

    /// Output positions per image.
    pub fn positions(&self) -> usize {
        let [oh, ow] = self.out();
        oh * ow
    }

    /// Values per patch.
    pub fn patch_len(&self) -> usize {
        self.kh * self.kw * self.c
    }

    /// Padding before the first row and column (the odd pixel goes after, as in TensorFlow
    /// and burn's `Same`).
    pub fn pad_before(&self) -> [usize; 2] {
        let [oh, ow] = self.out();
        let total =
            |out: usize, k: usize, len: usize| ((out - 1) * self.stride + k).saturating_sub(len);
        [total(oh, self.kh, self.h) / 2, total(ow, self.kw, self.w) / 2]
    }

    /// For output position `(y, x)` and kernel row `ky`: the input row, and the kernel
    /// columns `lo..hi` that land inside the image with the input column of `lo`.
    fn span(&self, y: usize, x: usize, ky: usize) -> Option<(usize, usize, usize, usize)> {
        let [pt, pl] = self.pad_before();
        let iy = (y * self.stride + ky).checked_sub(pt).filter(|&iy| iy < self.h)?;
        let x0 = (x * self.stride) as isize - pl as isize;
        let lo = (-x0).max(0) as usize;
        let hi = ((self.w as isize - x0).max(0) as usize).min(self.kw);
        (lo < hi).then(|| (iy, lo, hi, (x0 + lo as isize) as usize))
    }

    /// The patches of `batch` channel-last images into `cols`, `[B·positions, patch_len]`;
    /// padding reads 0. Every value is written once: the padding's zeros beside the copied
    /// spans, not a zeroed buffer first (a whole extra pass over a buffer of megabytes, which
    /// had taken longer than the copy itself in a training step).
    pub fn im2col(&self, x: &[f32], batch: usize, cols: &mut Vec<f32>) {
        let (k, image) = (self.patch_len(), self.h * self.w * self.c);
        // Checked in release too: the `set_len` below relies on every value being written.
        assert_eq!(x.len(), batch * image, "im2col: {batch} images of {image} values");
        let len = batch * self.positions() * k;
        cols.clear();
        if k == 0 || image == 0 {
            cols.resize(len, 0.0);
            return;
        }
        cols.reserve(len);
        let [oh, ow] = self.out();
        let (c, kw) = (self.c, self.kw);
        // One image per work item; a single image, or inside `gemm::on_this_thread`, on the
        // calling thread (a rayon call from outside a pool would hand it to a pool thread).
        let fill = |(cols, img): (&mut [MaybeUninit<f32>], &[f32])| {
            let zero = |to: &mut [MaybeUninit<f32>]| to.fill(MaybeUninit::new(0.0));
            for (row, patch) in cols.chunks_exact_mut(k).enumerate() {
                let (y, xo) = (row / ow, row % ow);
                for (ky, krow) in patch.chunks_exact_mut(kw * c).enumerate() {
                    let Some((iy, lo, hi, ix)) = self.span(y, xo, ky) else {
                        zero(krow);
                        continue;
                    };
                    let src = &img[(iy * self.w + ix) * c..(iy * self.w + ix + hi - lo) * c];
                    let (before, rest) = krow.split_at_mut(lo * c);
                    let (span, after) = rest.split_at_mut((hi - lo) * c);
                    zero(before);
                    for (d, &s) in span.iter_mut().zip(src) {
                        *d = MaybeUninit::new(s);
                    }
                    zero(after);
                }
            }
            debug_assert_eq!(cols.len(), oh * ow * k);
        };
        let spare = &mut cols.spare_capacity_mut()[..len];
        if batch == 1 || !crate::gemm::may_split() {
            spare.chunks_mut(self.positions() * k).zip(x.chunks(image)).for_each(fill);
        } else {
            spare.par_chunks_mut(self.positions() * k).zip(x.par_chunks(image)).for_each(fill);
        }
        // SAFETY: the `len` values fit the capacity reserved above, and the loop above
        // wrote every one of them: `spare` is `batch` chunks of `positions · k`, each paired
        // with one image of `x`; a chunk's `positions` patches of `k = kh · kw · c` are
        // `kh` kernel rows of `kw · c`, each written whole (zeros, or zeros, the span of
        // `(hi - lo) · c` values copied from an image slice of exactly that length, zeros).
        // Every chunk has its image because `x` holds exactly `batch` images (asserted at
        // the top, in release builds too: a shorter `x` would stop the zip early). A panic
        // in `fill` leaves `cols` empty.
        #[allow(unsafe_code)]
        unsafe {
            cols.set_len(len);
        }
    }

    /// The adjoint of [`ConvGeometry::im2col`]: adds each patch value back onto the input
    /// position it was read from. `dx` is overwritten, `[B, H, W, C]`.
    pub fn col2im(&self, dcols: &[f32], batch: usize, dx: &mut Vec<f32>) {
        let (k, image) = (self.patch_len(), self.h * self.w * self.c);
        dx.clear();
        dx.resize(batch * image, 0.0);
        if k == 0 || image == 0 {
            return;
        }
        let [oh, ow] = self.out();
        let c = self.c;
        // One image per work item (images do not share input positions).
        dx.par_chunks_mut(image).zip(dcols.par_chunks(self.positions() * k)).for_each(
            |(img, dcols)| {
                for y in 0..oh {
                    for xo in 0..ow {
                        let row = (y * ow + xo) * k;
                        for ky in 0..self.kh {
                            if let Some((iy, lo, hi, ix)) = self.span(y, xo, ky) {
                                let dst = (iy * self.w + ix) * c;
                                let src = row + (ky * self.kw + lo) * c;
                                let len = (hi - lo) * c;
                                for (d, s) in
                                    img[dst..dst + len].iter_mut().zip(&dcols[src..src + len])
                                {
                                    *d += s;
                                }
                            }
                        }
                    }
                }
            },
        );
    }

    /// A convolution weight `[out, in, kh, kw]` as `[out, kh, kw, in]`, the patches' order.
    pub fn permute_weight(&self, w: &[f32]) -> Vec<f32> {
        let (c, kk) = (self.c, self.kh * self.kw);
        let mut out = vec![0.0; w.len()];
        for o in 0..self.out_channels {
            for ch in 0..c {
                for p in 0..kk {
                    out[(o * kk + p) * c + ch] = w[(o * c + ch) * kk + p];
                }
            }
        }
        out
    }

    /// The inverse of [`ConvGeometry::permute_weight`] (for weight gradients).
    pub fn unpermute_weight(&self, wp: &[f32]) -> Vec<f32> {
        let (c, kk) = (self.c, self.kh * self.kw);
        let mut out = vec![0.0; wp.len()];
        for o in 0..self.out_channels {
            for ch in 0..c {
                for p in 0..kk {
                    out[(o * c + ch) * kk + p] = wp[(o * kk + p) * c + ch];
                }
            }
        }
        out
    }
}

/// A convolution + ReLU on `batch` channel-last images `x`: their patches cut into `cols`
/// (kept: the backward pass reads them), then [`patch_product_relu`] with the weight in the
/// patches' order and transposed (`(w, wt)`).
pub fn conv_relu(
    g: &ConvGeometry,
    x: &[f32],
    batch: usize,
    (w, wt): (&[f32], &[f32]),
    bias: &[f32],
    cols: &mut Vec<f32>,
) -> Vec<f32> {
    g.im2col(x, batch, cols);
    patch_product_relu(cols, w, wt, bias, batch * g.positions())
}

/// `y = relu(cols · wᵀ + bias)`, `[rows, out]`, for patches `cols` (`[rows, k]`) and a weight
/// `w` (`[out, k]`), given also transposed (`wt`, `[k, out]`: what a batch's product reads,
/// kept by the caller instead of gathered at every call, a measurable share of the second
/// depth convolution's forward).
pub fn patch_product_relu(
    cols: &[f32],
    w: &[f32],
    wt: &[f32],
    bias: &[f32],
    rows: usize,
) -> Vec<f32> {
    let out = bias.len();
    let k = w.len() / out.max(1);
    debug_assert_eq!(wt.len(), w.len());
    // A single observation's few patches: the `gemm` crate (faster there, for a depth-only
    // decision on a Zen 4 core); a batch's: `gemm_tall`.
    if rows < 1024 {
        let mut y = bias.repeat(rows);
        gemm(rows, out, k, Mat::n(cols), Mat::t(w), &mut y, true);
        relu_in_place(&mut y);
        return y;
    }
    let mut y = gemm_tall(rows, out, k, Mat::n(cols), Mat::n(wt));
    for row in y.chunks_exact_mut(out.max(1)) {
        for (y, b) in row.iter_mut().zip(bias) {
            *y = (*y + b).max(0.0);
        }
    }
    y
}

/// Gradients of a patch product (see [`patch_product_relu`]) from `dy` (`[rows, out]`,
/// already through the ReLU): the weight's `[out, k]` and the bias's, and with `dcols` the
/// patches' (`[rows, k]`).
pub fn patch_product_backward(
    cols: &[f32],
    w: &[f32],
    dy: &[f32],
    rows: usize,
    dcols: Option<&mut Vec<f32>>,
) -> (Vec<f32>, Vec<f32>) {
    let out = dy.len() / rows.max(1);
    let k = w.len() / out.max(1);
    let (dw, ()) = rayon::join(
        || gemm_tall(out, k, rows, Mat::t(dy), Mat::n(cols)),
        || {
            if let Some(dcols) = dcols {
                *dcols = gemm_tall(rows, k, out, Mat::n(dy), Mat::n(w));
            }
        },
    );
    (dw, column_sums(dy, out))
}

/// Sums of the columns of a row-major matrix with `cols` columns.
pub fn column_sums(m: &[f32], cols: usize) -> Vec<f32> {
    let mut s = vec![0.0f32; cols];
    for row in m.chunks_exact(cols.max(1)) {
        for (s, v) in s.iter_mut().zip(row) {
            *s += v;
        }
    }
    s
}

/// `max(x, 0)` in place.
pub fn relu_in_place(x: &mut [f32]) {
    for v in x {
        *v = v.max(0.0);
    }
}

/// Zeroes the gradient where the ReLU's output was 0 (the ReLU passed nothing back).
pub fn relu_backward(dy: &mut [f32], y: &[f32]) {
    for (d, &y) in dy.iter_mut().zip(y) {
        if y <= 0.0 {
            *d = 0.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// col2im is the adjoint of im2col: <im2col(x), c> = <x, col2im(c)>.
    #[test]
    fn col2im_is_the_adjoint_of_im2col() {
        for g in [
            ConvGeometry { h: 5, w: 7, c: 3, kh: 3, kw: 4, stride: 2, out_channels: 2 },
            ConvGeometry { h: 1, w: 9, c: 2, kh: 1, kw: 3, stride: 2, out_channels: 2 },
        ] {
            let x: Vec<f32> = (0..2 * g.h * g.w * g.c).map(|v| (v % 7) as f32 - 3.0).collect();
            let mut cols = Vec::new();
            g.im2col(&x, 2, &mut cols);
            let c: Vec<f32> = (0..cols.len()).map(|v| (v % 5) as f32 * 0.5).collect();
            let mut back = Vec::new();
            g.col2im(&c, 2, &mut back);
            let lhs: f32 = cols.iter().zip(&c).map(|(a, b)| a * b).sum();
            let rhs: f32 = x.iter().zip(&back).map(|(a, b)| a * b).sum();
            assert!((lhs - rhs).abs() < 1e-3, "{lhs} vs {rhs}");
        }
    }

    /// Every patch value is written, padding as 0, into a buffer whose memory held
    /// something else before (im2col no longer zeroes the buffer first): against patches
    /// cut one value at a time from the definition of SAME padding.
    #[test]
    fn im2col_writes_every_value_over_old_contents() {
        for g in [
            ConvGeometry { h: 5, w: 7, c: 3, kh: 3, kw: 4, stride: 2, out_channels: 2 },
            ConvGeometry { h: 1, w: 9, c: 2, kh: 1, kw: 3, stride: 2, out_channels: 2 },
            ConvGeometry { h: 6, w: 6, c: 1, kh: 5, kw: 5, stride: 1, out_channels: 1 },
        ] {
            let b = 3;
            let x: Vec<f32> = (0..b * g.h * g.w * g.c).map(|v| v as f32 + 1.0).collect();
            let [oh, ow] = g.out();
            let [pt, pl] = g.pad_before();
            let mut want = Vec::new();
            for i in 0..b {
                for (y, xo) in (0..oh).flat_map(|y| (0..ow).map(move |xo| (y, xo))) {
                    for (ky, kx, ch) in (0..g.kh).flat_map(|ky| {
                        (0..g.kw).flat_map(move |kx| (0..g.c).map(move |ch| (ky, kx, ch)))
                    }) {
                        let iy = (y * g.stride + ky) as isize - pt as isize;
                        let ix = (xo * g.stride + kx) as isize - pl as isize;
                        let inside =
                            (0..g.h as isize).contains(&iy) && (0..g.w as isize).contains(&ix);
                        want.push(if inside {
                            x[((i * g.h + iy as usize) * g.w + ix as usize) * g.c + ch]
                        } else {
                            0.0
                        });
                    }
                }
            }
            let mut cols = vec![f32::NAN; want.len() + 17];
            g.im2col(&x, b, &mut cols);
            assert_eq!(cols, want, "{g:?}");
        }
    }

    /// `relu(P · Wᵀ + b)` on both paths (a few rows through the `gemm` crate, a batch's
    /// through the tall kernel reading the transposed weight) against sums taken one by one.
    #[test]
    fn patch_product_relu_matches_the_definition_on_both_paths() {
        let (k, out) = (37, 21);
        let w: Vec<f32> = (0..out * k).map(|v| ((v * 5) % 11) as f32 * 0.1 - 0.5).collect();
        let mut wt = vec![0.0; w.len()];
        crate::transpose_into(&w, out, k, &mut wt, false);
        let bias: Vec<f32> = (0..out).map(|o| o as f32 * 0.05 - 0.4).collect();
        for rows in [10, 1100] {
            let cols: Vec<f32> = (0..rows * k).map(|v| ((v * 3) % 7) as f32 * 0.25 - 0.7).collect();
            let got = patch_product_relu(&cols, &w, &wt, &bias, rows);
            assert_eq!(got.len(), rows * out);
            for r in 0..rows {
                for o in 0..out {
                    let sum: f32 =
                        (0..k).map(|p| cols[r * k + p] * w[o * k + p]).sum::<f32>() + bias[o];
                    let want = sum.max(0.0);
                    let g = got[r * out + o];
                    assert!(
                        (g - want).abs() <= 1e-4 * want.abs().max(1.0),
                        "{rows} rows, ({r}, {o}): {g} vs {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn weight_permutation_round_trips() {
        let g = ConvGeometry { h: 4, w: 4, c: 3, kh: 2, kw: 3, stride: 1, out_channels: 5 };
        let w: Vec<f32> = (0..5 * 3 * 2 * 3).map(|v| v as f32).collect();
        let p = g.permute_weight(&w);
        assert_ne!(p, w);
        assert_eq!(g.unpermute_weight(&p), w);
    }
}
