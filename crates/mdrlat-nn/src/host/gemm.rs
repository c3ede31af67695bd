//! The one matrix product of the host kernels: the `gemm` crate (the same kernels burn's
//! `flex` backend multiplies with, AVX-512 where the CPU has it), called on dense row-major
//! slices with optional transposes and accumulation.

/// Products of at least this many multiply-adds are split over the current rayon pool's
/// threads by `gemm` itself (its own tiling; each output element is still summed by one
/// thread in one order, so the result does not depend on the thread count).
const PARALLEL_MACS: usize = 1 << 21;

/// One operand of a product: row-major `rows × cols` data, or its transpose stored
/// row-major (`cols × rows`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Mat<'a> {
    data: &'a [f32],
    transposed: bool,
}

impl<'a> Mat<'a> {
    /// The matrix as stored.
    pub(crate) fn n(data: &'a [f32]) -> Self {
        Self { data, transposed: false }
    }

    /// The transpose of the stored matrix.
    pub(crate) fn t(data: &'a [f32]) -> Self {
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
pub(crate) fn gemm(
    m: usize,
    n: usize,
    k: usize,
    a: Mat<'_>,
    b: Mat<'_>,
    c: &mut [f32],
    accumulate: bool,
) {
    assert!(c.len() >= m * n, "gemm: output has {} values, needs {m}x{n}", c.len());
    if k == 0 && !accumulate {
        c[..m * n].fill(0.0);
        return;
    }
    // SAFETY: `c` holds `m × n` values (asserted) and is borrowed mutably, so it overlaps
    // neither input.
    unsafe { product(m, n, k, a, b, c.as_mut_ptr(), accumulate) }
}

/// `a · b` as a new `m × n` row-major matrix. Its memory is written once, by the product
/// (not zeroed first: the gradients of a step are ~44 MB).
///
/// # Panics
/// If a slice is shorter than its matrix.
#[allow(unsafe_code)]
pub(crate) fn gemm_new(m: usize, n: usize, k: usize, a: Mat<'_>, b: Mat<'_>) -> Vec<f32> {
    if m == 0 || n == 0 || k == 0 {
        return vec![0.0; m * n];
    }
    let mut c = Vec::with_capacity(m * n);
    // SAFETY: the capacity holds `m × n` values and overlaps neither input. Without
    // `read_dst` the `gemm` crate never reads the destination: its first pass over the
    // depth dimension stores `lhs · rhs` into every one of the `m × n` elements (alpha is
    // zeroed and the microkernels' "alpha_status 0" path overwrites; `k > 0` here), later
    // passes add to what it stored. So every element is initialised before `set_len`.
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
    let parallelism = if m * n * k >= PARALLEL_MACS && rayon::current_num_threads() > 1 {
        gemm::Parallelism::Rayon(0)
    } else {
        gemm::Parallelism::None
    };
    // SAFETY: the asserts above keep every element the strides reach — `a` (m × k) and
    // `b` (k × n), row-major or transposed as `Mat` says — inside its slice; the caller
    // vouches for `c`.
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

#[cfg(test)]
mod tests {
    use super::*;

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
