// Deterministic reductions, and the helpers the fused solver kernels share.
//
// A reducing kernel writes a pair of contributions per pixel (per spectral bin), summed over
// the NC channels inside the work-item, into two planes of n reals (real2 stores stop PoCL's
// vectoriser). `sum16` then
// folds it with a fixed pattern, out[i] = sum_k in[i + k m] (k = 0..FOLD-1, m = ceil(n/FOLD)), until
// at most REDUCE_HOST pairs are left, and the host sums those in float64 (numpy's pairwise
// sum of a fixed-length array). Every addition happens in an order fixed by n alone, so the
// results are bit-for-bit repeatable and independent of timing and work-group scheduling.
// (A work-group tree in local memory was 100x slower on PoCL's CPU device: barriers stop its
// vectoriser. Each fold here is one element per work-item over contiguous streams.)
//
// twist_combine, on TwIST's hot path, sums RROWS rows per work-item before writing: RROWS
// times fewer contributions to write and fold (at 2048^2 it wrote three planes of 16 MB, more
// than its own output; 5.9 -> 3.7 ms with 2 rows). RROWS is a compile-time constant dividing
// the row count (the backend picks 2 or 1), so the row loop unrolls without a bounds test.
// Measured and not adopted: 4 rows (no faster), blocking the spectral kernels (slower,
// 1.6 -> 2.0-2.3 ms: their contributions are one half-size plane), blocking admm_update
// (4 rows spilled registers, 9.6 ms; with 2 rows PoCL ran it at 5 ms in some processes and
// 35-98 ms in others on the solver's data, where the one-row kernel is a steady 8 ms).
//
// The backend concatenates common.cl + reduce.cl + the program that uses the helpers.
#ifndef RROWS
#define RROWS 1
#endif

// Batches of frames. F independent frames of one camera run as the launch's third dimension
// (frame f = get_global_id(2); 0 in the one-frame 2-D launches, so these kernels are the
// one-frame kernels too). Frame f's arrays start f NC W H reals into an image array and
// f NC Hs Ws complex values into a spectrum; its contributions start f KP planes of the
// launch's work-items into contrib, KP being the number of planes the kernel writes, so that
// sum16 folds the F frames' planes as F KP consecutive planes. fpar holds FPAR reals per
// frame: factors of the kernel's penalty (rho), second penalty (mu) and shrink threshold
// (thr) arguments, and 1 while the frame runs, 0 once it has stopped (its kernels then return
// at once: a stopped frame costs the launch, not the arithmetic).
#define FPAR 4
#define FPAR_RHO 0
#define FPAR_MU 1
#define FPAR_THR 2
#define FPAR_ACTIVE 3

inline size_t frame_image(const int W, const int H)
{
    return get_global_id(2) * (size_t)NC * W * H;
}

inline size_t frame_spectrum(const int Ws, const int Hs)  // in reals (interleaved complex)
{
    return get_global_id(2) * (size_t)2 * NC * Ws * Hs;
}

inline size_t frame_contrib(const int planes)
{
    return get_global_id(2) * (size_t)planes * get_global_size(0) * get_global_size(1);
}

inline __global const real *frame_par(__global const real *fpar)
{
    return fpar + get_global_id(2) * FPAR;
}

// FOLD: the fold's factor, 16 (CPU devices) or 64 (GPUs: a 512^2 image's contributions fold
// to the host's few thousand in one launch instead of two; each launch is the cost there). The
// kernel keeps its name sum16 for the CPU's pattern.
#ifndef FOLD
#define FOLD 16
#endif

// s = sum over k < FOLD of in[i + k m] (the terms past n read as 0), in that order. A macro, not
// an inline function: PoCL's work-group vectoriser sees an un-inlined call and gives the loop up
// (tests/test_pocl_remarks.py)
#define FOLD_AT(s, in, i, m, n)                                   \
    do {                                                          \
        s = (real)0;                                              \
        _Pragma("unroll")                                         \
        for (int k = 0; k < FOLD; ++k) {                          \
            const int j_ = (i) + k * (m);                         \
            s += j_ < (n) ? (in)[j_] : (real)0;                   \
        }                                                         \
    } while (0)

__kernel void sum16(__global const real *in, __global real *out, const int m, const int n)
{
    // two planes (the two sums of a pair): plane q reads in[q n ..], writes out[q m ..]
    const int i = get_global_id(0), q = get_global_id(1);
    if (i >= m) return;
    real s;
    FOLD_AT(s, in + q * n, i, m, n);
    out[q * m + i] = s;
}

