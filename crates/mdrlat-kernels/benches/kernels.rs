//! Criterion benches of the host kernels' matrix products at the learner's shapes (batch 32
//! and 64, MDRLAT's widest layers), in FLOP/s (criterion's "elements"), one thread and two:
//! the issue-13 goal is half of `mdrlat bench train`'s reference GEMM rate for a whole step,
//! so these say how far each product is from that. The weight is read either from cache
//! (`hot`: one weight) or from memory (`cold`: 128 MB of weights in turn, as in a step,
//! where every weight is read once per pass).

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group};
use mdrlat_kernels::ConvGeometry;
use mdrlat_kernels::conv::conv_relu;
use mdrlat_kernels::gemm::{
    Conv16, Mat, conv16, conv16_weight_grad, gemm, gemm_short_by_long, gemm_tall,
};
use std::hint::black_box;

/// The allocator `mdrlat` runs with, keeping freed memory as the CLI does: the gradient
/// products return fresh multi-megabyte matrices, which glibc malloc (or a purging mimalloc)
/// would hand back to the OS and fault in again at every call — a cost the learner does not
/// pay.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

#[allow(unsafe_code)]
fn keep_freed_memory() {
    // `mi_option_purge_delay` (see `mdrlat-cli`'s `keep_freed_memory`): -1, never purge.
    const PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;
    // SAFETY: setting an option stores a value in mimalloc's option table; any value is
    // valid for this option and it may be set at any time.
    unsafe { libmimalloc_sys::mi_option_set(PURGE_DELAY, -1) };
}

/// Deterministic values in [-1.5, 1.5].
fn values(len: usize, seed: usize) -> Vec<f32> {
    (0..len).map(|v| ((v * 7 + seed) % 13) as f32 * 0.25 - 1.5).collect()
}

/// Enough copies of a `din × dout` weight to fill 128 MB (at least one).
fn weights(din: usize, dout: usize) -> Vec<Vec<f32>> {
    weights_filling(din, dout, 128)
}

/// Enough copies of a `din × dout` weight to fill `mb` MB (at least one).
fn weights_filling(din: usize, dout: usize, mb: usize) -> Vec<Vec<f32>> {
    let copies = ((mb << 20) / (din * dout * 4)).max(1);
    (0..copies).map(|s| values(din * dout, s)).collect()
}

fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("thread pool")
}

fn forward(c: &mut Criterion) {
    let mut g = c.benchmark_group("linear_forward_flops");
    for (batch, din, dout) in [(32, 4096, 512), (32, 8192, 512), (64, 4096, 512), (32, 1024, 64)] {
        let x = values(batch * din, 1);
        let ws = weights(din, dout);
        let mut y = vec![0.0f32; batch * dout];
        g.throughput(Throughput::Elements((2 * batch * din * dout) as u64));
        for threads in [1, 2] {
            let pool = pool(threads);
            for (temp, cold) in [("hot", false), ("cold", true)] {
                let id = format!("{batch}x{din}->{dout}/{threads}t/{temp}");
                let mut i = 0;
                g.bench_function(BenchmarkId::new("host", &id), |b| {
                    b.iter(|| {
                        i += usize::from(cold);
                        let w = &ws[i % ws.len()];
                        pool.install(|| gemm_short_by_long(batch, dout, din, &x, w, &mut y, true));
                        black_box(y[0]);
                    })
                });
                if threads == 1 {
                    g.bench_function(BenchmarkId::new("gemm_crate", &id), |b| {
                        b.iter(|| {
                            i += usize::from(cold);
                            let w = &ws[i % ws.len()];
                            pool.install(|| {
                                gemm(batch, dout, din, Mat::n(&x), Mat::n(w), &mut y, true)
                            });
                            black_box(y[0]);
                        })
                    });
                }
            }
        }
    }
    g.finish();
}

