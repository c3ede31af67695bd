//! The one matrix product of the kernels: the `gemm` crate (the same kernels burn's
//! `flex` backend multiplies with, AVX-512 where the CPU has it), called on dense row-major
//! slices with optional transposes and accumulation.

use crate::conv::ConvGeometry;

/// Products of at least this many multiply-adds are split over the current rayon pool's
/// threads by `gemm` itself (its own tiling; each output element is still summed by one
/// thread in one order, so the result does not depend on the thread count).
const PARALLEL_MACS: usize = 1 << 21;

thread_local! {
    /// Inside [`on_this_thread`]: every product and patch cut stays on this thread.
    static THIS_THREAD: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f` with the host kernels' products and patch cuts kept on the calling thread, no
/// rayon call among them: from a thread outside a pool, rayon would run them on the global
/// pool (every core) and wait (see `HostNet::on_calling_thread`).
pub fn on_this_thread<R>(f: impl FnOnce() -> R) -> R {
    /// Restores the flag, also when `f` panics.
    struct Restore(bool);
    impl Drop for Restore {
        fn drop(&mut self) {
            THIS_THREAD.set(self.0);
        }
    }
    let _restore = Restore(THIS_THREAD.replace(true));
    f()
}

/// Whether work may be split over the current rayon pool's threads: more than one, and not
/// inside [`on_this_thread`].
pub fn may_split() -> bool {
    !THIS_THREAD.get() && rayon::current_num_threads() > 1
}

/// One operand of a product: row-major `rows × cols` data, or its transpose stored
/// row-major (`cols × rows`).
#[derive(Debug, Clone, Copy)]
pub struct Mat<'a> {
    data: &'a [f32],
    transposed: bool,
}

impl<'a> Mat<'a> {
    /// The matrix as stored.
    pub fn n(data: &'a [f32]) -> Self {
        Self { data, transposed: false }
    }

    /// The transpose of the stored matrix.
    pub fn t(data: &'a [f32]) -> Self {
        Self { data, transposed: true }
    }

    /// Row and column strides of the `rows × cols` matrix this operand stands for.
    fn strides(&self, rows: usize, cols: usize) -> (isize, isize) {
        if self.transposed { (1, rows as isize) } else { (cols as isize, 1) }
    }
}

/// `c = a · b`, or `c += a · b` with `accumulate`: `a` is `m × k`, `b` is `k × n`, `c` is
/// `m × n` row-major.
///
/// # Panics
/// If a slice is shorter than its matrix.
#[allow(unsafe_code)]
pub fn gemm(m: usize, n: usize, k: usize, a: Mat<'_>, b: Mat<'_>, c: &mut [f32], accumulate: bool) {
    assert!(c.len() >= m * n, "gemm: output has {} values, needs {m}x{n}", c.len());
    if k == 0 && !accumulate {
        c[..m * n].fill(0.0);
        return;
    }
    // SAFETY: `product` needs `c` valid for writes (and, with `accumulate`, reads) of
    // `m × n` values and disjoint from both inputs: `c` holds at least `m × n` initialised
    // values (asserted above), and as a `&mut` borrow it cannot overlap the shared borrows
    // inside `a` and `b`. `product` checks the inputs' sizes itself.
    unsafe { product(m, n, k, a, b, c.as_mut_ptr(), accumulate) }
}

/// Outputs from which [`gemm_new`] skips zeroing its memory.
const UNINIT_MIN: usize = 1 << 16;

/// `a · b` as a new `m × n` row-major matrix. Its memory is written once, by the product
/// (not zeroed first: the gradients of a step are ~44 MB).
///
/// # Panics
/// If a slice is shorter than its matrix.
#[allow(unsafe_code)]
pub fn gemm_new(m: usize, n: usize, k: usize, a: Mat<'_>, b: Mat<'_>) -> Vec<f32> {
    if m == 0 || n == 0 || k == 0 {
        return vec![0.0; m * n];
    }
    if m == 1 || n == 1 || m * n < UNINIT_MIN {
        // Small, or a vector the `gemm` crate routes to its matrix-vector paths (which view
        // the destination as a slice): zeroed first.
        let mut c = vec![0.0; m * n];
        gemm(m, n, k, a, b, &mut c, false);
        return c;
    }
    let mut c = Vec::with_capacity(m * n);
    // SAFETY: `product`'s contract: the fresh capacity holds `m × n` values and overlaps
    // neither input (it checks the inputs' sizes itself). `set_len`'s: `m × n` fits the
    // capacity, and every element is initialised first, although the memory starts
    // uninitialised, because without `read_dst` the `gemm` crate never reads the
    // destination: it zeroes alpha, its first pass over the depth dimension stores
    // `lhs · rhs` into every one of the `m × n` elements (the microkernels' "alpha_status 0"
    // path, and `gevv` for `k <= 2`, overwrite; `k > 0` here), and later passes add to what
    // it stored (checked in gemm-common 0.19.0, which `=0.19.0` pins: alpha is reset per
    // column block, partial tiles only store). The shapes that read or skip the
    // destination otherwise never get here: the matrix-vector paths (`m` or `n` of 1) and
    // the small `m · n <= 256` path are below `UNINIT_MIN` or excluded above. If `product`
    // panics, the length stays 0.
    unsafe {
        product(m, n, k, a, b, c.as_mut_ptr(), false);
        c.set_len(m * n);
    }
    c
}

/// The `gemm` call behind [`gemm`] and [`gemm_new`].
///
/// # Safety
/// `c` must be valid for writes of `m × n` values (and reads, with `accumulate`), and not
/// overlap `a` or `b`.
#[allow(unsafe_code)]
unsafe fn product(
    m: usize,
    n: usize,
    k: usize,
    a: Mat<'_>,
    b: Mat<'_>,
    c: *mut f32,
    accumulate: bool,
) {
    assert!(a.data.len() >= m * k, "gemm: lhs has {} values, needs {m}x{k}", a.data.len());
    assert!(b.data.len() >= k * n, "gemm: rhs has {} values, needs {k}x{n}", b.data.len());
    if m == 0 || n == 0 {
        return;
    }
    let (a_rs, a_cs) = a.strides(m, k);
    let (b_rs, b_cs) = b.strides(k, n);
    let parallelism = if m * n * k >= PARALLEL_MACS && may_split() {
        gemm::Parallelism::Rayon(0)
    } else {
        gemm::Parallelism::None
    };
    // SAFETY: `a` is read at `i · a_rs + p · a_cs` for `i < m`, `p < k`: `i · k + p`
    // row-major or `i + p · m` transposed, below `m · k` either way, so inside `a.data` by
    // the first assert; `b` likewise below `k · n`, inside `b.data` by the second. The
    // caller vouches for `c` (`m × n` values at row stride `n`, column stride 1, writable,
    // disjoint from `a` and `b`). The `gemm` crate picks its SIMD kernels by run-time
    // feature detection, so no target feature is assumed here.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            c,
            1,
            n as isize,
            accumulate,
            a.data.as_ptr(),
            a_cs,
            a_rs,
            b.data.as_ptr(),
            b_cs,
            b_rs,
            1.0f32,
            1.0f32,
            false,
            false,
            false,
            parallelism,
        );
    }
}

/// Rows of `a` for which [`gemm_short_by_long`] uses its short-by-long kernel: one row (a
/// single decision) has a kernel of its own, and for two the `gemm` crate is faster.
const SHORT_MIN_ROWS: usize = 3;
const SHORT_ROWS: usize = 128;

/// `c = a · b` (or `c += a · b`) for a short `a` (`m × k` row-major: the rows of a batch)
/// and a long row-major weight `b` (`k × n`): the forward product of every linear layer.
/// On CPUs with AVX-512, kernels that stream `b` once, in order (the `gemm` crate first
/// copies the whole weight into panels, which for a batch of 32 costs more memory traffic
/// than the arithmetic): wider than two vectors, `avx512::packed` (the batch rows packed
/// once, each weight strip copied as its first tile reads it); narrower, the in-place
/// kernel. Elsewhere the `gemm` crate.
///
/// # Panics
/// If a slice is shorter than its matrix.
#[allow(unsafe_code)]
pub fn gemm_short_by_long(
    m: usize,
    n: usize,
    k: usize,
    a: &[f32],
    b: &[f32],
    c: &mut [f32],
    accumulate: bool,
) {
    assert!(a.len() >= m * k, "gemm: lhs has {} values, needs {m}x{k}", a.len());
    assert!(b.len() >= k * n, "gemm: rhs has {} values, needs {k}x{n}", b.len());
    assert!(c.len() >= m * n, "gemm: output has {} values, needs {m}x{n}", c.len());
    #[cfg(target_arch = "x86_64")]
    if m == 1 && n.is_multiple_of(16) && n > 0 && k > 2 && avx512::available() {
        // A single decision: the weight is read from memory once, and only its rows the
        // input does not zero (a ReLU zeroes about half of a representation; an input with
        // few zeros has every row read, in one stream). The sums are
        // the `gemm` crate's, whose vector-matrix path this replaces (from a depth of 3:
        // below, that crate multiplies and adds apart).
        if !accumulate {
            c[..n].fill(0.0);
        }
        let mut rows = Vec::with_capacity(k);
        // SAFETY: `vec_mat_nonzero`'s contract: AVX-512F is present and `n` a multiple of
        // 16 (both checked in the condition above); with `m == 1` the asserts at the top
        // give `x` = `a` its `k` values, `w` = `b` its `k` rows of `n` values `n` apart, and
        // `y` = `c` its `n` values. `c` is a `&mut` borrow, so it overlaps neither input.
        unsafe {
            avx512::vec_mat_nonzero(k, n, a.as_ptr(), b.as_ptr(), n, c.as_mut_ptr(), &mut rows)
        };
        return;
    }
    #[cfg(target_arch = "x86_64")]
    if m >= SHORT_MIN_ROWS && (m <= SHORT_ROWS || n <= 16) && n > 0 && k > 0 && avx512::available()
    {
        let out = avx512::SendPtr(c.as_mut_ptr());
        // Wider than two vectors: the rows of `a` packed once, for both threads.
        let rows = (n > 32).then(|| avx512::PackedRows::new(m, k, a));
        // Rows i0..i1 and columns j0..j1 of `c`.
        let run = |(i0, i1): (usize, usize), (j0, j1): (usize, usize)| {
            // SAFETY: AVX-512F is present (checked in the condition above; `PackedRows::new`
            // asserts it again). Bounds: `i0 <= i1 <= m` and `j0 <= j1 <= n` (the splits
            // below cut at a `half` no greater than `m` or `n`), so rows `i0..i1` of `a`
            // (row stride `k`), columns `j0..j1` of `b` and that block of `c` (row stride
            // `n`; the kernels' column masks stop at `j1 - j0`) lie inside the slices the
            // asserts at the top size as `m × k`, `k × n` and `m × n`; `i0` is 0 or a
            // multiple of 16, so `rows.tile(i0)` is the start of a packed tile, followed by
            // the packed tiles (`k` steps each) of every row up to `m`. Aliasing: `c`
            // (through `out`) is touched only here until `run` returns, both `rayon::join`
            // halves below write disjoint blocks of it (columns `..half` / `half..`, or
            // rows), and `a`, `b` and the packed rows are only read.
            unsafe {
                if let Some(rows) = &rows {
                    avx512::packed(
                        rows.tile(i0),
                        i1 - i0,
                        j1 - j0,
                        k,
                        b.as_ptr().add(j0),
                        n,
                        out.get().add(i0 * n + j0),
                        n,
                        accumulate,
                    );
                } else {
                    avx512::short_by_long(
                        i1 - i0,
                        j1 - j0,
                        k,
                        a.as_ptr().add(i0 * k),
                        (k, 1),
                        b.as_ptr().add(j0),
                        n,
                        out.get().add(i0 * n + j0),
                        n,
                        accumulate,
                        avx512::KC,
                        false,
                    );
                }
            }
        };
        let parallel = m * n * k >= PARALLEL_MACS && may_split();
        // Each output element is still summed by one thread in one order.
        if parallel && n >= 2 * avx512::STRIP {
            let half = n.div_ceil(avx512::STRIP).div_ceil(2) * avx512::STRIP;
            rayon::join(|| run((0, m), (0, half)), || run((0, m), (half, n)));
        } else if parallel && m >= 32 {
            let half = m.div_ceil(16).div_ceil(2) * 16;
            rayon::join(|| run((0, half), (0, n)), || run((half, m), (0, n)));
        } else {
            run((0, m), (0, n));
        }
        return;
    }
    gemm(m, n, k, Mat::n(a), Mat::n(b), c, accumulate);
}

/// `a · b` as a new `m × n` row-major matrix, for a tall `a` or a short depth: the weight
/// and input gradients of a linear layer (`xᵀ · dy`, `W · dyᵀ`) and the patch products of
/// the convolutions after the first (forward `P · Wᵀ`, backward `dyᵀ · P` and `dy · W`).
/// On CPUs with AVX-512 the short-by-long kernel, reading `a` in place (row-major or
/// transposed, the latter from L2: its rows alias in L1) and `b` in one block of depth when
/// it is small, so that each register tile streams its rows of `a` once, in order, and,
/// strip by strip, fetching each next tile's rows of `c` for writing while a tile is summed
/// (the output is fresh memory: without that, the stores wait on memory); elsewhere the
/// `gemm` crate.
/// Each element is summed by one thread in one order. With one small block of depth and
/// several strips (the weight gradients `xᵀ · dy`, the convolutions' patch gradients
/// `dy · W`) the tiles go row band by row band, a transposed `a` packed band by band, with
/// no hand-made fetches of `c` (the band is one sequential stream).
///
/// # Panics
/// If a slice is shorter than its matrix.
#[allow(unsafe_code)]
pub fn gemm_tall(m: usize, n: usize, k: usize, a: Mat<'_>, b: Mat<'_>) -> Vec<f32> {
    assert!(a.data.len() >= m * k, "gemm: lhs has {} values, needs {m}x{k}", a.data.len());
    assert!(b.data.len() >= k * n, "gemm: rhs has {} values, needs {k}x{n}", b.data.len());
    #[cfg(target_arch = "x86_64")]
    if m >= 16 && n > 0 && k > 0 && avx512::available() {
        let rhs: std::borrow::Cow<'_, [f32]> = if b.transposed {
            (0..k * n).map(|i| b.data[(i % n) * k + i / n]).collect()
        } else {
            b.data[..k * n].into()
        };
        let (rows, depth) = if a.transposed { (1, m) } else { (k, 1) };
        // One block of depth while the whole of `b` fits in L2 with room to spare.
        let kc = if k * n <= 1 << 14 { k } else { avx512::KC };
        let mut c: Vec<f32> = Vec::with_capacity(m * n);
        let out = avx512::SendPtr(c.as_mut_ptr());
        let run = |i0: usize, i1: usize| {
            // SAFETY: AVX-512F is present (checked in the condition above). `a` is read at
            // row `i0 + i`, depth `p` as `(i0 + i) · rows + p · depth`: `i · k + p`
            // row-major or `i + p · m` transposed, below `m · k` (asserted above) for
            // `i0 + i < i1 <= m`, `p < k`; `rhs` is `k × n` row-major (sliced or built just
            // above); rows `i0..i1` of `c` lie in its capacity of `m × n`. `c` is still
            // uninitialised, but with `accumulate` off the kernel only stores in its first
            // block of depth and later reads back only what it stored. The two
            // `rayon::join` halves below write disjoint rows (`..half`, `half..m`, with
            // `half <= m` as `m >= 16`) through `out`, and `c` itself is not touched until
            // both have returned.
            unsafe {
                avx512::short_by_long(
                    i1 - i0,
                    n,
                    k,
                    a.data.as_ptr().add(i0 * rows),
                    (rows, depth),
                    rhs.as_ptr(),
                    n,
                    out.get().add(i0 * n),
                    n,
                    false,
                    kc,
                    true,
                );
            }
        };
        if m * n * k >= PARALLEL_MACS && may_split() {
            let half = m.div_ceil(2 * 16) * 16;
            rayon::join(|| run(0, half), || run(half, m));
        } else {
            run(0, m);
        }
        // SAFETY: `m × n` fits the capacity reserved above, and every one of those values
        // is initialised: `k > 0` (checked above), so `short_by_long` runs a first block of
        // depth, which with `accumulate` off stores (never loads) every register tile over
        // rows `0..m` (the halves cover `..half` and `half..m`; `tile_rows_at` only picks
        // heights for which `run_tile` has a kernel of that height) and every strip of columns
        // `0..n` (the masks cover the tail strip). Both halves have returned, so no other
        // thread still writes through `out`.
        unsafe { c.set_len(m * n) };
        return c;
    }
    gemm_new(m, n, k, a, b)
}

/// A float rounded to bfloat16 (round to nearest, ties to even): its upper 16 bits.
pub fn to_bf16(x: f32) -> u16 {
    let bits = x.to_bits();
    if x.is_nan() {
        return ((bits >> 16) | 0x40) as u16;
    }
    ((bits + 0x7FFF + ((bits >> 16) & 1)) >> 16) as u16
}

/// A `k × n` weight rounded to bfloat16 (round to nearest, ties to even) for
/// [`Bf16Matrix::vec_mul`], stored in the order the kernel reads it, so that it streams
/// through memory strictly sequentially: groups of four rows (the last padded with zero
/// rows); within a group, blocks of 32 columns; within a block, the four rows' 32 weights
/// one after the other, as 16 words of 32 bits holding columns `(j, j + 16)` — column `j`
/// in the upper half, which clearing the lower half leaves as an f32, column `j + 16` in
/// the lower half, which one shift left makes an f32 (two plain integer operations per 32
/// weights, no shuffle). Columns past `n` hold zeros. On an AMD EPYC Zen 4 core the
/// row-major layout read four rows at a time (four interleaved streams 1 KB apart) made an
/// MDRLAT decision slower than with f32 weights: that CPU's prefetchers follow one
/// sequential stream much better than four interleaved ones.
#[derive(Debug, Clone)]
pub struct Bf16Matrix {
    k: usize,
    n: usize,
    words: Vec<u32>,
}

impl Bf16Matrix {
    /// Columns per block of the stored layout.
    const BLOCK: usize = 32;
    /// Rows per group of the stored layout (the kernel's unroll).
    const GROUP: usize = 4;

    /// `w` (`k × n` row-major) rounded and laid out for the kernel.
    ///
    /// # Panics
    /// If `w` holds fewer than `k · n` values.
    pub fn new(k: usize, n: usize, w: &[f32]) -> Self {
        assert!(w.len() >= k * n, "Bf16Matrix: {} weights for {k}x{n}", w.len());
        let half = Self::BLOCK / 2;
        let (groups, blocks) = (k.div_ceil(Self::GROUP), n.div_ceil(Self::BLOCK));
        let mut words = Vec::with_capacity(groups * blocks * Self::GROUP * half);
        let at =
            |i: usize, j: usize| if i < k && j < n { u32::from(to_bf16(w[i * n + j])) } else { 0 };
        for g in 0..groups {
            for b in 0..blocks {
                for i in g * Self::GROUP..(g + 1) * Self::GROUP {
                    for l in 0..half {
                        let j = b * Self::BLOCK + l;
                        words.push((at(i, j) << 16) | at(i, j + half));
                    }
                }
            }
        }
        Self { k, n, words }
    }

    /// The rounded weight at row `i`, column `j`, widened back to f32.
    #[cfg(test)]
    pub fn get(&self, i: usize, j: usize) -> f32 {
        let (half, blocks) = (Self::BLOCK / 2, self.n.div_ceil(Self::BLOCK));
        let (g, r, b, l) = (i / Self::GROUP, i % Self::GROUP, j / Self::BLOCK, j % Self::BLOCK);
        let word = self.words[((g * blocks + b) * Self::GROUP + r) * half + l % half];
        f32::from_bits(if l < half { word & 0xFFFF_0000 } else { word << 16 })
    }

    /// `y += x · w` for one row `x` (`k`), summed in f32: the weight is widened to f32 as it
    /// is read, so only the weight is rounded. Half the bytes of an f32 weight: the single
    /// decision on the robot is a pass over every weight, bound by memory. `false` (nothing
    /// done) where the CPU lacks AVX-512.
    ///
    /// # Panics
    /// If `x` or `y` is shorter than `k` or `n`.
    #[allow(unsafe_code)]
    pub fn vec_mul(&self, x: &[f32], y: &mut [f32]) -> bool {
        assert!(x.len() >= self.k && y.len() >= self.n, "Bf16Matrix::vec_mul: short slices");
        #[cfg(target_arch = "x86_64")]
        if avx512::available() {
            // SAFETY: AVX-512F is present (`avx512::available()` just above); `x` and `y`
            // hold at least `k` and `n` values (asserted above); `words` holds exactly the
            // layout's `k.div_ceil(4) · n.div_ceil(32) · 64` words, as `new` built it for
            // this `k` and `n` (the fields are private and never changed after). `y` is a
            // `&mut` borrow, disjoint from `x` and `words`.
            unsafe {
                avx512::vec_by_bf16(self.k, self.n, x.as_ptr(), self.words.as_ptr(), y.as_mut_ptr())
            };
            return true;
        }
        false
    }
}

/// Whether `MDRLAT_PORTABLE_KERNELS=1` asks for the portable kernels on a CPU that has
/// AVX-512 (the `gemm` crate's paths and the plain loops): CI runs the network tests once
/// so, and the branches a machine with AVX-512 never takes are tested there too.
pub fn portable_forced() -> bool {
    std::env::var_os("MDRLAT_PORTABLE_KERNELS").is_some_and(|v| v == "1")
}

/// Whether [`Bf16Matrix::vec_mul`] has its kernel on this CPU.
pub fn bf16_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        avx512::available()
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Geometry of [`conv16`]: a zero-padded `[channels, rows, cols]` image, a `kh × kw`
/// kernel at `stride`, and `out_rows × out_cols` outputs.
#[derive(Debug, Clone, Copy)]
pub struct Conv16 {
    /// Image channels.
    pub channels: usize,
    /// Rows of the zero-padded image.
    pub rows: usize,
    /// Columns of the zero-padded image.
    pub cols: usize,
    /// Kernel rows.
    pub kh: usize,
    /// Kernel columns.
    pub kw: usize,
    /// Stride (both axes).
    pub stride: usize,
    /// Output rows.
    pub out_rows: usize,
    /// Output columns.
    pub out_cols: usize,
}

impl Conv16 {
    /// The direct kernel's geometry for a SAME convolution `g` on channel-first images
    /// zero-padded on every side: `(out - 1) · stride + k` rows and columns, the padding
    /// before as [`ConvGeometry::pad_before`] (the caller pads; see its `pad_before`).
    pub fn padded(g: &ConvGeometry) -> Self {
        let [oh, ow] = g.out();
        Conv16 {
            channels: g.c,
            rows: (oh - 1) * g.stride + g.kh,
            cols: (ow - 1) * g.stride + g.kw,
            kh: g.kh,
            kw: g.kw,
            stride: g.stride,
            out_rows: oh,
            out_cols: ow,
        }
    }

    /// The channel-first `image` of `g` zero-padded into `padded` as this geometry reads it
    /// (made [`Conv16::padded`] from `g`); `false` where the padding does not take that form
    /// (the caller cuts patches instead). The border stays zero from the buffer's first use:
    /// only the interior is written.
    pub fn pad(&self, g: &ConvGeometry, image: &[f32], padded: &mut Vec<f32>) -> bool {
        let [pt, pl] = g.pad_before();
        let (h, w) = (g.h, g.w);
        if pt + h > self.rows || pl + w > self.cols || image.len() != g.c * h * w {
            return false;
        }
        let len = self.image_len();
        if padded.len() != len {
            padded.clear();
            padded.resize(len, 0.0);
        }
        for (ch, plane) in image.chunks_exact(h * w).enumerate() {
            for (iy, src) in plane.chunks_exact(w).enumerate() {
                let at = (ch * self.rows + pt + iy) * self.cols + pl;
                padded[at..at + w].copy_from_slice(src);
            }
        }
        true
    }

    /// Floats of one zero-padded image.
    pub fn image_len(&self) -> usize {
        self.channels * self.rows * self.cols
    }

    /// FLOPs of the convolution on one image (and of its weight gradient).
    pub fn flop(&self) -> usize {
        2 * self.out_rows * self.out_cols * self.channels * self.kh * self.kw * 16
    }
}

/// A convolution with 16 filters straight from a zero-padded image, no patches:
/// `out[y·out_cols + x, 0..16] += Σ img[ch][y·s + ky][x·s + kx] · wt[(ch·kh + ky)·kw + kx,
/// 0..16]` (`wt` is the weight transposed, one 16-float vector per kernel value). `false`
/// (nothing done) where the CPU lacks AVX-512: the caller cuts patches instead.
///
/// `next` (may be empty) is fetched into L2 a few lines per step while this image is
/// convolved: the caller's next image, whose first read from memory would otherwise stall
/// the copy that pads it.
///
/// # Panics
/// If the kernel does not fit the padded image or a slice is short.
#[allow(unsafe_code)]
pub fn conv16(g: &Conv16, img: &[f32], wt: &[f32], out: &mut [f32], next: &[f32]) -> bool {
    assert!(
        g.out_rows > 0 && g.out_cols > 0 && g.stride > 0 && g.kh > 0 && g.kw > 0 && g.channels > 0,
        "conv16 geometry"
    );
    assert!((g.out_rows - 1) * g.stride + g.kh <= g.rows, "conv16: kernel rows leave the image");
    assert!((g.out_cols - 1) * g.stride + g.kw <= g.cols, "conv16: kernel columns leave the image");
    assert!(img.len() >= g.channels * g.rows * g.cols, "conv16 image size");
    assert_eq!(wt.len(), g.channels * g.kh * g.kw * 16, "conv16 weight size");
    assert_eq!(out.len(), g.out_rows * g.out_cols * 16, "conv16 output size");
    #[cfg(target_arch = "x86_64")]
    if avx512::available() {
        // SAFETY: AVX-512F is present (`avx512::available()` just above), and the asserts
        // above are the kernel's geometry contract: a non-empty geometry whose last window
        // (`(out_rows - 1) · stride + kh` rows, `(out_cols - 1) · stride + kw` columns)
        // fits the `rows × cols` image, `img` holding `channels × rows × cols` values, `wt`
        // one 16-float vector per kernel value and `out` one per output position. So every
        // pixel, weight and output the kernel reaches is inside its slice. `out` is a
        // `&mut` borrow, disjoint from `img` and `wt`; `next` is only prefetched.
        unsafe { avx512::conv16(g, img.as_ptr(), wt.as_ptr(), out.as_mut_ptr(), next) };
        return true;
    }
    false
}

/// The weight gradient of [`conv16`], added into `dwt` (its transposed layout, one
/// 16-float vector per kernel value): `dwt[(ch·kh + ky)·kw + kx, 0..16] += Σ_{y,x}
/// img[ch][y·s + ky][x·s + kx] · dy[y·out_cols + x, 0..16]`, each sum over the output
/// positions in order. No patches: the first depth layer's patches are 320 × 560 floats an
/// image (700 KB), which the `gemm` crate then packs again. `false` (nothing done) where the
/// CPU lacks AVX-512.
///
/// `next` (may be empty) is fetched into L2 meanwhile, as in [`conv16`].
///
/// # Panics
/// As [`conv16`].
#[allow(unsafe_code)]
pub fn conv16_weight_grad(
    g: &Conv16,
    img: &[f32],
    dy: &[f32],
    dwt: &mut [f32],
    next: &[f32],
) -> bool {
    assert!(
        g.out_rows > 0 && g.out_cols > 0 && g.stride > 0 && g.kh > 0 && g.kw > 0 && g.channels > 0,
        "conv16 geometry"
    );
    assert!((g.out_rows - 1) * g.stride + g.kh <= g.rows, "conv16: kernel rows leave the image");
    assert!((g.out_cols - 1) * g.stride + g.kw <= g.cols, "conv16: kernel columns leave the image");
    assert!(img.len() >= g.channels * g.rows * g.cols, "conv16 image size");
    assert_eq!(dwt.len(), g.channels * g.kh * g.kw * 16, "conv16 weight size");
    assert_eq!(dy.len(), g.out_rows * g.out_cols * 16, "conv16 output size");
    #[cfg(target_arch = "x86_64")]
    if avx512::available() {
        // SAFETY: AVX-512F is present (`avx512::available()` just above), and the asserts
        // above are the kernel's geometry contract, as in `conv16`: the last window fits
        // the image, `img` holds `channels × rows × cols` values, `dy` one 16-float vector
        // per output position and `dwt` one per kernel value, so every pixel, output
        // gradient and weight gradient the kernel reaches is inside its slice. `dwt` is a
        // `&mut` borrow, disjoint from `img` and `dy`; `next` is only prefetched.
        unsafe {
            avx512::conv16_weight_grad(g, img.as_ptr(), dy.as_ptr(), dwt.as_mut_ptr(), next);
        };
        return true;
    }
    false
}

#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod avx512 {
    //! The short-by-long products on AVX-512: [`packed`] for the forward products, and
    //! [`short_by_long`], reading its operands in place, for the rest. Both keep 8 rows ×
    //! 48 columns of `c` in 24 registers (fewer rows, more or fewer columns at the edges)
    //! and read the weight row by row in blocks of depth. What follows is the in-place one,
    //! in blocks of `KC` rows. While a block is multiplied, the
    //! next block (its rows of this call's columns) is fetched into L2 a few lines per
    //! step of the register tiles, and each strip's successor within the block into L1.
    //! Without the L2 stream the kernel waits on memory: a strip's rows lie one weight row
    //! apart, three cache lines each, which the hardware prefetchers do not follow.
    use std::arch::x86_64::*;

    /// A register tile's sums (`rows`: an iterator over its rows of vectors) added to
    /// (`t.add`) or stored into `c`: row `r`, vector `v` at `t.c + r · t.ldc + 16 v` under
    /// `t.masks[v]` (nothing where a mask is empty). A macro, not a function: a function
    /// would take the accumulators' address and keep them in memory through the tile's loop.
    macro_rules! store {
        ($rows:expr, $t:expr) => {
            for (r, acc) in $rows.enumerate() {
                let cp = $t.c.wrapping_add(r * $t.ldc);
                for (v, &sum) in acc.iter().enumerate() {
                    let mask = $t.masks[v];
                    if mask == 0 {
                        continue;
                    }
                    // In bounds: the tile's rows of `c` exist, and a set mask means this
                    // vector's first column does.
                    let at = cp.wrapping_add(16 * v);
                    let value = if $t.add {
                        // SAFETY: AVX-512F is required by both kernels that expand this
                        // macro (`tile`, `packed_tile`). The masked load reads only the
                        // lanes under `mask` (masked-off lanes are not accessed and cannot
                        // fault): columns of row `r` of the tile, whose rows (`R`, or the
                        // first `t.rows`) and masked columns the kernel's caller guarantees
                        // lie in `c`. With `add` they were initialised before, by the
                        // caller (`accumulate`) or by an earlier block of depth.
                        _mm512_add_ps(unsafe { _mm512_maskz_loadu_ps(mask, at) }, sum)
                    } else {
                        sum
                    };
                    // SAFETY: as for the load: the store writes only the lanes under `mask`,
                    // in row `r` of the tile's block of `c`, which the caller guarantees is
                    // in bounds, disjoint from `a` and `b`, and written by no other thread.
                    unsafe { _mm512_mask_storeu_ps(at, mask, value) };
                }
            }
        };
    }

    /// Columns of `c` per register tile (three 16-float vectors).
    pub(super) const STRIP: usize = 48;
    /// Rows of `c` per register tile.
    const ROWS: usize = 8;
    /// Weight rows per block (128 rows × 48 floats: 24 KB of a strip, kept in L1/L2 while
    /// every row tile of `a` passes over it).
    pub(super) const KC: usize = 128;

    /// A pointer the two halves of a product may share (they write disjoint columns or
    /// rows).
    #[derive(Clone, Copy)]
    pub(super) struct SendPtr(pub(super) *mut f32);

    impl SendPtr {
        /// The pointer (a method, so that closures capture the whole `Sync` wrapper).
        pub(super) fn get(self) -> *mut f32 {
            self.0
        }
    }
    // SAFETY: a `SendPtr` only carries an address; every access through it is an unsafe
    // kernel call in `gemm_short_by_long` or `gemm_tall`, where it points into an output
    // (a `&mut [f32]`, or a `Vec`'s reserved capacity) that nothing else touches until the
    // `rayon::join` sharing it has returned, and whose two halves write disjoint blocks
    // (columns or rows) of it. Moving it to another thread therefore races with nothing.
    unsafe impl Send for SendPtr {}
    // SAFETY: a `&SendPtr` only lets a thread copy the address out (`get`); the writes
    // through that address are disjoint between the threads, as argued for `Send` above.
    unsafe impl Sync for SendPtr {}

    /// AVX-512F is there and the portable kernels are not forced (see
    /// [`super::portable_forced`]); decided once per process.
    pub(super) fn available() -> bool {
        static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
        *ON.get_or_init(|| {
            std::arch::is_x86_feature_detected!("avx512f") && !super::portable_forced()
        })
    }

    fn mask(n: usize) -> u16 {
        if n >= 16 { u16::MAX } else { ((1u32 << n) - 1) as u16 }
    }

    /// `y (n) += x (k) · w (k × n bfloat16 in the layout of [`super::Bf16Matrix`])`. The
    /// weight is streamed once, sequentially; each pair of column vectors of `y` is updated
    /// in L1 once per four rows. (The same loop over f32 weights was measured slower than
    /// the `gemm` crate's vector-matrix path for an MDRLAT decision: f32 keeps that.)
    ///
    /// # Safety
    /// AVX-512F must be available; `x` must hold `k` floats, `y` `n`, and `w` the layout's
    /// `k.div_ceil(4) · n.div_ceil(32) · 64` words.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn vec_by_bf16(
        k: usize,
        n: usize,
        x: *const f32,
        w: *const u32,
        y: *mut f32,
    ) {
        let blocks = n.div_ceil(32);
        let high = _mm512_set1_epi32(0xFFFF_0000_u32 as i32);
        let mut w = w;
        for g in 0..k.div_ceil(4) {
            let i = g * 4;
            let xv: [__m512; 4] = std::array::from_fn(|r| {
                // SAFETY: `x` is read only at `i + r < k`, inside the `k` floats the caller
                // guarantees (the padded rows past `k` get 0.0, beside their zero weights).
                _mm512_set1_ps(if i + r < k { unsafe { *x.add(i + r) } } else { 0.0 })
            });
            for b in 0..blocks {
                let j = b * 32;
                let (lo, hi) = (mask(n - j), mask(n.saturating_sub(j + 16)));
                // SAFETY: the CPU has AVX-512F (this function's contract). `j < n` (as
                // `b < n.div_ceil(32)`), so `y.add(j)` is inside `y`, and the masks `lo`
                // and `hi` keep every lane loaded or stored below column `n`, inside the `n`
                // floats the caller guarantees. `w` is at block `b` of group `g`: 4 rows of
                // 16 words, read as `w.add(r · 16)` for `r < 4`; it advances by those 64
                // words per block, `k.div_ceil(4) · blocks` times in all, which is the
                // layout's size the caller guarantees (ending one past its end). Where
                // `n - j < 16`, `hi` is empty and nothing is accessed at `j + 16`; that
                // pointer may lie past `y`'s `n` floats, so it is formed with
                // `wrapping_add`, which (unlike `add`) allows it.
                unsafe {
                    let y_hi = y.wrapping_add(j + 16);
                    let mut acc_lo = _mm512_maskz_loadu_ps(lo, y.add(j));
                    let mut acc_hi = _mm512_maskz_loadu_ps(hi, y_hi);
                    for (r, xr) in xv.iter().enumerate() {
                        let v = _mm512_loadu_si512(w.add(r * 16).cast());
                        let first = _mm512_castsi512_ps(_mm512_and_si512(v, high));
                        let second = _mm512_castsi512_ps(_mm512_slli_epi32(v, 16));
                        acc_lo = _mm512_fmadd_ps(*xr, first, acc_lo);
                        acc_hi = _mm512_fmadd_ps(*xr, second, acc_hi);
                    }
                    _mm512_mask_storeu_ps(y.add(j), lo, acc_lo);
                    _mm512_mask_storeu_ps(y_hi, hi, acc_hi);
                    w = w.add(64);
                }
            }
        }
    }

    /// `y (n) += x (k) · w (k × n, row stride ldw)` reading only the rows of `w` whose
    /// value of `x` is not zero, four rows at a time: each element of `y` is summed in the
    /// order of the rows, one fused multiply-add a row, as the `gemm` crate's vector-matrix
    /// path sums it (that path also adds the zero rows' `0 · w`, which for finite weights
    /// changes no sum but the sign of an exact zero; a non-finite weight in a skipped row
    /// no longer turns its outputs into NaN). `rows` is scratch for the rows read. Each group's weight
    /// rows are fetched while the group two before it is summed: the rows a ReLU leaves are
    /// scattered, 2 KB streams each, too short for the hardware prefetchers to follow. They
    /// are fetched into L2, not L1 (`_MM_HINT_T2`): on Zen 4 that was the faster of the two
    /// with the weights out of cache (criterion, `zeros0.55-scattered/mem`), and for
    /// `mdrlat ros`'s MDRLAT decisions spaced apart in time (back to back, within the noise;
    /// not measured on the Xeon).
    ///
    /// Where at least [`DENSE_SHARE`] of `x` is non-zero (the bilinear fusion's `vec(d lᵀ)`
    /// has no zeros) every row is read instead, one after another ([`add_row`]; its
    /// zero rows add `0 · w` as the `gemm` crate's do, non-finite weights included): on
    /// Zen 4 a single sequential stream is what its prefetchers follow, and both the gaps
    /// of skipped rows and rows read side by side (four or two) are slower than one row at
    /// a time (criterion, `vector_matrix_bytes`; a 4096 → 512 layer breaks even between
    /// skipping and reading every row at 30–40 % zeros).
    ///
    /// # Safety
    /// AVX-512F must be available; `n` must be a multiple of 16; `x` must hold `k` floats,
    /// `y` `n`, and `w` `k` rows of `n` floats `ldw` apart.
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn vec_mat_nonzero(
        k: usize,
        n: usize,
        x: *const f32,
        w: *const f32,
        ldw: usize,
        y: *mut f32,
        rows: &mut Vec<usize>,
    ) {
        debug_assert!(n.is_multiple_of(16));
        // Groups between the one summed and the one fetched (1 and 2 measured the same).
        const AHEAD: usize = 2;
        rows.clear();
        // The non-zero inputs of each 16 (NaN counts as non-zero: it must reach `y`).
        let nonzero = |at: usize| {
            // SAFETY: the CPU has AVX-512F (this function's contract); `at` is only ever a
            // step of `(0..k).step_by(16)`, so `at < k`, `x.add(at)` is inside the `k`
            // floats the caller guarantees, and `mask(k - at)` keeps every lane read below
            // `k`.
            let v = unsafe { _mm512_maskz_loadu_ps(mask(k - at), x.add(at)) };
            _mm512_cmp_ps_mask::<_CMP_NEQ_UQ>(v, _mm512_setzero_ps())
        };
        let count: u32 = (0..k).step_by(16).map(|at| nonzero(at).count_ones()).sum();
        if count as f32 >= DENSE_SHARE * k as f32 {
            for r in 0..k {
                // SAFETY: `add_row`'s contract, from this function's: AVX-512F, `n` a
                // multiple of 16, and, as `r < k`, `x.add(r)` one of `x`'s `k` floats and
                // `w.add(r · ldw)` the start of row `r` of `w`, `n` floats long; `y` holds
                // `n` floats.
                unsafe { add_row(n, *x.add(r), w.add(r * ldw), y) };
            }
            return;
        }
        for at in (0..k).step_by(16) {
            let mut bits = nonzero(at);
            while bits != 0 {
                rows.push(at + bits.trailing_zeros() as usize);
                bits &= bits - 1;
            }
        }
        let vectors = n / 16;
        // SAFETY: `row` is only called with indices from `rows`, each `at + lane` for a
        // lane set in `nonzero(at)`: its masked-off lanes load as 0.0 and compare equal to
        // zero, so every index is below `k` and `w.add(i · ldw)` starts a row of `w`.
        let row = |i: usize| unsafe { w.add(i * ldw) };
        let groups = rows.chunks(4);
        let count = groups.len();
        for (g, group) in groups.enumerate() {
            let next: &[usize] = if g + AHEAD < count { &rows[(g + AHEAD) * 4..] } else { &[] };
            let next = &next[..next.len().min(4)];
            // SAFETY: the CPU has AVX-512F (this function's contract). Every row index in
            // `group` and `next` is below `k` (see `row`), so `x.add(r)` is inside `x` and
            // `row(r)` starts one of `w`'s rows of `n` floats; `j = 16 v` with
            // `v < n / 16` (`n` a multiple of 16) keeps `j + 16 <= n`, so every full-width
            // load of a row of `w` and load and store of `y` is in bounds (prefetches never
            // fault). A group of fewer than four goes row by row to `add_row`, whose
            // contract is this function's.
            unsafe {
                if let &[r0, r1, r2, r3] = group {
                    let (x0, x1, x2, x3) = (
                        _mm512_set1_ps(*x.add(r0)),
                        _mm512_set1_ps(*x.add(r1)),
                        _mm512_set1_ps(*x.add(r2)),
                        _mm512_set1_ps(*x.add(r3)),
                    );
                    let (w0, w1, w2, w3) = (row(r0), row(r1), row(r2), row(r3));
                    for v in 0..vectors {
                        let j = v * 16;
                        // One line of each next row: a row of n floats is n / 16 lines.
                        for &r in next {
                            _mm_prefetch::<_MM_HINT_T2>(row(r).add(j).cast());
                        }
                        let mut acc = _mm512_loadu_ps(y.add(j));
                        acc = _mm512_fmadd_ps(_mm512_loadu_ps(w0.add(j)), x0, acc);
                        acc = _mm512_fmadd_ps(_mm512_loadu_ps(w1.add(j)), x1, acc);
                        acc = _mm512_fmadd_ps(_mm512_loadu_ps(w2.add(j)), x2, acc);
                        acc = _mm512_fmadd_ps(_mm512_loadu_ps(w3.add(j)), x3, acc);
                        _mm512_storeu_ps(y.add(j), acc);
                    }
                } else {
                    for &r in group {
                        add_row(n, *x.add(r), row(r), y);
                    }
                }
            }
        }
    }

    /// The share of non-zero inputs from which [`vec_mat_nonzero`] reads every row.
    pub(super) const DENSE_SHARE: f32 = 0.75;

    /// `y (n) += xr · w_row (n)`, one fused multiply-add an element (`y` stays in L1): a row
    /// of the `gemm` crate's vector-matrix loop, with its sums. Row after row, that is
    /// [`vec_mat_nonzero`]'s dense path (one sequential stream where the rows are `n` apart).
    ///
    /// # Safety
    /// AVX-512F must be available; `n` must be a multiple of 16; `w_row` and `y` must hold
    /// `n` floats.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn add_row(n: usize, xr: f32, w_row: *const f32, y: *mut f32) {
        let xr = _mm512_set1_ps(xr);
        for j in (0..n).step_by(16) {
            // SAFETY: the CPU has AVX-512F (this function's contract); `j` steps by 16
            // through `0..n` and `n` is a multiple of 16, so `j + 16 <= n` and both 16-float
            // accesses stay inside the `n` floats of `y` and of `w_row`.
            unsafe {
                let acc = _mm512_loadu_ps(y.add(j));
                _mm512_storeu_ps(y.add(j), _mm512_fmadd_ps(_mm512_loadu_ps(w_row.add(j)), xr, acc));
            }
        }
    }

    /// `c (m × n, row stride ldc) (+)= a (m × k, row stride lda) · b (k × n, row stride ldb)`.
    ///
    /// # Safety
    /// AVX-512F must be available; the three matrices must lie in valid memory as given,
    /// and `c` must not overlap the others.
    #[target_feature(enable = "avx512f")]
    #[allow(clippy::too_many_arguments)]
    pub(super) unsafe fn short_by_long(
        m: usize,
        n: usize,
        k: usize,
        a: *const f32,
        (lda, step): (usize, usize),
        b: *const f32,
        ldb: usize,
        c: *mut f32,
        ldc: usize,
        accumulate: bool,
        kc: usize,
        c_ahead: bool,
    ) {
        // Register tiles by the width of `c`: up to 16 columns (the first depth
        // convolution's 16 filters) one vector × 16 rows; up to 32 (a batch, in the
        // transposed input-gradient products) two vectors × 12 rows; else three × 8.
        let vectors = n.div_ceil(16).min(3);
        let (tile_rows, strip) = match vectors {
            1 => (16, 16),
            2 => (12, 32),
            _ => (ROWS, STRIP),
        };
        let wide = vectors > 1;
        let mut pc = 0;
        while pc < k {
            let kk = kc.min(k - pc);
            let add = accumulate || pc > 0;
            let mut ahead = if wide {
                let tiles = n.div_ceil(strip) * m.div_ceil(tile_rows);
                Ahead::new(b.wrapping_add((pc + kk) * ldb), kc.min(k - pc - kk), n, ldb, tiles * kk)
            } else {
                Ahead::none()
            };
            // The whole depth in one block with a small `b` (at most 16,384 values: it stays
            // in L2) and several strips — the linear layers' weight gradients `xᵀ · dy` and the
            // convolutions' patch gradients `dy · W`, both of depth 32: row band by row band,
            // every strip of a band before the next, so that `c` is written as one sequential
            // stream (a band of 8 rows is 8 whole rows), which the L2 streamer fetches ahead
            // for writing; strip by strip, each tile wrote 8 pieces of 192 bytes 2 KB apart.
            // Each element is still summed by one tile in the same order: the same bits.
            if wide && pc == 0 && kk == k && k * n <= 1 << 14 && n > strip {
                // A transposed `a` (`xᵀ`: a band's values of one depth step side by side, the
                // depth steps a whole row of `x` apart, all in one L1 set) is packed band by
                // band, `[depth][rows]`, so that every strip reads it from L1.
                let mut pack = if step == 1 { Vec::new() } else { vec![0.0_f32; tile_rows * kk] };
                let mut ic = 0;
                while ic < m {
                    let rows = tile_rows_at(tile_rows, vectors, m - ic);
                    let (a_band, lda_band, step_band) = if step == 1 {
                        // SAFETY: element `(ic, pc)` of `a` (strides `lda`, `step == 1`),
                        // with `ic < m` and `pc == 0 < k`: in the caller's matrix.
                        (unsafe { a.add(ic * lda + pc) }, lda, 1)
                    } else {
                        for p in 0..kk {
                            for r in 0..rows {
                                // SAFETY: element `(ic + r, pc + p)` of `a`, with
                                // `ic + r < m` (`rows <= m - ic`) and `pc + p < k`.
                                pack[p * rows + r] =
                                    unsafe { *a.add((ic + r) * lda + (pc + p) * step) };
                            }
                        }
                        (pack.as_ptr(), 1, rows)
                    };
                    let mut jc = 0;
                    while jc < n {
                        let masks = strip_masks(strip.min(n - jc));
                        // This band's next strip of `b`, or the first again, to L1. `c` is
                        // not fetched for writing by hand here: the L2 streamer follows the
                        // band, and the explicit fetches cost more than they saved (criterion,
                        // on a Sapphire Rapids core).
                        let b_next = if jc + strip < n { jc + strip } else { 0 };
                        let t = Tile {
                            k: kk,
                            a: a_band,
                            lda: lda_band,
                            step: step_band,
                            // SAFETY: element `(pc, jc)` of `b`, with `pc < k`, `jc < n`.
                            b: unsafe { b.add(pc * ldb + jc) },
                            ldb,
                            // SAFETY: element `(ic, jc)` of `c`, with `ic < m`, `jc < n`.
                            c: unsafe { c.add(ic * ldc + jc) },
                            ldc,
                            masks,
                            add,
                            prefetch: Some(b.wrapping_add(pc * ldb + b_next)),
                            c_next: None,
                        };
                        // SAFETY: `t` meets `tile`'s contract for `rows` (`<= m - ic`) rows
                        // and `vectors` vectors: the band's rows of `a` in place, or packed
                        // in `pack` (`[kk][rows]`: row stride 1, depth stride `rows`; not
                        // touched again until the call returns), `kk` steps from depth `pc`
                        // (`pc + kk <= k`), columns from `jc` of `b` and `c` under masks
                        // cut at `n` for this tile width. AVX-512F and `c` disjoint from
                        // `a` and `b` are this function's contract; `prefetch` is only
                        // prefetched.
                        unsafe { run_tile(vectors, rows, &t, &mut Ahead::none()) };
                        jc += strip;
                    }
                    ic += rows;
                }
                pc += kk;
                continue;
            }
            let mut jc = 0;
            while jc < n {
                let masks = strip_masks(strip.min(n - jc));
                // What the hardware should fetch while this strip is multiplied: the next
                // strip of this block, or the first of the next block.
                let next = if jc + strip < n {
                    b.wrapping_add(pc * ldb + jc + strip)
                } else {
                    b.wrapping_add((pc + kk) * ldb)
                };
                let more = wide && (jc + strip < n || pc + kk < k);
                // One strip and one block (the input gradient `W · dyᵀ`): `b` stays in L2
                // and each tile's rows of `a` are read once, from memory, so the L2
                // prefetcher is handed the next tile's rows instead — 12 weight rows of
                // 2 KB, streams too short for the hardware prefetchers to pick up.
                let stream_a = wide && step == 1 && n <= strip && pc + kk >= k;
                let mut ic = 0;
                while ic < m {
                    let rows = tile_rows_at(tile_rows, vectors, m - ic);
                    if stream_a {
                        let next = tile_rows.min(m - ic - rows);
                        ahead =
                            Ahead::new(a.wrapping_add((ic + rows) * lda + pc), next, kk, lda, kk);
                    }
                    let t = Tile {
                        k: kk,
                        // SAFETY: element `(ic, pc)` of `a` (strides `lda`, `step`), with
                        // `ic < m`, `pc < k`.
                        a: unsafe { a.add(ic * lda + pc * step) },
                        lda,
                        step,
                        // SAFETY: element `(pc, jc)` of `b`, with `pc < k`, `jc < n`.
                        b: unsafe { b.add(pc * ldb + jc) },
                        ldb,
                        // SAFETY: element `(ic, jc)` of `c`, with `ic < m`, `jc < n`.
                        c: unsafe { c.add(ic * ldc + jc) },
                        ldc,
                        masks,
                        add,
                        prefetch: (more && ic == 0).then_some(next),
                        c_next: (c_ahead && ic + rows < m)
                            .then(|| c.wrapping_add((ic + rows) * ldc + jc).cast_const()),
                    };
                    // SAFETY: `t` meets `tile`'s contract for `rows` (`<= m - ic`) rows and
                    // `vectors` vectors: rows from `ic` of `a` in place, `kk` steps from
                    // depth `pc` (`pc + kk <= k`), columns from `jc` of `b` and `c` under
                    // masks cut at `n` for this tile width. AVX-512F and `c` disjoint from
                    // `a` and `b` are this function's contract; `prefetch`, `c_next` and
                    // `ahead` are only prefetched.
                    unsafe { run_tile(vectors, rows, &t, &mut ahead) };
                    ic += rows;
                }
                jc += strip;
            }
            pc += kk;
        }
    }

    /// The column masks of a strip `w` columns wide, one per vector of the register tile.
    fn strip_masks(w: usize) -> [u16; 3] {
        [mask(w), mask(w.saturating_sub(16)), mask(w.saturating_sub(32))]
    }

    /// The rows of the register tile that starts `left` rows before the end of `a`: the
    /// largest of 16, 12, 8, 4, 2, 1 that fits the kind (12 only with two vectors).
    fn tile_rows_at(tile_rows: usize, vectors: usize, left: usize) -> usize {
        [16, 12, 8, 4, 2, 1]
            .into_iter()
            .find(|&r| r <= tile_rows && r <= left && (r != 12 || vectors == 2))
            .unwrap_or(1)
    }

    /// One register tile of [`short_by_long`], `rows` × `vectors` vectors.
    ///
    /// # Safety
    /// As [`tile`] (or [`column`], for one vector) with `R = rows` and `V = vectors`.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn run_tile(vectors: usize, rows: usize, t: &Tile, ahead: &mut Ahead) {
        // SAFETY: each arm's kernel has `V = vectors` (3, 2, or one vector for the rest)
        // and `R = rows`, or, in the fallback arms, `R = 1 <= rows`: it touches no row,
        // column or depth step beyond those the caller guarantees for a `rows × vectors`
        // tile. AVX-512F is this function's contract too.
        unsafe {
            match (vectors, rows) {
                (3, 8) => tile::<8, 3>(t, ahead),
                (3, 4) => tile::<4, 3>(t, ahead),
                (3, 2) => tile::<2, 3>(t, ahead),
                (3, _) => tile::<1, 3>(t, ahead),
                (2, 12) => tile::<12, 2>(t, ahead),
                (2, 8) => tile::<8, 2>(t, ahead),
                (2, 4) => tile::<4, 2>(t, ahead),
                (2, 2) => tile::<2, 2>(t, ahead),
                (2, _) => tile::<1, 2>(t, ahead),
                (_, 16) => column::<16>(t),
                (_, 8) => column::<8>(t),
                (_, 4) => column::<4>(t),
                (_, 2) => column::<2>(t),
                (_, _) => column::<1>(t),
            }
        }
    }

    /// Depth per block of [`packed`]: 128 rows of a 48-wide strip of `b` (24 KB) and of the
    /// packed rows of a batch of 32 (16 KB) stay in L1 together.
    const PKC: usize = 128;

    /// The rows of a row-major `m × k` matrix, packed for [`packed`]: tiles of 8 rows,
    /// each `[k][8]` (the tile's 8 values of one depth step side by side), rows past `m`
    /// as zeros.
    pub(super) struct PackedRows {
        data: Aligned,
        k: usize,
    }

    impl PackedRows {
        /// # Panics
        /// If `a` holds fewer than `m · k` values.
        pub(super) fn new(m: usize, k: usize, a: &[f32]) -> Self {
            assert!(a.len() >= m * k, "PackedRows: {} values for {m}x{k}", a.len());
            assert!(available(), "PackedRows: the kernel needs AVX-512F");
            let tiles = m.div_ceil(ROWS);
            let mut data = Aligned::new(tiles * ROWS * k);
            for t in 0..tiles {
                let rows = ROWS.min(m - t * ROWS);
                // SAFETY: AVX-512F is present (asserted above). `rows = min(8, m - 8t)`, so
                // rows `8t..8t + rows` of `a` are the `rows × k` values from `8t · k`, inside
                // the `m × k` asserted above; tile `t` of `data` is the `k × 8` floats from
                // `8t · k`, inside its `tiles × 8 × k`. `data` is a fresh allocation,
                // disjoint from `a`.
                unsafe {
                    transpose_rows(
                        a.as_ptr().add(t * ROWS * k),
                        rows,
                        k,
                        data.as_mut_ptr().add(t * ROWS * k),
                    );
                }
            }
            Self { data, k }
        }

        /// Row `i`'s value at depth step `p`, as packed.
        #[cfg(test)]
        pub(super) fn get(&self, i: usize, p: usize) -> f32 {
            let at = (i / ROWS) * ROWS * self.k + p * ROWS + i % ROWS;
            self.data.data[at / 16].0[at % 16]
        }

        /// The packed tile that starts at row `i` (a multiple of 8).
        pub(super) fn tile(&self, i: usize) -> *const f32 {
            debug_assert_eq!(i % ROWS, 0, "packed rows start at a tile");
            self.data.as_ptr().wrapping_add(i * self.k)
        }
    }

    /// Up to 8 rows of `k` floats (`src`, row-major) as `[k][8]` at `dst` (missing rows as
    /// zeros): 16 depth steps at a time, the 8 rows loaded as vectors and transposed in
    /// registers (two unpack stages within 128-bit lanes, then two lane shuffles) into 8
    /// vectors of two depth steps each. (Copied one float at a time, the batch rows cost
    /// as much as their multiply-adds in the narrow products: 32 × 64 × 1024.)
    ///
    /// # Safety
    /// AVX-512F must be available; `src` must hold `rows × k` floats (`rows` ≤ 8) and
    /// `dst` `k × 8`.
    #[target_feature(enable = "avx512f")]
    unsafe fn transpose_rows(src: *const f32, rows: usize, k: usize, dst: *mut f32) {
        let mut p0 = 0;
        while p0 < k {
            let kr = (k - p0).min(16);
            let m = mask(kr);
            let r: [__m512; ROWS] = std::array::from_fn(|i| {
                if i < rows {
                    // SAFETY: the CPU has AVX-512F (this function's contract); `i < rows`,
                    // so row `i` of `src` is `k` floats from `i · k`, and `m = mask(kr)`,
                    // `kr = min(16, k - p0)`, keeps the lanes read at columns
                    // `p0..p0 + kr <= k`: inside the `rows × k` the caller guarantees.
                    unsafe { _mm512_maskz_loadu_ps(m, src.add(i * k + p0)) }
                } else {
                    _mm512_setzero_ps()
                }
            });
            let lo = |a, b| _mm512_unpacklo_ps(a, b);
            let hi = |a, b| _mm512_unpackhi_ps(a, b);
            // Per 128-bit lane L (depth steps 4L..4L+4): pairs of rows interleaved.
            let t = [
                lo(r[0], r[1]),
                hi(r[0], r[1]),
                lo(r[2], r[3]),
                hi(r[2], r[3]),
                lo(r[4], r[5]),
                hi(r[4], r[5]),
                lo(r[6], r[7]),
                hi(r[6], r[7]),
            ];
            let pd = |x| _mm512_castps_pd(x);
            let ps = |x| _mm512_castpd_ps(x);
            // u[j] (rows 0–3) and u[4 + j] (rows 4–7): depth step 4L + j in lane L.
            let u = [
                ps(_mm512_unpacklo_pd(pd(t[0]), pd(t[2]))),
                ps(_mm512_unpackhi_pd(pd(t[0]), pd(t[2]))),
                ps(_mm512_unpacklo_pd(pd(t[1]), pd(t[3]))),
                ps(_mm512_unpackhi_pd(pd(t[1]), pd(t[3]))),
                ps(_mm512_unpacklo_pd(pd(t[4]), pd(t[6]))),
                ps(_mm512_unpackhi_pd(pd(t[4]), pd(t[6]))),
                ps(_mm512_unpacklo_pd(pd(t[5]), pd(t[7]))),
                ps(_mm512_unpackhi_pd(pd(t[5]), pd(t[7]))),
            ];
            // out[q]: depth steps 2q and 2q + 1, 8 rows each.
            let mut out = [_mm512_setzero_ps(); 8];
            for j in [0, 2] {
                // Lanes 0–1 and 2–3 of rows 0–3 beside rows 4–7, for steps 4L + j, 4L + j + 1.
                let x0 = _mm512_shuffle_f32x4::<0x44>(u[j], u[4 + j]);
                let x1 = _mm512_shuffle_f32x4::<0x44>(u[j + 1], u[5 + j]);
                let x2 = _mm512_shuffle_f32x4::<0xEE>(u[j], u[4 + j]);
                let x3 = _mm512_shuffle_f32x4::<0xEE>(u[j + 1], u[5 + j]);
                let q = j / 2;
                out[q] = _mm512_shuffle_f32x4::<0x88>(x0, x1);
                out[q + 2] = _mm512_shuffle_f32x4::<0xDD>(x0, x1);
                out[q + 4] = _mm512_shuffle_f32x4::<0x88>(x2, x3);
                out[q + 6] = _mm512_shuffle_f32x4::<0xDD>(x2, x3);
            }
            for (q, &v) in out.iter().enumerate().take(kr.div_ceil(2)) {
                // SAFETY: `q < kr.div_ceil(2)`, so step `p0 + 2q < k` and `at` is inside
                // `dst`'s `k × 8`; the full 16-float store covers steps `p0 + 2q` and
                // `p0 + 2q + 1`, both below `k` when `2q + 1 < kr`, and otherwise the mask
                // `0x00FF` stores only step `p0 + 2q`'s 8 floats.
                unsafe {
                    let at = dst.add((p0 + 2 * q) * ROWS);
                    if 2 * q + 1 < kr {
                        _mm512_storeu_ps(at, v);
                    } else {
                        _mm512_mask_storeu_ps(at, 0x00FF, v);
                    }
                }
            }
            p0 += kr;
        }
    }

    /// `c (m × n, row stride ldc) (+)= a (m × k) · b (k × n, row stride ldb)`, with `a`
    /// packed ([`PackedRows`], from its first tile). Per block of depth, each 48-column
    /// strip of `b` is copied into one contiguous, zero-padded buffer by the strip's first
    /// register tile as it multiplies; the other tiles read the copy. (In place, a strip's
    /// rows lie one weight row apart — 2 KB for 512 columns — and fall in six sets of L1: a
    /// 128-row strip does not stay there between row tiles.) Over the block, the next
    /// block's rows are handed to the L2 prefetcher in address order, which its streamer
    /// follows.
    ///
    /// # Safety
    /// AVX-512F must be available; `a` must hold the packed tiles of `m` rows and `k`
    /// depth steps, `b` and `c` must lie in valid memory as given, and `c` must not overlap
    /// the others.
    #[target_feature(enable = "avx512f")]
    #[allow(clippy::too_many_arguments)]
    pub(super) unsafe fn packed(
        a: *const f32,
        m: usize,
        n: usize,
        k: usize,
        b: *const f32,
        ldb: usize,
        c: *mut f32,
        ldc: usize,
        accumulate: bool,
    ) {
        let tiles = m.div_ceil(ROWS);
        let mut strip = Aligned::new(PKC * STRIP);
        let mut pc = 0;
        while pc < k {
            let kk = PKC.min(k - pc);
            let add = accumulate || pc > 0;
            // The next block, row by row in address order, over this block's groups of
            // four depth steps.
            let groups = n.div_ceil(STRIP) * tiles * (kk / 4);
            let mut ahead =
                Ahead::new(b.wrapping_add((pc + kk) * ldb), PKC.min(k - pc - kk), n, ldb, groups);
            let mut jc = 0;
            while jc < n {
                let masks = strip_masks(STRIP.min(n - jc));
                for t in 0..tiles {
                    let ic = t * ROWS;
                    let tile = PackedTile {
                        k: kk,
                        // SAFETY: tile `t < m.div_ceil(8)` of the packed rows starts at
                        // `8t · k`, and its depth step `pc < k` at `8 pc` within it: inside
                        // the packed tiles of `m` rows and `k` steps the caller guarantees.
                        a: unsafe { a.add(t * ROWS * k + pc * ROWS) },
                        b: strip.as_mut_ptr(),
                        src: b.wrapping_add(pc * ldb + jc),
                        ldb,
                        // SAFETY: element `(ic, jc)` of `c`, with `ic = 8t < m`, `jc < n`.
                        c: unsafe { c.add(ic * ldc + jc) },
                        ldc,
                        rows: ROWS.min(m - ic),
                        masks,
                        add,
                    };
                    // SAFETY: `tile` meets `packed_tile`'s contract: `kk <= PKC` steps of the
                    // tile's packed rows from `tile.a`; `strip`, this call's own buffer of
                    // `PKC × 48` floats, 64-byte aligned (`Aligned`), whose rows `0..kk` the
                    // first row tile (`t == 0`, `FIRST`) writes for this strip and block
                    // before the others read them; with `FIRST`, `src` at row `pc`, column
                    // `jc` of `b`, with `kk` rows of valid columns under `masks` (cut at
                    // `n`); `rows <= m - ic` rows of `c` from row `ic` under the same masks.
                    // AVX-512F and `c` disjoint from `a` and `b` are this function's
                    // contract; `ahead` is only prefetched.
                    unsafe {
                        if t == 0 {
                            packed_tile::<true>(&tile, &mut ahead);
                        } else {
                            packed_tile::<false>(&tile, &mut ahead);
                        }
                    }
                }
                jc += STRIP;
            }
            pc += kk;
        }
    }

    /// One register tile of [`packed`].
    struct PackedTile {
        k: usize,
        /// The tile's rows of `a`, packed: `[k][8]`.
        a: *const f32,
        /// The strip of `b`, packed: `[k][48]` (written by the first tile).
        b: *mut f32,
        /// The strip of `b` in place (read by the first tile), rows `ldb` apart.
        src: *const f32,
        ldb: usize,
        c: *mut f32,
        ldc: usize,
        rows: usize,
        masks: [u16; 3],
        add: bool,
    }

    /// The lines of the next block of a weight — `rows` rows of `cols` columns, one weight
    /// row (`ld` floats) apart — handed to the L2 prefetcher in address order (which its
    /// streamer then follows), an equal share at each of the current block's steps, so that
    /// the whole block is in flight by the end of the current one.
    pub(super) struct Ahead {
        row: *const f32,
        ld: usize,
        line: usize,
        row_lines: usize,
        left: usize,
        per_step: usize,
    }

    impl Ahead {
        /// Over `steps` calls of [`Ahead::issue`].
        pub(super) fn new(
            base: *const f32,
            rows: usize,
            cols: usize,
            ld: usize,
            steps: usize,
        ) -> Self {
            let row_lines = cols.div_ceil(16).max(1);
            let left = rows * row_lines;
            Self { row: base, ld, line: 0, row_lines, left, per_step: left.div_ceil(steps.max(1)) }
        }

        /// Nothing to fetch.
        pub(super) fn none() -> Self {
            Self::new(std::ptr::null(), 0, 0, 0, 1)
        }

        /// The next share of lines.
        #[inline(always)]
        fn issue(&mut self) {
            for _ in 0..self.per_step {
                if self.left == 0 {
                    return;
                }
                let at = self.row.wrapping_add(16 * self.line);
                // SAFETY: `_mm_prefetch` (SSE, in the x86_64 baseline) is a hint: it never
                // faults and accesses no memory architecturally, whatever the address; `at`
                // and `row` are formed with `wrapping_add`, so they may run past the weight
                // (or start from the null of `Ahead::none`) without UB.
                unsafe { _mm_prefetch::<_MM_HINT_T1>(at.cast::<i8>()) };
                self.left -= 1;
                self.line += 1;
                if self.line == self.row_lines {
                    self.line = 0;
                    self.row = self.row.wrapping_add(self.ld);
                }
            }
        }
    }

    /// 8 rows × 48 columns from packed operands (`FIRST`: reading the strip in place and
    /// packing it); the first `rows` rows and the columns under `masks` are added to (or
    /// stored into) `c`.
    ///
    /// # Safety
    /// The CPU must have AVX-512F. `t.a` must be valid for reads of the tile's `t.k × 8`
    /// packed floats (`[k][8]`); `t.b` must be 64-byte aligned and valid for `t.k × 48`
    /// floats, written here with `FIRST` and read otherwise; with `FIRST`, `t.src` must be
    /// valid for reads of the columns under `t.masks` in each of `t.k` rows `t.ldb` apart;
    /// `t.c` must be valid for writes (and, with `t.add`, reads of initialised values) of
    /// the columns under `t.masks` in its first `t.rows` (at most 8) rows, `t.ldc` apart,
    /// accessed by no other thread and overlapping none of the others. `ahead` may point
    /// anywhere (it is only prefetched).
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn packed_tile<const FIRST: bool>(t: &PackedTile, ahead: &mut Ahead) {
        let mut acc = [[_mm512_setzero_ps(); 3]; ROWS];
        let (mut a, mut b, mut src) = (t.a, t.b, t.src);
        macro_rules! step {
            () => {{
                // SAFETY: the CPU has AVX-512F (this function's contract). The loops below
                // run `t.k` steps in all; at step `p < t.k`, `b` is `t.b + 48 p`, row `p`
                // of the strip buffer: in bounds, and 64-byte aligned (the buffer is, and 48
                // floats are 3 lines) as the aligned loads and stores at `b`, `b + 16`,
                // `b + 32` need. `src` (formed with `wrapping_add`) is read only under the
                // strip's masks, in row `p` of the strip the caller vouches for.
                let bv = unsafe {
                    if FIRST {
                        let v = [
                            _mm512_maskz_loadu_ps(t.masks[0], src),
                            _mm512_maskz_loadu_ps(t.masks[1], src.wrapping_add(16)),
                            _mm512_maskz_loadu_ps(t.masks[2], src.wrapping_add(32)),
                        ];
                        _mm512_store_ps(b, v[0]);
                        _mm512_store_ps(b.add(16), v[1]);
                        _mm512_store_ps(b.add(32), v[2]);
                        src = src.wrapping_add(t.ldb);
                        v
                    } else {
                        [_mm512_load_ps(b), _mm512_load_ps(b.add(16)), _mm512_load_ps(b.add(32))]
                    }
                };
                for (r, acc) in acc.iter_mut().enumerate() {
                    // SAFETY: `r < 8`, and `a` is `t.a + 8 p` at step `p < t.k`: inside the
                    // packed `[k][8]`.
                    let x = _mm512_set1_ps(unsafe { *a.add(r) });
                    for (acc, &bv) in acc.iter_mut().zip(&bv) {
                        *acc = _mm512_fmadd_ps(x, bv, *acc);
                    }
                }
                // SAFETY: after step `p < t.k`, `a` is at most `t.k · 8` floats past `t.a`:
                // inside the packed rows, or one past the caller's `[k][8]`.
                a = unsafe { a.add(ROWS) };
                // SAFETY: likewise at most `t.k · 48` floats past `t.b`: inside the strip
                // buffer, or one past its `t.k × 48` floats.
                b = unsafe { b.add(STRIP) };
            }};
        }
        for _ in 0..t.k / 4 {
            ahead.issue();
            step!();
            step!();
            step!();
            step!();
        }
        for _ in 0..t.k % 4 {
            step!();
        }
        store!(acc.iter().take(t.rows), t);
    }

    /// One cache line of floats.
    #[derive(Clone, Copy)]
    #[repr(C, align(64))]
    struct Line([f32; 16]);

    /// A 64-byte-aligned scratch buffer of floats.
    struct Aligned {
        data: Vec<Line>,
    }

    impl Aligned {
        fn new(floats: usize) -> Self {
            Self { data: vec![Line([0.0; 16]); floats.div_ceil(16)] }
        }

        fn as_mut_ptr(&mut self) -> *mut f32 {
            self.data.as_mut_ptr().cast()
        }

        fn as_ptr(&self) -> *const f32 {
            self.data.as_ptr().cast()
        }
    }

    /// `R` rows × one vector of columns (under `masks[0]`).
    ///
    /// # Safety
    /// As [`tile`] with `V = 1`: the CPU must have AVX-512F; `t.masks[0]` must be non-empty;
    /// `t.a` must be valid for reads at `r · t.lda + p · t.step` (`r < R`, `p < t.k`), `t.b`
    /// at the columns under `t.masks[0]` of its rows `p < t.k`, `t.ldb` apart, and `t.c` for
    /// writes (and, with `t.add`, reads of initialised values) at those columns of its rows
    /// `r < R`, `t.ldc` apart, accessed by no other thread and overlapping neither `a` nor
    /// `b`.
    #[target_feature(enable = "avx512f")]
    unsafe fn column<const R: usize>(t: &Tile) {
        let mut acc = [_mm512_setzero_ps(); R];
        for p in 0..t.k {
            // SAFETY: row `p < t.k` of `t.b` starts in bounds (its first column is under
            // the non-empty `masks[0]`), and the masked load reads only the columns under
            // `masks[0]`, which the caller guarantees.
            let bv = unsafe { _mm512_maskz_loadu_ps(t.masks[0], t.b.add(p * t.ldb)) };
            for (r, acc) in acc.iter_mut().enumerate() {
                // SAFETY: element `(r, p)` of `t.a`, with `r < R`, `p < t.k`.
                let x = _mm512_set1_ps(unsafe { *t.a.add(r * t.lda + p * t.step) });
                *acc = _mm512_fmadd_ps(x, bv, *acc);
            }
        }
        for (r, &sum) in acc.iter().enumerate() {
            // SAFETY: row `r < R` of `t.c` starts in bounds (its first column is under the
            // non-empty `masks[0]`).
            let at = unsafe { t.c.add(r * t.ldc) };
            let value = if t.add {
                // SAFETY: the masked load reads only row `r`'s columns under `masks[0]`,
                // which the caller guarantees and, with `add`, initialised before.
                _mm512_add_ps(unsafe { _mm512_maskz_loadu_ps(t.masks[0], at) }, sum)
            } else {
                sum
            };
            // SAFETY: the masked store writes only those columns, which no other thread
            // accesses and which overlap neither `a` nor `b` (the caller's contract).
            unsafe { _mm512_mask_storeu_ps(at, t.masks[0], value) };
        }
    }

    /// [`super::conv16`]: per output row, tiles of up to 16 consecutive output positions,
    /// each with its 16 filters in one register, summed over channels, kernel rows and
    /// kernel columns straight from the image.
    ///
    /// # Safety
    /// AVX-512F must be available and the geometry checked as in [`super::conv16`].
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn conv16(
        g: &super::Conv16,
        img: *const f32,
        wt: *const f32,
        out: *mut f32,
        next: &[f32],
    ) {
        // One share of `next`'s lines per kernel row of each tile (the tiles of the depth
        // layer: one per output row).
        let tiles = g.out_rows * g.out_cols.div_ceil(20);
        let mut ahead =
            Ahead::new(next.as_ptr(), 1, next.len(), next.len(), tiles * g.channels * g.kh);
        let ahead = &mut ahead;
        for y in 0..g.out_rows {
            let mut x = 0;
            while x < g.out_cols {
                // Tiles of 20 positions: the depth layer's whole output row (20 columns) in 20
                // independent sums, where a 16 + 4 split left the 4-wide tile waiting on FMA
                // latency. Same sums.
                let n =
                    [20, 16, 8, 4, 2, 1].into_iter().find(|&r| r <= g.out_cols - x).unwrap_or(1);
                // SAFETY: pixel `(0, y · stride, x · stride)` of the image: `y < out_rows` and
                // `x < out_cols`, and the caller's checks put the last window inside
                // `rows × cols`, so that row and column exist.
                let base = unsafe { img.add(y * g.stride * g.cols + x * g.stride) };
                // SAFETY: output position `y · out_cols + x < out_rows · out_cols`, whose 16
                // floats are inside `out`.
                let o = unsafe { out.add((y * g.out_cols + x) * 16) };
                // The paper's stride (8) as a constant: each tile's pixels are then fixed
                // offsets from one pointer, where a stride known only at run time made the
                // compiler step a pointer from pixel to pixel (16 dependent adds a kernel
                // column). Same sums.
                // SAFETY: `conv16_tile`'s contract: AVX-512F and the checked geometry are
                // this function's; `base` and `o` are output row `y`'s position `x` (above),
                // and the arm's `R = n <= out_cols - x` (it is chosen so), so the tile's
                // positions and windows stay inside `out` and the image; `S = 8` only in the
                // arms where `g.stride == 8`, else 0 (the geometry's stride).
                unsafe {
                    match (n, g.stride) {
                        (20, 8) => conv16_tile::<20, 8>(g, base, wt, o, ahead),
                        (16, 8) => conv16_tile::<16, 8>(g, base, wt, o, ahead),
                        (8, 8) => conv16_tile::<8, 8>(g, base, wt, o, ahead),
                        (4, 8) => conv16_tile::<4, 8>(g, base, wt, o, ahead),
                        (2, 8) => conv16_tile::<2, 8>(g, base, wt, o, ahead),
                        (1, 8) => conv16_tile::<1, 8>(g, base, wt, o, ahead),
                        (20, _) => conv16_tile::<20, 0>(g, base, wt, o, ahead),
                        (16, _) => conv16_tile::<16, 0>(g, base, wt, o, ahead),
                        (8, _) => conv16_tile::<8, 0>(g, base, wt, o, ahead),
                        (4, _) => conv16_tile::<4, 0>(g, base, wt, o, ahead),
                        (2, _) => conv16_tile::<2, 0>(g, base, wt, o, ahead),
                        _ => conv16_tile::<1, 0>(g, base, wt, o, ahead),
                    }
                }
                x += n;
            }
        }
    }

    /// [`super::conv16_weight_grad`]: per kernel row of each channel, the kernel's columns
    /// (up to 16 at a time) in registers, each summing its pixel times the 16 filters'
    /// output gradients over every output position.
    ///
    /// # Safety
    /// AVX-512F must be available and the geometry checked as in
    /// [`super::conv16_weight_grad`].
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn conv16_weight_grad(
        g: &super::Conv16,
        img: *const f32,
        dy: *const f32,
        dwt: *mut f32,
        next: &[f32],
    ) {
        // One share of `next`'s lines per output row of each kernel row's pass.
        let passes = g.channels * g.kh * g.kw.div_ceil(16);
        let mut ahead = Ahead::new(next.as_ptr(), 1, next.len(), next.len(), passes * g.out_rows);
        let ahead = &mut ahead;
        for ch in 0..g.channels {
            for ky in 0..g.kh {
                let mut kx = 0;
                while kx < g.kw {
                    let n = (g.kw - kx).min(16);
                    // SAFETY: pixel `(ch, ky, kx)` of the image: `ch < channels`,
                    // `ky < kh <= rows` and `kx < kw <= cols` (the caller's checks).
                    let base = unsafe { img.add((ch * g.rows + ky) * g.cols + kx) };
                    // SAFETY: kernel value `(ch · kh + ky) · kw + kx`, whose 16 floats are
                    // inside `dwt`.
                    let out = unsafe { dwt.add(((ch * g.kh + ky) * g.kw + kx) * 16) };
                    // SAFETY: `weight_grad_row`'s contract: AVX-512F and the checked
                    // geometry are this function's; `base` and `out` are kernel column `kx`
                    // of kernel row `ky` of channel `ch` (above), and the arm's
                    // `R = n = min(16, kw - kx)` keeps `kx + R <= kw`; `dy` holds every
                    // output position's 16 gradients.
                    unsafe {
                        match n {
                            16 => weight_grad_row::<16>(g, base, dy, out, ahead),
                            15 => weight_grad_row::<15>(g, base, dy, out, ahead),
                            14 => weight_grad_row::<14>(g, base, dy, out, ahead),
                            13 => weight_grad_row::<13>(g, base, dy, out, ahead),
                            12 => weight_grad_row::<12>(g, base, dy, out, ahead),
                            11 => weight_grad_row::<11>(g, base, dy, out, ahead),
                            10 => weight_grad_row::<10>(g, base, dy, out, ahead),
                            9 => weight_grad_row::<9>(g, base, dy, out, ahead),
                            8 => weight_grad_row::<8>(g, base, dy, out, ahead),
                            7 => weight_grad_row::<7>(g, base, dy, out, ahead),
                            6 => weight_grad_row::<6>(g, base, dy, out, ahead),
                            5 => weight_grad_row::<5>(g, base, dy, out, ahead),
                            4 => weight_grad_row::<4>(g, base, dy, out, ahead),
                            3 => weight_grad_row::<3>(g, base, dy, out, ahead),
                            2 => weight_grad_row::<2>(g, base, dy, out, ahead),
                            _ => weight_grad_row::<1>(g, base, dy, out, ahead),
                        }
                    }
                    kx += n;
                }
            }
        }
    }

    /// `R` consecutive kernel columns of one kernel row: `R` vectors of 16 filters.
    ///
    /// # Safety
    /// The CPU must have AVX-512F, and `g` must pass [`super::conv16_weight_grad`]'s checks.
    /// `base` must point at pixel `(ch, ky, kx)` of the `[channels, rows, cols]` image for a
    /// channel `ch < channels`, a kernel row `ky < kh` and a kernel column with
    /// `kx + R <= kw`; `dy` must hold the `out_rows · out_cols` output gradients of 16
    /// floats; `out` must be valid for reads and writes of the `R` weight-gradient vectors
    /// from kernel value `(ch · kh + ky) · kw + kx` (initialised, accessed by no other
    /// thread, overlapping neither the image nor `dy`).
    #[target_feature(enable = "avx512f")]
    unsafe fn weight_grad_row<const R: usize>(
        g: &super::Conv16,
        base: *const f32,
        dy: *const f32,
        out: *mut f32,
        ahead: &mut Ahead,
    ) {
        let mut acc = [_mm512_setzero_ps(); R];
        for y in 0..g.out_rows {
            ahead.issue();
            // SAFETY: image row `ky + y · stride` with `y < out_rows`: at most
            // `(out_rows - 1) · stride + kh - 1 < rows`, by the caller's checks.
            let row = unsafe { base.add(y * g.stride * g.cols) };
            for x in 0..g.out_cols {
                // SAFETY: output position `y · out_cols + x < out_rows · out_cols`: its 16
                // floats are inside `dy`.
                let d = unsafe { _mm512_loadu_ps(dy.add((y * g.out_cols + x) * 16)) };
                // SAFETY: image column `kx + x · stride` with `x < out_cols`: inside the
                // row, as the bound below shows for every `r`.
                let px = unsafe { row.add(x * g.stride) };
                for (r, acc) in acc.iter_mut().enumerate() {
                    // SAFETY: image column `kx + r + x · stride`, with `kx + r < kw` and
                    // `x < out_cols`: at most `(out_cols - 1) · stride + kw - 1 < cols`.
                    let v = _mm512_set1_ps(unsafe { *px.add(r) });
                    *acc = _mm512_fmadd_ps(v, d, *acc);
                }
            }
        }
        for (r, &sum) in acc.iter().enumerate() {
            // SAFETY: kernel column `kx + r < kw`: its 16 floats are inside `out`.
            let at = unsafe { out.add(r * 16) };
            // SAFETY: the 16 initialised floats at `at` (above), which only this call
            // accesses.
            unsafe { _mm512_storeu_ps(at, _mm512_add_ps(_mm512_loadu_ps(at), sum)) };
        }
    }

    /// `R` consecutive output positions of one output row, at stride `S` (0: the
    /// geometry's, known at run time).
    ///
    /// # Safety
    /// The CPU must have AVX-512F, and `g` must pass [`super::conv16`]'s checks. `base` must
    /// point at pixel `(0, y · stride, x · stride)` of the `[channels, rows, cols]` image for
    /// an output row `y < out_rows` and a first position `x` with `x + R <= out_cols`; `wt`
    /// must hold the `channels · kh · kw` weight vectors of 16 floats; `out` must be valid
    /// for reads and writes of the `R` output vectors from position `(y, x)` (initialised,
    /// accessed by no other thread, overlapping neither the image nor `wt`); `S` must be 0
    /// or `g.stride`.
    #[target_feature(enable = "avx512f")]
    unsafe fn conv16_tile<const R: usize, const S: usize>(
        g: &super::Conv16,
        base: *const f32,
        wt: *const f32,
        out: *mut f32,
        ahead: &mut Ahead,
    ) {
        let stride = if S == 0 { g.stride } else { S };
        let mut acc = [_mm512_setzero_ps(); R];
        for ch in 0..g.channels {
            for ky in 0..g.kh {
                ahead.issue();
                // SAFETY: channel `ch < channels`, image row `y · stride + ky` with `ky < kh`:
                // at most `(out_rows - 1) · stride + kh - 1 < rows`, by the caller's checks.
                let row = unsafe { base.add((ch * g.rows + ky) * g.cols) };
                // SAFETY: kernel value `(ch · kh + ky) · kw`, the first of this kernel row's
                // `kw` vectors, inside `wt`.
                let w = unsafe { wt.add((ch * g.kh + ky) * g.kw * 16) };
                for kx in 0..g.kw {
                    // SAFETY: kernel value `(ch · kh + ky) · kw + kx` with `kx < kw`: 16
                    // floats inside `wt`.
                    let wv = unsafe { _mm512_loadu_ps(w.add(kx * 16)) };
                    for (r, acc) in acc.iter_mut().enumerate() {
                        // SAFETY: image column `(x + r) · stride + kx` (`stride` is
                        // `g.stride`, as `S` is 0 or equal to it), with `x + r < out_cols`
                        // and `kx < kw`: at most `(out_cols - 1) · stride + kw - 1 < cols`.
                        let x = _mm512_set1_ps(unsafe { *row.add(r * stride + kx) });
                        *acc = _mm512_fmadd_ps(x, wv, *acc);
                    }
                }
            }
        }
        for (r, &sum) in acc.iter().enumerate() {
            // SAFETY: output position `x + r`, `r < R`: its 16 floats are inside `out`.
            let at = unsafe { out.add(r * 16) };
            // SAFETY: the 16 initialised floats at `at` (above), which only this call
            // accesses.
            unsafe { _mm512_storeu_ps(at, _mm512_add_ps(_mm512_loadu_ps(at), sum)) };
        }
    }

    /// One register tile's operands.
    struct Tile {
        k: usize,
        a: *const f32,
        /// Strides of `a` from row to row and from depth to depth.
        lda: usize,
        step: usize,
        b: *const f32,
        ldb: usize,
        c: *mut f32,
        ldc: usize,
        masks: [u16; 3],
        add: bool,
        prefetch: Option<*const f32>,
        /// The next tile's block of `c`, to fetch for writing while this one is summed.
        c_next: Option<*const f32>,
    }

    /// `R` rows × `V` vectors of columns: `k` rank-1 updates in registers, then added to
    /// (or stored into) `c` under the column masks.
    ///
    /// # Safety
    /// The CPU must have AVX-512F; `t.masks[0]` must be non-empty. For `r < R`, `p < t.k`
    /// and the lanes `l` set in `t.masks[v]`, `v < V`: `t.a` must be valid for reads at
    /// `r · t.lda + p · t.step`; `t.b` at `p · t.ldb + 16 v + l`; `t.c` for writes (and,
    /// with `t.add`, reads of initialised values) at `r · t.ldc + 16 v + l`, accessed by no
    /// other thread and overlapping neither `a` nor `b`. `t.prefetch`, `t.c_next` and
    /// `ahead` may point anywhere (they are only prefetched).
    #[target_feature(enable = "avx512f")]
    unsafe fn tile<const R: usize, const V: usize>(t: &Tile, ahead: &mut Ahead) {
        let mut acc = [[_mm512_setzero_ps(); V]; R];
        for p in 0..t.k {
            // SAFETY: row `p < t.k` of `t.b` starts in bounds (its first column is under
            // the non-empty `masks[0]`).
            let bp = unsafe { t.b.add(p * t.ldb) };
            ahead.issue();
            if let Some(cn) = t.c_next
                && p < R * V
            {
                let at = cn.wrapping_add((p / V) * t.ldc + 16 * (p % V));
                _mm_prefetch::<_MM_HINT_ET0>(at.cast::<i8>());
            }
            if let Some(next) = t.prefetch {
                let q = next.wrapping_add(p * t.ldb);
                for v in 0..V {
                    _mm_prefetch::<_MM_HINT_T0>(q.wrapping_add(16 * v).cast::<i8>());
                }
            }
            // A masked-off vector reads nothing; its address may lie past the row's end
            // (a tail strip), so it is computed with `wrapping_add`.
            let mut bv = [_mm512_setzero_ps(); V];
            for (v, b) in bv.iter_mut().enumerate() {
                // SAFETY: the masked load reads only the lanes under `masks[v]`, columns of
                // row `p` of `t.b` that the caller guarantees.
                *b = unsafe { _mm512_maskz_loadu_ps(t.masks[v], bp.wrapping_add(16 * v)) };
            }
            for (r, acc) in acc.iter_mut().enumerate() {
                // SAFETY: element `(r, p)` of `t.a`, with `r < R`, `p < t.k`.
                let x = _mm512_set1_ps(unsafe { *t.a.add(r * t.lda + p * t.step) });
                for (acc, &b) in acc.iter_mut().zip(&bv) {
                    *acc = _mm512_fmadd_ps(x, b, *acc);
                }
            }
        }
        store!(acc.iter(), t);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bf16_rounds_to_nearest_even() {
        assert_eq!(to_bf16(1.0), 0x3F80);
        assert_eq!(to_bf16(-2.5), 0xC020);
        // 1 + 2^-8 lies halfway between 1 and 1 + 2^-7: ties go to the even mantissa (1.0).
        assert_eq!(to_bf16(f32::from_bits(0x3F80_8000)), 0x3F80);
        assert_eq!(to_bf16(f32::from_bits(0x3F81_8000)), 0x3F82);
        assert_eq!(to_bf16(f32::from_bits(0x3F80_8001)), 0x3F81);
        assert!(f32::from_bits(u32::from(to_bf16(f32::NAN)) << 16).is_nan());
    }

    /// Whether the AVX-512 kernels run here. A test of them that cannot run says so, and
    /// fails where `MDRLAT_REQUIRE_AVX512=1` says they must (CI sets it where the CPU has
    /// AVX-512F and the portable kernels are not forced).
    fn avx512_here(test: &str) -> bool {
        if bf16_available() {
            return true;
        }
        let required = std::env::var_os("MDRLAT_REQUIRE_AVX512").is_some_and(|v| v == "1");
        assert!(
            !required,
            "{test}: MDRLAT_REQUIRE_AVX512=1, yet the AVX-512 kernels are off here (no AVX-512F, \
             or MDRLAT_PORTABLE_KERNELS=1)"
        );
        eprintln!("SKIPPED {test}: the AVX-512 kernels are off here");
        false
    }

    /// A direct convolution that declined to run did so exactly where the AVX-512 kernels
    /// are off (see [`avx512_here`]): `ran` is whether it ran.
    fn ran_where_expected(ran: bool, test: &str) -> bool {
        let here = avx512_here(test);
        assert_eq!(ran, here, "{test}: the kernel ran {ran}, the AVX-512 kernels are on: {here}");
        ran
    }

    /// The bfloat16 vector-matrix kernel against the definition (weights rounded, widened
    /// back to f32, sums in f64) on row counts around its unroll of 4 and column tails
    /// around its blocks of 32.
    #[test]
    fn bf16_vec_mul_matches_the_definition() {
        if !avx512_here("bf16_vec_mul_matches_the_definition") {
            return;
        }
        for (k, n) in [(1, 1), (3, 6), (4, 10), (5, 16), (7, 17), (6, 33), (100, 300), (257, 512)] {
            let x: Vec<f32> = (0..k).map(|v| ((v * 7) % 13) as f32 * 0.25 - 1.5).collect();
            let w: Vec<f32> = (0..k * n).map(|v| ((v * 5) % 11) as f32 * 0.13 - 0.6).collect();
            let m = Bf16Matrix::new(k, n, &w);
            let mut y: Vec<f32> = (0..n + 5).map(|j| j as f32 * 0.5).collect();
            let mut want: Vec<f64> = y.iter().map(|&v| f64::from(v)).collect();
            for i in 0..k {
                for (j, out) in want.iter_mut().enumerate().take(n) {
                    let wij = f32::from_bits(u32::from(to_bf16(w[i * n + j])) << 16);
                    assert_eq!(m.get(i, j).to_bits(), wij.to_bits(), "k {k} n {n} ({i}, {j})");
                    *out += f64::from(x[i]) * f64::from(wij);
                }
            }
            assert!(m.vec_mul(&x, &mut y));
            for (j, (got, want)) in y.iter().zip(&want).enumerate() {
                let err = (f64::from(*got) - want).abs();
                assert!(
                    err <= 1e-4 * want.abs().max(1.0),
                    "k {k} n {n} column {j}: {got} vs {want}"
                );
            }
        }
    }

    /// The batch rows' in-register transpose against the rows themselves: partial tiles,
    /// depths around its blocks of 16 (odd tails too), zeros past the last row.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn packed_rows_are_the_rows_side_by_side() {
        if !avx512_here("packed_rows_are_the_rows_side_by_side") {
            return;
        }
        for (m, k) in [(1, 1), (3, 17), (8, 16), (9, 33), (13, 37), (32, 130), (5, 2)] {
            let a: Vec<f32> = (0..m * k).map(|v| v as f32 + 0.5).collect();
            let packed = avx512::PackedRows::new(m, k, &a);
            for i in 0..m.div_ceil(8) * 8 {
                for p in 0..k {
                    let want = if i < m { a[i * k + p] } else { 0.0 };
                    assert_eq!(packed.get(i, p), want, "{m}x{k}: row {i}, step {p}");
                }
            }
        }
    }

    /// The short-by-long kernel against the definition on the shapes it meets: every row
    /// count of a register tile, column tails, strips split between threads, depths over a
    /// block, with and without accumulation.
    #[test]
    fn short_by_long_matches_the_definition() {
        for (m, n, k) in [
            (1, 16, 3),
            (3, 17, 5),
            (8, 48, 130),
            (9, 100, 300),
            (32, 512, 257),
            (64, 130, 129),
            (5, 10, 40),
            (320, 16, 560),
            (333, 7, 200),
        ] {
            let a: Vec<f32> = (0..m * k).map(|v| ((v * 7) % 13) as f32 * 0.25 - 1.5).collect();
            let b: Vec<f32> = (0..k * n).map(|v| ((v * 5) % 11) as f32 * 0.125 - 0.6).collect();
            let mut want = vec![0.0f32; m * n];
            for i in 0..m {
                for j in 0..n {
                    want[i * n + j] = (0..k)
                        .map(|p| a[i * k + p] as f64 * b[p * n + j] as f64)
                        .sum::<f64>() as f32;
                }
            }
            let close = |got: &[f32], want: &[f32]| {
                got.iter().zip(want).all(|(x, y)| (x - y).abs() <= 1e-4 * y.abs().max(1.0))
            };
            let mut c = vec![f32::NAN; m * n];
            gemm_short_by_long(m, n, k, &a, &b, &mut c, false);
            assert!(close(&c, &want), "{m}x{n}x{k}");
            gemm_short_by_long(m, n, k, &a, &b, &mut c, true);
            let twice: Vec<f32> = want.iter().map(|v| 2.0 * v).collect();
            assert!(close(&c, &twice), "{m}x{n}x{k} accumulated");
            // Split between two threads: the same bytes as on one.
            let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().expect("pool");
            let mut split = vec![0.0f32; m * n];
            pool.install(|| gemm_short_by_long(m, n, k, &a, &b, &mut split, false));
            let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool");
            let mut single = vec![0.0f32; m * n];
            one.install(|| gemm_short_by_long(m, n, k, &a, &b, &mut single, false));
            assert_eq!(split, single);
        }
    }

    /// Inside `on_this_thread` nothing may split over rayon's threads, even in a pool of
    /// two; the flag is restored afterwards, also after a panic.
    #[test]
    fn on_this_thread_keeps_work_on_the_calling_thread() {
        let two = rayon::ThreadPoolBuilder::new().num_threads(2).build().expect("pool");
        two.install(|| {
            assert!(may_split());
            assert!(!on_this_thread(may_split));
            assert!(on_this_thread(|| on_this_thread(|| true) && !may_split()));
            assert!(may_split());
            let panicked = std::panic::catch_unwind(|| on_this_thread(|| panic!("inside")));
            assert!(panicked.is_err());
            assert!(may_split());
        });
    }

    /// One row (a single decision): the kernel that reads only the rows of non-zero
    /// inputs (or every row, where at least `DENSE_SHARE` of them are non-zero) gives the
    /// `gemm` crate's vector-matrix sums exactly (up to the sign of an exact zero), with a
    /// ReLU's share of zeros (3/7, 2/7: rows skipped), a few (1/7: every row read), none,
    /// or all, over and beside a group of four.
    #[test]
    fn one_row_skips_zero_inputs_and_keeps_the_sums() {
        let same = |got: &[f32], want: &[f32]| {
            got.iter().zip(want).all(|(x, y)| x == y || (x.is_nan() && y.is_nan()))
        };
        for (n, k) in [(16, 1), (16, 2), (16, 3), (64, 1024), (128, 2560), (512, 4097), (512, 8192)]
        {
            for zero_every in [0, 2, 3, 7, 1] {
                let mut a: Vec<f32> = (0..k)
                    .map(|p| {
                        let v = ((p * 7) % 13) as f32 * 0.37 - 2.1;
                        if zero_every > 0 && (p * 5) % 7 < 7 / zero_every { 0.0 } else { v }
                    })
                    .collect();
                // A NaN input must reach every output, as in the `gemm` crate's sums.
                if (zero_every == 3 || zero_every == 7) && k > 100 {
                    a[k / 2] = f32::NAN;
                }
                let b: Vec<f32> = (0..k * n).map(|v| ((v * 5) % 11) as f32 * 0.113 - 0.6).collect();
                for accumulate in [false, true] {
                    let start: Vec<f32> = (0..n).map(|j| j as f32 * 0.01 - 0.07).collect();
                    let (mut got, mut want) = (start.clone(), start);
                    gemm_short_by_long(1, n, k, &a, &b, &mut got, accumulate);
                    gemm(1, n, k, Mat::n(&a), Mat::n(&b), &mut want, accumulate);
                    assert!(same(&got, &want), "1x{n}x{k}, zeros 1/{zero_every}, {accumulate}");
                }
            }
        }
    }

    /// The tall product against the definition: the weight-gradient shape (`a`
    /// transposed), the input-gradient shape (`b` transposed, one or two vectors wide),
    /// depths over a block, row tails; the same bytes on one thread and on two.
    #[test]
    fn tall_products_match_the_definition() {
        for (m, n, k, ta, tb) in [
            (600, 70, 32, true, false),
            (4096, 512, 32, true, false),
            (300, 32, 200, false, true),
            (1030, 32, 512, false, true),
            (41, 17, 5, false, false),
            (100, 5, 512, true, true),
            (64, 48, 700, false, false),
            (17, 1, 3, true, false),
            // Row band by row band (one block of depth, several strips), with tails.
            (45, 100, 24, false, false),
            (45, 100, 24, true, false),
            (21, 200, 7, true, true),
        ] {
            let a: Vec<f32> = (0..m * k).map(|v| ((v * 7) % 13) as f32 * 0.25 - 1.5).collect();
            let b: Vec<f32> = (0..k * n).map(|v| ((v * 5) % 11) as f32 * 0.125 - 0.6).collect();
            let at = |i: usize, p: usize| if ta { a[p * m + i] } else { a[i * k + p] };
            let bt = |p: usize, j: usize| if tb { b[j * k + p] } else { b[p * n + j] };
            let mut want = vec![0.0f32; m * n];
            for i in 0..m {
                for j in 0..n {
                    want[i * n + j] =
                        (0..k).map(|p| at(i, p) as f64 * bt(p, j) as f64).sum::<f64>() as f32;
                }
            }
            let mat = |d, t| if t { Mat::t(d) } else { Mat::n(d) };
            let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool");
            let two = rayon::ThreadPoolBuilder::new().num_threads(2).build().expect("pool");
            let single = one.install(|| gemm_tall(m, n, k, mat(&a, ta), mat(&b, tb)));
            let split = two.install(|| gemm_tall(m, n, k, mat(&a, ta), mat(&b, tb)));
            assert!(
                single.iter().zip(&want).all(|(x, y)| (x - y).abs() <= 1e-4 * y.abs().max(1.0)),
                "{m}x{n}x{k}"
            );
            assert_eq!(single, split, "{m}x{n}x{k} on two threads");
        }
    }

    /// A [`Conv16`] geometry (`channels, kh, kw, stride, out_rows, out_cols`) and an image
    /// for it, for the direct convolution's tests.
    struct ConvCase {
        g: Conv16,
        img: Vec<f32>,
    }

    impl ConvCase {
        fn new(
            (channels, kh, kw, stride, out_rows, out_cols): (
                usize,
                usize,
                usize,
                usize,
                usize,
                usize,
            ),
        ) -> Self {
            let rows = (out_rows - 1) * stride + kh;
            let cols = (out_cols - 1) * stride + kw;
            let g = Conv16 { channels, rows, cols, kh, kw, stride, out_rows, out_cols };
            let img =
                (0..channels * rows * cols).map(|v| ((v * 7) % 13) as f32 * 0.25 - 1.5).collect();
            Self { g, img }
        }

        /// Every term of the convolution's definition: output position `y·out_cols + x`,
        /// kernel value `(ch·kh + ky)·kw + kx`, and the pixel the two meet at.
        fn terms(&self) -> impl Iterator<Item = (usize, usize, f64)> + '_ {
            let g = self.g;
            let kernel = g.channels * g.kh * g.kw;
            (0..g.out_rows * g.out_cols).flat_map(move |p| {
                let (y, x) = (p / g.out_cols, p % g.out_cols);
                (0..kernel).map(move |k| {
                    let (ch, ky, kx) = (k / (g.kh * g.kw), (k / g.kw) % g.kh, k % g.kw);
                    let at = (ch * g.rows + y * g.stride + ky) * g.cols + x * g.stride + kx;
                    (p, k, f64::from(self.img[at]))
                })
            })
        }

        /// `0.5 +` the definition's sums (the kernels add to 0.5, to check they add) of
        /// pixel · `other[·, f]` for the 16 filters `f`: per output position with `other` the
        /// weight (the convolution), or per kernel value with `other` the output gradient
        /// (the weight gradient).
        fn definition(&self, other: &[f32], per_position: bool) -> Vec<f32> {
            let g = &self.g;
            let rows =
                if per_position { g.out_rows * g.out_cols } else { g.channels * g.kh * g.kw };
            let mut sums = vec![0.0f64; rows * 16];
            for (p, k, px) in self.terms() {
                let (row, by) = if per_position { (p, k) } else { (k, p) };
                for f in 0..16 {
                    sums[row * 16 + f] += px * f64::from(other[by * 16 + f]);
                }
            }
            sums.iter().map(|&s| 0.5 + s as f32).collect()
        }

        /// `len` values for the other operand (weights or output gradients).
        fn values(len: usize) -> Vec<f32> {
            (0..len).map(|v| ((v * 5) % 11) as f32 * 0.125 - 0.6).collect()
        }

        /// `got` against `want` (added to 0.5 by both), to 1e-4 relative.
        fn check(&self, got: &[f32], want: &[f32]) {
            let g = &self.g;
            assert!(
                got.iter().zip(want).all(|(x, y)| (x - y).abs() <= 1e-4 * y.abs().max(1.0)),
                "{}x{}x{}/{}",
                g.channels,
                g.kh,
                g.kw,
                g.stride
            );
        }
    }

    /// The direct first-layer convolution against its definition, at the paper's stride
    /// (its constant-stride tiles) and at others, with every tile width (20, 16 to 1) at both.
    #[test]
    fn conv16_matches_the_definition() {
        for shape in [
            (4, 10, 14, 8, 2, 31),
            (2, 3, 5, 2, 3, 23),
            (1, 2, 19, 3, 2, 7),
            (1, 2, 19, 3, 1, 9),
            (2, 3, 5, 8, 1, 16),
            (1, 2, 19, 3, 1, 17),
        ] {
            let c = ConvCase::new(shape);
            let g = c.g;
            let wt = ConvCase::values(g.channels * g.kh * g.kw * 16);
            let want = c.definition(&wt, true);
            let mut got = vec![0.5f32; want.len()];
            let ran = conv16(&g, &c.img, &wt, &mut got, &c.img);
            if ran_where_expected(ran, "conv16_matches_the_definition") {
                c.check(&got, &want);
            }
        }
    }

    /// The direct first-layer convolution's weight gradient against its definition, for
    /// kernels narrower and wider than one register row of 16.
    #[test]
    fn conv16_weight_grad_matches_the_definition() {
        for shape in [(2, 3, 5, 2, 4, 3), (4, 10, 14, 8, 3, 4), (1, 2, 19, 3, 2, 2)] {
            let c = ConvCase::new(shape);
            let g = c.g;
            let dy = ConvCase::values(g.out_rows * g.out_cols * 16);
            let want = c.definition(&dy, false);
            let mut got = vec![0.5f32; want.len()];
            let ran = conv16_weight_grad(&g, &c.img, &dy, &mut got, &c.img);
            if ran_where_expected(ran, "conv16_weight_grad_matches_the_definition") {
                c.check(&got, &want);
            }
        }
    }

    /// Every transpose combination against a naive triple loop, with and without
    /// accumulation.
    #[test]
    fn products_match_the_definition() {
        let (m, n, k) = (5, 7, 3);
        let a: Vec<f32> = (0..m * k).map(|v| v as f32 * 0.5 - 3.0).collect();
        let b: Vec<f32> = (0..k * n).map(|v| (v % 5) as f32 - 1.5).collect();
        let at: Vec<f32> = (0..m * k).map(|i| a[(i % m) * k + i / m]).collect();
        let bt: Vec<f32> = (0..k * n).map(|i| b[(i % k) * n + i / k]).collect();
        let mut want = vec![0.0f32; m * n];
        for i in 0..m {
            for j in 0..n {
                want[i * n + j] = (0..k).map(|p| a[i * k + p] * b[p * n + j]).sum();
            }
        }
        let mut short = vec![1.0f32; m * n];
        gemm_short_by_long(m, n, k, &a, &b, &mut short, false);
        assert!(short.iter().zip(&want).all(|(x, y)| (x - y).abs() <= 1e-5 * y.abs().max(1.0)));
        for (lhs, rhs) in [
            (Mat::n(&a), Mat::n(&b)),
            (Mat::t(&at), Mat::n(&b)),
            (Mat::n(&a), Mat::t(&bt)),
            (Mat::t(&at), Mat::t(&bt)),
        ] {
            assert_eq!(gemm_new(m, n, k, lhs, rhs), want);
            let mut c = vec![1.0f32; m * n];
            gemm(m, n, k, lhs, rhs, &mut c, false);
            assert_eq!(c, want);
            gemm(m, n, k, lhs, rhs, &mut c, true);
            let twice: Vec<f32> = want.iter().map(|v| 2.0 * v).collect();
            assert_eq!(c, twice);
        }
    }
}