// Two folds in one launch (the backend's deferred folds of two reductions read together, one
// launch instead of two): planes 0..p0-1 fold in0 (m0, n0) as sum16 does, the next ones in1
// (m1, n1). Each plane's additions are sum16's, in its order: the same bits.
__kernel void sum16x2(__global const real *in0, __global real *out0, const int m0, const int n0,
                      __global const real *in1, __global real *out1, const int m1, const int n1,
                      const int p0)
{
    const int i = get_global_id(0), q0 = get_global_id(1);
    const int second = q0 >= p0;
    const int q = second ? q0 - p0 : q0, m = second ? m1 : m0, n = second ? n1 : n0;
    __global const real *in = second ? in1 : in0;
    __global real *out = second ? out1 : out0;
    if (i >= m) return;
    real s;
    FOLD_AT(s, in + q * n, i, m, n);
    out[q * m + i] = s;
}

// Circular (periodic) backward differences, the TV value Phi of the objective (docs/design.md s.2):
// dx = x - roll(x, 1, axis=-1), dy = x - roll(x, 1, axis=-2), summed over NC channels inside the
// square root (vectorial TV for NC > 1).
// Neighbours at affine addresses: left_per along x, and along y a row offset that is uniform
// over a row (a select between two addresses, yi > 0 ? a[i - W] : a[i + (H - 1) W], made PoCL's
// vectoriser emit gathers: twist_combine at 2048^2 ~7 -> ~4.6 ms; docs/design.md s.6).

inline real tv_circ_at(__global const real *x, const int xi, const int yi, const int W,
                       const int H)
{
    const int up = yi > 0 ? -W : (H - 1) * W;  // uniform over a row (no gather)
    real s = (real)0;
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        const real v = x[i];
        const real dx = v - left_per(x, i, xi, W, v);
        const real dy = v - x[i + up];
        s += dx * dx + dy * dy;
    }
    return SQRT(s);
}

// contributions to (sum a*b, 0)
__kernel void dot_contrib(__global const real *a, __global const real *b,
                           __global real *contrib, const int W, const int H)
{
    a += frame_image(W, H);
    b += frame_image(W, H);
    contrib += frame_contrib(2);
    const int xi = get_global_id(0), yi = get_global_id(1);
    real acc_x = (real)0, acc_y = (real)0;
    if (xi < W) {
        for (int c = 0; c < NC; ++c) {
            const int i = c * W * H + yi * W + xi;
            acc_x += a[i] * b[i];
        }
    }
    if (xi < W) {
        contrib[yi * W + xi] = acc_x;
        contrib[W * H + yi * W + xi] = acc_y;
    }
}

// contributions to (||a - b||^2, ||a||^2): the relative step ||x_k - x_{k-1}|| / ||x_k||.
__kernel void diffnorm_contrib(__global const real *a, __global const real *b,
                                __global real *contrib, const int W,
                                const int H)
{
    a += frame_image(W, H);
    b += frame_image(W, H);
    contrib += frame_contrib(2);
    const int xi = get_global_id(0), yi = get_global_id(1);
    real acc_x = (real)0, acc_y = (real)0;
    if (xi < W) {
        for (int c = 0; c < NC; ++c) {
            const int i = c * W * H + yi * W + xi;
            const real d = a[i] - b[i];
            acc_x += d * d;
            acc_y += a[i] * a[i];
        }
    }
    if (xi < W) {
        contrib[yi * W + xi] = acc_x;
        contrib[W * H + yi * W + xi] = acc_y;
    }
}

// contributions to (Phi(x) circular TV, ||x||_1)
// Launched with exactly (W, H) work-items (_2d_red): no guard, which would mask every access.
__kernel void reg_contrib(__global const real *x, __global real *contrib, const int W, const int H)
{
    x += frame_image(W, H);
    contrib += frame_contrib(2);
    const int xi = get_global_id(0), yi = get_global_id(1);
    const real acc_x = tv_circ_at(x, xi, yi, W, H);
    real acc_y = (real)0;
    for (int c = 0; c < NC; ++c)
        acc_y += FABS(x[c * W * H + yi * W + xi]);
    contrib[yi * W + xi] = acc_x;
    contrib[W * H + yi * W + xi] = acc_y;
}