/// One decision's products (batch 1): the fusion's dense 8192 → 512 layer and a head's
/// 4096 → 512 on a representation of which a share is zero (a ReLU's output), on one
/// thread: mdrlat's kernel (reads only the rows a non-zero input needs) beside the `gemm`
/// crate's vector-matrix path (reads every row). The weights are read in turn from 36 MB,
/// the size of MDRLAT's (`l3`: they stay in a large last-level cache between decisions,
/// as a robot's repeated decisions keep them) or from 128 MB (`mem`).
fn vector_matrix(c: &mut Criterion) {
    let mut g = c.benchmark_group("vector_matrix_bytes");
    let pool = pool(1);
    // (inputs, outputs, share of zero inputs, MB of weights read in turn, zeros scattered
    // at random as a ReLU leaves them rather than evenly)
    for (din, dout, zero_share, mb, scattered) in [
        (8192, 512, 0.0, 36, false),
        (8192, 512, 0.0, 128, false),
        (4096, 512, 0.0, 36, false),
        (4096, 512, 0.6, 36, false),
        (4096, 512, 0.6, 128, false),
        (4096, 512, 0.2, 36, false),
        (4096, 512, 0.4, 36, false),
        (4096, 512, 0.55, 36, true),
        (4096, 512, 0.55, 128, true),
    ] {
        let mut x = values(din, 3);
        for (i, v) in x.iter_mut().enumerate() {
            let zero = if scattered {
                // A multiplicative hash of the index: zeros in runs and gaps of every length.
                ((i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40) % 100
                    < (zero_share * 100.0) as u64
            } else {
                // Every row whose index falls in the zero share of each 10.
                ((i * 7) % 10) < (zero_share * 10.0) as usize
            };
            if zero {
                *v = 0.0;
            }
        }
        let ws = weights_filling(din, dout, mb);
        let mut y = vec![0.0f32; dout];
        g.throughput(Throughput::Bytes((din * dout * 4) as u64));
        let temp = if mb < 64 { "l3" } else { "mem" };
        let spread = if scattered { "scattered" } else { "even" };
        let id = format!("{din}->{dout}/zeros{zero_share}-{spread}/{temp}");
        let mut i = 0;
        g.bench_function(BenchmarkId::new("host", &id), |b| {
            b.iter(|| {
                i += 1;
                let w = &ws[i % ws.len()];
                pool.install(|| gemm_short_by_long(1, dout, din, &x, w, &mut y, true));
                black_box(y[0]);
            })
        });
        g.bench_function(BenchmarkId::new("gemm_crate", &id), |b| {
            b.iter(|| {
                i += 1;
                let w = &ws[i % ws.len()];
                pool.install(|| gemm(1, dout, din, Mat::n(&x), Mat::n(w), &mut y, true));
                black_box(y[0]);
            })
        });
    }
    g.finish();
}

fn backward(c: &mut Criterion) {
    let mut g = c.benchmark_group("linear_backward_flops");
    let (batch, din, dout) = (32, 4096, 512);
    let x = values(batch * din, 1);
    let dy = values(batch * dout, 2);
    let ws = weights(din, dout);
    g.throughput(Throughput::Elements((2 * batch * din * dout) as u64));
    for threads in [1, 2] {
        let pool = pool(threads);
        let id = format!("{batch}x{din}->{dout}/{threads}t");
        g.bench_function(BenchmarkId::new("weight_gradient", &id), |b| {
            b.iter(|| {
                black_box(pool.install(|| gemm_tall(din, dout, batch, Mat::t(&x), Mat::n(&dy))))
            })
        });
        let mut i = 0;
        g.bench_function(BenchmarkId::new("input_gradient_cold", &id), |b| {
            b.iter(|| {
                i += 1;
                let w = &ws[i % ws.len()];
                black_box(pool.install(|| gemm_tall(din, batch, dout, Mat::n(w), Mat::t(&dy))))
            })
        });
    }
    g.finish();
}

/// The first depth convolution on one image (in cache, one thread), forward and weight
/// gradient: the kernel that holds ~64 % of the streams' FLOPs.
fn first_conv(c: &mut Criterion) {
    let mut g = c.benchmark_group("first_conv_flops");
    // The paper's first depth layer on a 4 × 128 × 160 stack, as the learner runs it.
    let geometry =
        ConvGeometry { h: 128, w: 160, c: 4, kh: 10, kw: 14, stride: 8, out_channels: 16 };
    let direct = Conv16::padded(&geometry);
    let image = values(direct.image_len(), 4);
    let wt = values(560 * 16, 5);
    let dy = values(320 * 16, 6);
    let mut out = vec![0.0f32; 320 * 16];
    let mut dwt = vec![0.0f32; 560 * 16];
    if !conv16(&direct, &image, &wt, &mut out, &[]) {
        eprintln!("first_conv_flops: no AVX-512 on this CPU, skipped");
        return;
    }
    g.throughput(Throughput::Elements(direct.flop() as u64));
    g.bench_function("forward", |b| {
        b.iter(|| black_box(conv16(&direct, &image, &wt, &mut out, &[])))
    });
    g.bench_function("weight_gradient", |b| {
        b.iter(|| black_box(conv16_weight_grad(&direct, &image, &dy, &mut dwt, &[])))
    });
    g.finish();
}

/// The depth stream's second and third convolutions (im2col and the patch product with its
/// ReLU) on a batch of 32, one thread and two.
fn later_convs(c: &mut Criterion) {
    let mut g = c.benchmark_group("later_conv_flops");
    // [h, w, c, kh, kw, stride, out]: the paper's conv2 (16×20×16 → 8×10×32, 4×4 stride 2)
    // and conv3 (8×10×32 → 8×10×32, 3×3).
    let layers: [(&str, [usize; 7]); 2] =
        [("conv2", [16, 20, 16, 4, 4, 2, 32]), ("conv3", [8, 10, 32, 3, 3, 1, 32])];
    for (name, geo) in layers {
        let [h, w, ch, kh, kw, stride, out] = geo;
        let geometry = ConvGeometry { h, w, c: ch, kh, kw, stride, out_channels: out };
        let batch = 32;
        let positions = h.div_ceil(stride) * w.div_ceil(stride);
        let k = kh * kw * ch;
        let x = values(batch * h * w * ch, 7);
        let w = values(out * k, 8);
        let wt = mdrlat_kernels::transposed(&w, out);
        let bias = values(out, 9);
        let mut cols = Vec::new();
        g.throughput(Throughput::Elements((2 * batch * positions * k * out) as u64));
        for threads in [1, 2] {
            let pool = pool(threads);
            g.bench_function(BenchmarkId::new(name, format!("b{batch}/{threads}t")), |b| {
                b.iter(|| {
                    black_box(
                        pool.install(|| {
                            conv_relu(&geometry, &x, batch, (&w, &wt), &bias, &mut cols)
                        }),
                    )
                })
            });
        }
    }
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = forward, vector_matrix, backward, first_conv, later_convs
}
fn main() {
    keep_freed_memory();
    benches();
    Criterion::default().configure_from_args().final_summary();
}
