//! Patches of channel-first images (`[B, C, H, W]`, the depth stacks as they come), ordered
//! channel, kernel row, kernel column like a `[out, C, kh, kw]` convolution weight.
//!
//! The first depth layer (16 filters of 4 x 10 x 14, stride 8, SAME padding) dominated the
//! CPU training step as a direct convolution on burn-flex (`docs/performance.md`). Its input is
//! data, never a parameter, so its patches ("im2col") can be cut on the host once per
//! batch; the layer is then one matrix product with the convolution's own weight, which
//! any backend's GEMM handles well, forward and backward. The weight keeps its
//! `[16, 4, 10, 14]` convolution layout, so exported weights are a plain `Conv2d`.

use crate::conv::ConvGeometry;
use rayon::prelude::*;
use std::mem::MaybeUninit;

impl ConvGeometry {
    /// Cuts the patches of `batch` channel-first images (`[B, c, h, w]`, row-major) into
    /// `out` as `[B, positions, patch_len]`, each patch ordered channel, kernel row, kernel
    /// column; padding reads 0.
    ///
    /// # Panics
    /// If `images` does not hold `batch` images.
    pub fn extract(&self, images: &[f32], batch: usize, out: &mut Vec<f32>) {
        out.clear();
        self.extract_append(images, batch, out);
    }

    /// [`ConvGeometry::extract`], appending to `out`: each value is written once (no
    /// zeroing pass over the 23 MB of a batch of 32 first), one image per work item.
    ///
    /// # Panics
    /// If `images` does not hold `batch` images.
    #[allow(unsafe_code)]
    pub fn extract_append(&self, images: &[f32], batch: usize, out: &mut Vec<f32>) {
        let (c, h, w) = (self.c, self.h, self.w);
        assert_eq!(images.len(), batch * c * h * w, "patch input size");
        let per_image = self.positions() * self.patch_len();
        if per_image == 0 || batch == 0 {
            return;
        }
        let start = out.len();
        out.reserve(batch * per_image);
        let spare = &mut out.spare_capacity_mut()[..batch * per_image];
        if batch == 1 {
            self.extract_one(images, spare);
        } else {
            spare
                .par_chunks_mut(per_image)
                .zip(images.par_chunks(c * h * w))
                .for_each(|(out, image)| self.extract_one(image, out));
        }
        // SAFETY: `extract_one` writes every element of its image's chunk (each patch row
        // is filled as zeros, copied pixels, zeros over its full kernel width, for every
        // position, channel and kernel row: `patch_len` values per position), and the
        // chunks cover the `batch · per_image` elements after `start`, within the capacity
        // reserved above.
        unsafe { out.set_len(start + batch * per_image) };
    }

    /// The patches of one `[channels, rows, cols]` image into `out` (one image's worth):
    /// every value is written, padding as 0.
    fn extract_one(&self, image: &[f32], out: &mut [MaybeUninit<f32>]) {
        let (c, h, w) = (self.c, self.h, self.w);
        let [or, oc] = self.out();
        let (kh, kw) = (self.kh, self.kw);
        let [pt, pl] = self.pad_before();
        let (patch, kernel_plane) = (self.patch_len(), kh * kw);
        debug_assert_eq!(out.len(), or * oc * patch);
        let mut o = 0;
        for y in 0..or {
            for x in 0..oc {
                // Kernel columns that land inside the image: one slice copy per row.
                let x0 = (x * self.stride) as isize - pl as isize;
                let kx_lo = ((-x0).max(0) as usize).min(kw);
                let kx_hi = ((w as isize - x0).max(0) as usize).clamp(kx_lo, kw);
                for ch in 0..c {
                    let plane = &image[ch * h * w..(ch + 1) * h * w];
                    for ky in 0..kh {
                        let iy = (y * self.stride + ky) as isize - pt as isize;
                        let dst = o + ch * kernel_plane + ky * kw;
                        let row = &mut out[dst..dst + kw];
                        if !(0..h as isize).contains(&iy) {
                            write_zeros(row);
                            continue;
                        }
                        let src = iy as usize * w + (x0 + kx_lo as isize) as usize;
                        if kx_lo == 0 && kx_hi == kw && kw == 14 {
                            // The paper's kernel width, inside the image: a copy of known
                            // length, which the compiler inlines (the patch rows are 56 bytes).
                            write_copy_n::<14>(row, &plane[src..src + 14]);
                            continue;
                        }
                        write_zeros(&mut row[..kx_lo]);
                        if kx_lo < kx_hi {
                            write_copy(&mut row[kx_lo..kx_hi], &plane[src..src + kx_hi - kx_lo]);
                        }
                        write_zeros(&mut row[kx_hi..]);
                    }
                }
                o += patch;
            }
        }
    }
}

/// `dst = src` into memory that may be uninitialised (a `memcpy`; the element loop the
/// compiler made of `MaybeUninit::write` was 4 floats a store).
#[allow(unsafe_code)]
fn write_copy(dst: &mut [MaybeUninit<f32>], src: &[f32]) {
    assert_eq!(dst.len(), src.len(), "write_copy lengths");
    // SAFETY: `MaybeUninit<f32>` has the layout of `f32`; both slices hold `src.len()`
    // values (asserted) and cannot overlap (one is borrowed mutably).
    unsafe {
        std::ptr::copy_nonoverlapping(src.as_ptr(), dst.as_mut_ptr().cast::<f32>(), src.len())
    }
}

/// [`write_copy`] of `N` values, `N` known to the compiler.
#[allow(unsafe_code)]
fn write_copy_n<const N: usize>(dst: &mut [MaybeUninit<f32>], src: &[f32]) {
    assert!(dst.len() == N && src.len() == N, "write_copy_n lengths");
    // SAFETY: as in `write_copy`, for `N` values (asserted).
    unsafe { std::ptr::copy_nonoverlapping(src.as_ptr(), dst.as_mut_ptr().cast::<f32>(), N) }
}

/// `dst = 0.0` into memory that may be uninitialised (a `memset`).
#[allow(unsafe_code)]
fn write_zeros(dst: &mut [MaybeUninit<f32>]) {
    // SAFETY: the slice is valid for writes of its length; all-zero bits are `0.0f32`.
    unsafe { std::ptr::write_bytes(dst.as_mut_ptr(), 0, dst.len()) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patches_follow_tensorflow_same_padding() {
        // 1 channel, 5 x 5, kernel 3 x 3, stride 2: out 3 x 3; total pad 2 → 1 before.
        let g = ConvGeometry { h: 5, w: 5, c: 1, kh: 3, kw: 3, stride: 2, out_channels: 1 };
        assert_eq!(g.out(), [3, 3]);
        let img: Vec<f32> = (0..25).map(|v| v as f32).collect();
        let mut out = Vec::new();
        g.extract(&img, 1, &mut out);
        assert_eq!(out.len(), 9 * 9);
        // Top-left patch: the padding row and column are 0.
        assert_eq!(&out[0..9], &[0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 5.0, 6.0]);
        // Centre patch (position 4) is centred on pixel (2, 2) = 12.
        assert_eq!(&out[4 * 9..5 * 9], &[6.0, 7.0, 8.0, 11.0, 12.0, 13.0, 16.0, 17.0, 18.0]);
        let paper =
            ConvGeometry { h: 128, w: 160, c: 4, kh: 10, kw: 14, stride: 8, out_channels: 16 };
        assert_eq!((paper.out(), paper.patch_len()), ([16, 20], 560));
        // Appending cuts the same patches after what is there.
        let mut appended = vec![f32::NAN; 3];
        g.extract_append(&img, 1, &mut appended);
        assert_eq!(appended.len(), 3 + out.len());
        assert_eq!(&appended[3..], &out[..]);
    }
}
