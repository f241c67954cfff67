// Element-wise and fused solver kernels. 1-D kernels run over all n = NC*H*W elements; the
// kernels that also need neighbours (circular TV of their output, ADMM's differences) run on
// (Wpad, H) with one work-item per pixel and a deterministic work-group reduction.
// Needs common.cl and reduce.cl in front (the backend concatenates them).

// Periodic x-neighbours use left_per/right_per of common.cl (no gathers on PoCL).

// a = b + s c: the bandwidth probe ("triad") of the benchmark's machine limit.
__kernel void triad(__global real *a, __global const real *b, __global const real *c,
                    const real s, const int n)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    a[i] = b[i] + s * c[i];
}

// out = a X + b Y + c Z
__kernel void lincomb3(__global real *out, const real a, __global const real *X, const real b,
                       __global const real *Y, const real c, __global const real *Z, const int n)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    out[i] = a * X[i] + b * Y[i] + c * Z[i];
}

inline real soft1(const real v, const real t)
{
    return COPYSIGN(FMAX(FABS(v) - t, (real)0), v);
}

// out = soft(x + s g, t)   (l1 prox; the TwIST default Psi). s = 0 gives soft(x, t).
__kernel void soft_step(__global real *out, __global const real *x, __global const real *g,
                        const real s, const real t, const int n)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    out[i] = soft1(x[i] + s * g[i], t);
}

// out = max(v, 0)
__kernel void project_nonneg(__global real *out, __global const real *v, const int n)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    out[i] = FMAX(v[i], (real)0);
}

// Isotropic (vectorial) shrinkage of a field (t1, t2) of NC channels:
// z = max(|t| - thr, 0) t / |t|, |t|^2 summed over both components and all channels.
__kernel void shrink_vec(__global real *z1, __global real *z2, __global const real *t1,
                         __global const real *t2, const real thr, const int W, const int H)
{
    const int xi = get_global_id(0), yi = get_global_id(1);
    if (xi >= W) return;
    real n2 = (real)0;
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        n2 += t1[i] * t1[i] + t2[i] * t2[i];
    }
    const real nrm = SQRT(n2);
    const real f = nrm > thr ? (real)1 - thr / nrm : (real)0;
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        z1[i] = f * t1[i];
        z2[i] = f * t2[i];
    }
}

// A batch of frames (reduce.cl, above frame_image; TwIST's batch): the frame's arrays and
// contributions; a frame whose FPAR_ACTIVE is 0 (its candidate this round is not a two-step
// one, or it has stopped) returns at once, its output and contributions left as they were.
#define TWIST_FRAME(PLANES)                                                             \
    if (frame_par(fpar)[FPAR_ACTIVE] == (real)0) return;                                \
    {                                                                                   \
        const size_t fo = frame_image(W, H);                                            \
        out += fo;                                                                      \
        xm2 += fo;                                                                      \
        xm1 += fo;                                                                      \
        xist += fo;                                                                     \
        contrib += frame_contrib(PLANES);                                               \
    }

// ---------------------------------------------------------------------------------------------
// TwIST two-step combination (docs/design.md s.2), fused with the objective's regulariser:
//   m = (x_ist != 0) when sparse (the reference's "set to zero the past when the present is
//   zero"), out = (1 - alpha) m x_{t-2} + (alpha - beta) m x_{t-1} + beta x_ist,
//   contributions (Phi(out) circular TV if want_tv else ||out||_1, number of zeros of x_ist,
//   Phi(x_ist) or ||x_ist||_1: the regulariser of the IST estimate, which a monotone fallback
//   needs, from the loads already made).
// Neighbours of `out` for Phi are recomputed from the three inputs (never re-read from out).
// ---------------------------------------------------------------------------------------------
__kernel void twist_combine(__global real *out, __global const real *xm2,
                            __global const real *xm1, __global const real *xist,
                            const real c2, const real c1, const real cb, const int sparse,
                            const int want_tv, __global const real *fpar,
                            __global real *contrib, const int W, const int H)
{
    TWIST_FRAME(3);
    // Branch-free so that PoCL vectorises it: the mask is a select, both regularisers are
    // computed and one is kept. The in-place zeroing of the past iterates is left to
    // `mask_past`, launched by the host only when the second sum (the number of zeros of
    // x_ist) is non-zero. Launched with exactly (W, H / RROWS) work-items: no `xi >= W` guard
    // (it made PoCL mask every load and store); the row above (wrapped) is a row offset,
    // uniform over the row-wide work-group (see reduce.cl). Each work-item sums RROWS rows
    // into one contribution (reduce.cl: RROWS).
    const int xi = get_global_id(0), yb = get_global_id(1);
    real a0 = (real)0, a1 = (real)0, a2 = (real)0;
#pragma unroll
    for (int r = 0; r < RROWS; ++r) {
        const int yi = yb * RROWS + r;
        const int up = yi > 0 ? -W : (H - 1) * W;
        real n2 = (real)0, l1 = (real)0, nz = (real)0, ns = (real)0, ls = (real)0;
        for (int c = 0; c < NC; ++c) {
            const int i0 = c * W * H + yi * W + xi;
            const real s0 = xist[i0], sl = left_per(xist, i0, xi, W, s0);
            const real su = xist[i0 + up];
            const real x2c = xm2[i0], x1c = xm1[i0];
            const real m0 = (sparse && s0 == (real)0) ? (real)0 : (real)1;
            const real ml = (sparse && sl == (real)0) ? (real)0 : (real)1;
            const real mu = (sparse && su == (real)0) ? (real)0 : (real)1;
            const real v = m0 * (c2 * x2c + c1 * x1c) + cb * s0;
            const real vl = ml * (c2 * left_per(xm2, i0, xi, W, x2c)
                                  + c1 * left_per(xm1, i0, xi, W, x1c)) + cb * sl;
            const real vu = mu * (c2 * xm2[i0 + up] + c1 * xm1[i0 + up])
                            + cb * su;
            n2 += (v - vl) * (v - vl) + (v - vu) * (v - vu);
            l1 += FABS(v);
            ns += (s0 - sl) * (s0 - sl) + (s0 - su) * (s0 - su);
            ls += FABS(s0);
            nz += (real)1 - m0;
            out[i0] = v;
        }
        a0 += want_tv ? SQRT(n2) : l1;
        a1 += nz;
        a2 += want_tv ? SQRT(ns) : ls;
    }
    const int m = W * (H / RROWS);
    contrib[yb * W + xi] = a0;
    contrib[m + yb * W + xi] = a1;
    contrib[2 * m + yb * W + xi] = a2;
}

// The reference's "set to zero the past when the present is zero" (TwIST's sparse default):
// x_{t-1} and x_{t-2} are zeroed where x_ist == 0. A batch of frames (launched over all their
// elements, per = NC W H of each): only the frames whose FPAR_ACTIVE is not 0 (one frame:
// per = n, frame 0).
__kernel void mask_past(__global real *xm1, __global real *xm2, __global const real *xist,
                        __global const real *fpar, const int per, const int n)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    const int f = per == n ? 0 : i / per;  // uniform test: no division for one frame
    if (fpar[f * FPAR + FPAR_ACTIVE] == (real)0) return;
    const real m = xist[i] == (real)0 ? (real)0 : (real)1;
    xm1[i] *= m;
    xm2[i] *= m;
}

// FISTA extrapolation of the gradient-step point:  out = a1 W1 + a2 W2, W = X + K^T(y - K X).
// With W affine in X and a1 + a2 = 1, this is y_k + K^T(y - K y_k) for the extrapolated point
// y_k = a1 X1 + a2 X2, without ever applying K to y_k.
// A batch of frames (launched over all their elements, per = NC W H of each): frame f's
// coefficients are a1 coef[2 f] and a2 coef[2 f + 1] (each frame's monotone step decides its
// own; one frame: coef = (1, 1), the arguments themselves).
__kernel void fista_extrap(__global real *out, real a1, __global const real *W1,
                           real a2, __global const real *W2, __global const real *coef,
                           const int per, const int n)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    const int f = per == n ? 0 : i / per;  // uniform test: no division for one frame
    a1 *= coef[2 * f];
    a2 *= coef[2 * f + 1];
    out[i] = a1 * W1[i] + a2 * W2[i];
}

// ---------------------------------------------------------------------------------------------
// ADMM-TV with periodic backward differences D (the differences of Phi).
// rhs = b + rho D^T q + mu (v - s),  D^T q = q1 - q1[x+1] + q2 - q2[y+1]  (wrapped).
// Periodic neighbours: along y the wrapped row is a row offset, along x left_per/right_per
// (top of this file).
// ---------------------------------------------------------------------------------------------
__kernel void admm_rhs(__global real *out, __global const real *b, __global const real *q1,
                       __global const real *q2, __global const real *v, __global const real *s,
                       real rho, real mu, __global const real *fpar, const int W,
                       const int H)
{
    __global const real *p = frame_par(fpar);
    if (p[FPAR_ACTIVE] == (real)0) return;
    rho *= p[FPAR_RHO];
    mu *= p[FPAR_MU];
    const size_t fo = frame_image(W, H);
    out += fo;
    b += fo;
    q1 += fo;
    q2 += fo;
    v += fo;
    s += fo;
    const int xi = get_global_id(0), yi = get_global_id(1);
    if (xi >= W) return;
    const int dn = yi < H - 1 ? W : (1 - H) * W;  // to the row below (wrapped)
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        const real q1c = q1[i];
        real r = b[i] + rho * (q1c - right_per(q1, i, xi, W, q1c) + q2[i] - q2[i + dn]);
        if (mu != (real)0) r += mu * (v[i] - s[i]);
        out[i] = r;
    }
}

// The ADMM split kernels' arguments moved to the work-item's frame of a batch and their
// scalars times the frame's factors (reduce.cl, above frame_image); a stopped frame returns.
#define ADMM_UPDATE_FRAME()                                                                   \
    __global const real *p = frame_par(fpar);                                                 \
    if (p[FPAR_ACTIVE] == (real)0) return;                                                    \
    thr *= p[FPAR_THR];                                                                       \
    const size_t fo = frame_image(W, H);                                                      \
    x += fo; u1 += fo; u2 += fo; q1 += fo; q2 += fo; v += fo; s += fo;                        \
    contrib += frame_contrib(2)
#define ADMM_UPDATE_RHS_FRAME()                                                               \
    __global const real *p = frame_par(fpar);                                                 \
    if (p[FPAR_ACTIVE] == (real)0) return;                                                    \
    thr *= p[FPAR_THR];                                                                       \
    rho *= p[FPAR_RHO];                                                                       \
    mu *= p[FPAR_MU];                                                                         \
    const size_t fo = frame_image(W, H);                                                      \
    x += fo; u1 += fo; u2 += fo; u1n += fo; u2n += fo; v += fo; s += fo; out += fo; b += fo;  \
    contrib += frame_contrib(2)

// The split at pixel (xi, yi), every channel, from the split before this update: the
// differences d = D x, t = D x + u, |d|^2 summed over the channels (nd), and the shrink factor
// f = max(1 - thr / |t|, 0) it returns (z = f t). admm_update and admm_update_rhs share it.
inline real split_at(__global const real *x, __global const real *u1,
                     __global const real *u2, const real thr, const int xi, const int yi,
                     const int W, const int H, real *d1, real *d2, real *t1, real *t2,
                     real *nd)
{
    const int up = yi > 0 ? -W : (H - 1) * W;  // to the row above (wrapped)
    real sd = (real)0, nt = (real)0;
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        const real x0 = x[i];
        d1[c] = x0 - left_per(x, i, xi, W, x0);
        d2[c] = x0 - x[i + up];
        t1[c] = d1[c] + u1[i];
        t2[c] = d2[c] + u2[i];
        sd += d1[c] * d1[c] + d2[c] * d2[c];
        nt += t1[c] * t1[c] + t2[c] * t2[c];
    }
    *nd = sd;
    const real nrm = SQRT(nt);
    return nrm > thr ? (real)1 - thr / nrm : (real)0;
}

// Given the new x: t = D x + u;  z = shrink(t, thr);  u <- t - z;  q = z - u  (the next rhs's
// input); with nonneg: v = max(x + s, 0), s <- s + x - v.
// contributions (TV(x) = sum |D x|, ||D x - z||^2 = primal residual).
__kernel void admm_update(__global const real *x, __global real *u1, __global real *u2,
                          __global real *q1, __global real *q2, __global real *v,
                          __global real *s, real thr, const int nonneg,
                          __global const real *fpar, __global real *contrib, const int W,
                          const int H)
{
    ADMM_UPDATE_FRAME();
    const int xi = get_global_id(0), yi = get_global_id(1);
    real acc_x = (real)0, acc_y = (real)0;
    if (xi < W) {
        real d1[NC], d2[NC], t1[NC], t2[NC], nd;
        const real f = split_at(x, u1, u2, thr, xi, yi, W, H, d1, d2, t1, t2, &nd);
        real pr = (real)0;
        for (int c = 0; c < NC; ++c) {
            const int i = c * W * H + yi * W + xi;
            const real z1 = f * t1[c], z2 = f * t2[c];
            const real w1 = t1[c] - z1, w2 = t2[c] - z2;
            u1[i] = w1;
            u2[i] = w2;
            q1[i] = z1 - w1;
            q2[i] = z2 - w2;
            pr += (d1[c] - z1) * (d1[c] - z1) + (d2[c] - z2) * (d2[c] - z2);
            if (nonneg) {
                const real a = x[i] + s[i];
                const real vv = FMAX(a, (real)0);
                v[i] = vv;
                s[i] = a - vv;
            }
        }
        acc_x = SQRT(nd);
        acc_y = pr;
    }
    if (xi < W) {
        contrib[yi * W + xi] = acc_x;
        contrib[W * H + yi * W + xi] = acc_y;
    }
}

// q = z - u of the split at (row, col), every channel, from the split before this update (x and
// the old u): t = D x + u, z = shrink(t, thr), the new u = t - z, q = z - u, in admm_update's
// arithmetic. admm_update_rhs needs it for the right and lower neighbours, which belong to
// other work-items.
inline void split_q_at(__global const real *x, __global const real *u1,
                       __global const real *u2, const real thr, const int row, const int col,
                       const int W, const int H, real *q1, real *q2)
{
    real d1[NC], d2[NC], t1[NC], t2[NC], nd;
    const real f = split_at(x, u1, u2, thr, col, row, W, H, d1, d2, t1, t2, &nd);
    for (int c = 0; c < NC; ++c) {
        const real z1 = f * t1[c], z2 = f * t2[c];
        q1[c] = z1 - (t1[c] - z1);
        q2[c] = z2 - (t2[c] - z2);
    }
}

// admm_update and then admm_rhs for the next x-update in one launch, one pixel per work-item
// (GPUs, and colour frames on CPU devices; CPU devices with one channel run
// admm_update_rhs16): the rhs needs q one column right and one row down, which other
// work-items own, so each work-item recomputes those two from the old split (split_q_at). The
// new split goes to (u1n, u2n), never in place, so no work-item reads what another writes;
// q is never stored. One launch and 5 arrays read and 5 written (x, u1, u2, s, K^T y; u1n,
// u2n, v, s, rhs) instead of two launches and 16 array passes: on a GPU an ADMM iteration is
// bound by its launches.
__kernel void admm_update_rhs(__global const real *x, __global const real *u1,
                              __global const real *u2, __global real *u1n, __global real *u2n,
                              __global real *v, __global real *s, __global real *out,
                              __global const real *b, real thr, const int nonneg, real rho,
                              real mu, __global const real *fpar, __global real *contrib,
                              const int W, const int H)
{
    ADMM_UPDATE_RHS_FRAME();
    const int xi = get_global_id(0), yi = get_global_id(1);
    if (xi >= W) return;
    real d1[NC], d2[NC], t1[NC], t2[NC], nd;
    const real f = split_at(x, u1, u2, thr, xi, yi, W, H, d1, d2, t1, t2, &nd);
    real q1r[NC], q2r[NC], q1d[NC], q2d[NC];
    split_q_at(x, u1, u2, thr, yi, xi < W - 1 ? xi + 1 : 0, W, H, q1r, q2r);
    split_q_at(x, u1, u2, thr, yi < H - 1 ? yi + 1 : 0, xi, W, H, q1d, q2d);
    real pr = (real)0;
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        const real z1 = f * t1[c], z2 = f * t2[c];
        const real w1 = t1[c] - z1, w2 = t2[c] - z2;
        u1n[i] = w1;
        u2n[i] = w2;
        pr += (d1[c] - z1) * (d1[c] - z1) + (d2[c] - z2) * (d2[c] - z2);
        real vs = (real)0;  // v - s of the updated non-negativity split
        if (nonneg) {
            const real a = x[i] + s[i];
            const real vv = FMAX(a, (real)0);
            v[i] = vv;
            s[i] = a - vv;
            vs = vv - (a - vv);
        } else if (mu != (real)0) {
            vs = v[i] - s[i];
        }
        real r = b[i] + rho * ((z1 - w1) - q1r[c] + (z2 - w2) - q2d[c]);
        if (mu != (real)0) r += mu * vs;
        out[i] = r;
    }
    contrib[yi * W + xi] = SQRT(nd);
    contrib[W * H + yi * W + xi] = pr;
}

#if !defined(REAL_IS_DOUBLE) && NC == 1
// admm_update on CPU devices (float32, one channel): 16 columns of a row per work-item as
// float16 vectors, one pair of contributions per work-item ((ceil(W / 16), H) work-items; the
// last of a row takes W mod 16 columns through a buffer). The one-pixel-per-work-item kernel
// above ran at 10-12 ms at 2048^2 on both PoCL versions (4.5-5.0 ms on Intel's runtime); this
// one 3.0-3.3 ms on both PoCLs and 2.8-3.0 ms on Intel's runtime, with the same results.
// Left neighbours: the vector one column left (a row's first work-item: shifted, lane 0 the
// wrapped last column); the row above is wrapped.

// the 16 columns left of those at x + i (c0: the first's column; n: columns left in the row;
// xv: the columns themselves)
inline float16 left16(__global const float *x, const size_t i, const int c0, const int n,
                      const int W, const float16 xv)
{
    if (c0 > 0)
        return load_upto16(x + i - 1, n + 1);
    float16 xl = SHIFT_RIGHT(xv);
    xl.s0 = x[i + W - 1];
    return xl;
}

// the split's shrink factor: z = f t, f = max(1 - thr / |t|, 0)
inline float16 shrink_factor16(const float16 t1, const float16 t2, const float thr)
{
    const float16 nrm = sqrt16(t1 * t1 + t2 * t2);
    return SEL16((float16)(0.0f), 1.0f - thr / nrm, nrm > (float16)(thr));
}

// a work-item's contributions over its own n columns: TV(x) and ||D x - z||^2
inline void admm_contrib16(__global float *contrib, const float16 d1, const float16 d2,
                           const float16 z1, const float16 z2, const int n, const int H)
{
    const int gx = get_global_id(0), yi = get_global_id(1), gw = get_global_size(0);
    const int16 lane = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const int16 own = lane < (int16)(n);
    const float16 zero = (float16)(0.0f), e1 = d1 - z1, e2 = d2 - z2;
    contrib[yi * gw + gx] = hsum16(SEL16(zero, sqrt16(d1 * d1 + d2 * d2), own));
    contrib[gw * H + yi * gw + gx] = hsum16(SEL16(zero, e1 * e1 + e2 * e2, own));
}

KERNEL_VEC16
void admm_update16(__global const float *x, __global float *u1, __global float *u2,
                   __global float *q1, __global float *q2, __global float *v,
                   __global float *s, float thr, const int nonneg,
                   __global const float *fpar, __global float *contrib, const int W,
                   const int H)
{
    ADMM_UPDATE_FRAME();
    const int gx = get_global_id(0), yi = get_global_id(1);
    const int c0 = gx * 16, n = W - c0;  // n: columns left in the row (>= 16 but in a tail)
    const size_t i = (size_t)yi * W + c0;
    const size_t iu = (size_t)(yi > 0 ? yi - 1 : H - 1) * W + c0;
    const float16 zero = (float16)(0.0f);
    const float16 xv = load_upto16(x + i, n);
    const float16 d1 = xv - left16(x, i, c0, n, W, xv), d2 = xv - load_upto16(x + iu, n);
    const float16 t1 = d1 + load_upto16(u1 + i, n), t2 = d2 + load_upto16(u2 + i, n);
    const float16 f = shrink_factor16(t1, t2, thr);
    const float16 z1 = f * t1, z2 = f * t2;
    const float16 w1 = t1 - z1, w2 = t2 - z2;
    store_upto16(u1 + i, w1, n);
    store_upto16(u2 + i, w2, n);
    store_upto16(q1 + i, z1 - w1, n);
    store_upto16(q2 + i, z2 - w2, n);
    if (nonneg) {
        const float16 a = xv + load_upto16(s + i, n);
        const float16 vv = SEL16(a, zero, a < zero);
        store_upto16(v + i, vv, n);
        store_upto16(s + i, a - vv, n);
    }
    admm_contrib16(contrib, d1, d2, z1, z2, n, H);
}

// TwIST's combination (twist_combine above) on CPU devices, float32, one channel: 16 columns
// of a row per work-item as float16 vectors, as admm_update16 ((ceil(W / 16), H) work-items,
// the left neighbours through left16, the row above wrapped), with three contributions per
// work-item: Phi or ||.||_1 of the combination, the number of zeros of x_ist, Phi or ||.||_1
// of x_ist (the scalar kernel's a0, a1, a2).

// twist_combine's v = m (c2 x2 + c1 x1) + cb s with m = 0 where sparse and s == 0
inline float16 combine16(const float16 x2, const float16 x1, const float16 s, const float c2,
                         const float c1, const float cb, const int sparse)
{
    const float16 past = c2 * x2 + c1 * x1;
    return (sparse ? SEL16(past, (float16)(0.0f), s == (float16)(0.0f)) : past) + cb * s;
}

// the regulariser's contribution of lanes `own`: isotropic TV from the left and upper
// neighbours, or |v|
inline float reg16(const float16 v, const float16 vl, const float16 vu, const int want_tv,
                   const int16 own)
{
    const float16 dl = v - vl, du = v - vu;
    const float16 r = want_tv ? sqrt16(dl * dl + du * du) : SEL16(v, -v, v < (float16)(0.0f));
    return hsum16(SEL16((float16)(0.0f), r, own));
}

KERNEL_VEC16
void twist_combine16(__global float *out, __global const float *xm2,
                     __global const float *xm1, __global const float *xist,
                     const float c2, const float c1, const float cb, const int sparse,
                     const int want_tv, __global const float *fpar, __global float *contrib,
                     const int W, const int H)
{
    TWIST_FRAME(3);
    const int gx = get_global_id(0), yi = get_global_id(1), gw = get_global_size(0);
    const int c0 = gx * 16, n = W - c0;  // n: columns left in the row (>= 16 but in a tail)
    const size_t i = (size_t)yi * W + c0;
    const size_t iu = (size_t)(yi > 0 ? yi - 1 : H - 1) * W + c0;
    const int16 lane = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const int16 own = lane < (int16)(n);
    const float16 x2 = load_upto16(xm2 + i, n), x1 = load_upto16(xm1 + i, n);
    const float16 s = load_upto16(xist + i, n);
    const float16 sl = left16(xist, i, c0, n, W, s), su = load_upto16(xist + iu, n);
    const float16 v = combine16(x2, x1, s, c2, c1, cb, sparse);
    const float16 vl = combine16(left16(xm2, i, c0, n, W, x2), left16(xm1, i, c0, n, W, x1),
                                 sl, c2, c1, cb, sparse);
    const float16 vu = combine16(load_upto16(xm2 + iu, n), load_upto16(xm1 + iu, n), su, c2,
                                 c1, cb, sparse);
    store_upto16(out + i, v, n);
    const size_t m = (size_t)gw * H, k = (size_t)yi * gw + gx;
    contrib[k] = reg16(v, vl, vu, want_tv, own);
    contrib[m + k] = sparse ? hsum16(SEL16((float16)(0.0f), (float16)(1.0f),
                                           own & (s == (float16)(0.0f))))
                            : 0.0f;
    contrib[2 * m + k] = reg16(s, sl, su, want_tv, own);
}

// q1 of one pixel's split: t = D x + u at (row, col), f = max(1 - thr/|t|, 0), z = f t, the new
// u = t - z, q = z - u. Scalar, for the column right of a work-item's last.
inline float split_q1_at(__global const float *x, __global const float *u1,
                         __global const float *u2, const float thr, const int row,
                         const int col, const int W, const int H)
{
    const size_t i = (size_t)row * W + col;
    const float x0 = x[i];
    const float t1 = x0 - x[col > 0 ? i - 1 : i + W - 1] + u1[i];
    const float t2 = x0 - x[(size_t)(row > 0 ? row - 1 : H - 1) * W + col] + u2[i];
    const float nrm = SQRT(t1 * t1 + t2 * t2);
    const float f = nrm > thr ? 1.0f - thr / nrm : 0.0f;
    const float z1 = f * t1, w1 = t1 - z1;  // as admm_update16 forms q
    return z1 - w1;
}

// admm_update16 and then admm_rhs for the next x-update in one pass (CPU devices, float32,
// one channel): the rhs at row y needs q at row y + 1 and one column right, which belong to
// other work-items, so each work-item recomputes them from the old split (q2 for the 16
// columns of the row below, q1 for the column right of its last): the split is read from
// (u1, u2) and written to (u1n, u2n), never in place, so no work-item reads what another
// writes. q is never stored: 5 arrays read (x, u1, u2, s, K^T y) and 5 written (u1n, u2n, v, s,
// out) against 16 passes for the two kernels. Same results as admm_update16 + admm_rhs up to
// rounding (the q recomputed for the neighbours is the same float arithmetic).
KERNEL_VEC16
void admm_update_rhs16(__global const float *x, __global const float *u1,
                       __global const float *u2, __global float *u1n, __global float *u2n,
                       __global float *v, __global float *s, __global float *out,
                       __global const float *b, float thr, const int nonneg,
                       float rho, float mu, __global const float *fpar,
                       __global float *contrib, const int W, const int H)
{
    ADMM_UPDATE_RHS_FRAME();
    const int gx = get_global_id(0), yi = get_global_id(1);
    const int c0 = gx * 16, n = W - c0;  // n: columns left in the row (>= 16 but in a tail)
    const int yd = yi < H - 1 ? yi + 1 : 0;  // the row below (wrapped)
    const size_t i = (size_t)yi * W + c0, id = (size_t)yd * W + c0;
    const size_t iu = (size_t)(yi > 0 ? yi - 1 : H - 1) * W + c0;
    const float16 zero = (float16)(0.0f);
    // this row: the split's update (admm_update16)
    const float16 xv = load_upto16(x + i, n);
    const float16 d1 = xv - left16(x, i, c0, n, W, xv), d2 = xv - load_upto16(x + iu, n);
    const float16 t1 = d1 + load_upto16(u1 + i, n), t2 = d2 + load_upto16(u2 + i, n);
    const float16 f = shrink_factor16(t1, t2, thr);
    const float16 z1 = f * t1, z2 = f * t2;
    const float16 w1 = t1 - z1, w2 = t2 - z2;
    store_upto16(u1n + i, w1, n);
    store_upto16(u2n + i, w2, n);
    const float16 q1 = z1 - w1, q2 = z2 - w2;
    float16 vs = zero;  // v - s of the updated non-negativity split
    if (nonneg) {
        const float16 a = xv + load_upto16(s + i, n);
        const float16 vv = SEL16(a, zero, a < zero);
        store_upto16(v + i, vv, n);
        store_upto16(s + i, a - vv, n);
        vs = vv - (a - vv);
    } else if (mu != 0.0f) {
        vs = load_upto16(v + i, n) - load_upto16(s + i, n);
    }
    // the row below: q2 only (its split is another work-item's to store)
    const float16 xd = load_upto16(x + id, n);
    const float16 t1d = xd - left16(x, id, c0, n, W, xd) + load_upto16(u1 + id, n);
    const float16 t2d = xd - xv + load_upto16(u2 + id, n);
    const float16 z2d = shrink_factor16(t1d, t2d, thr) * t2d, q2d = z2d - (t2d - z2d);
    // the column right of the last (wrapped past the row's end), into the last own lane
    const float q1r = split_q1_at(x, u1, u2, thr, yi, c0 + 16 < W ? c0 + 16 : 0, W, H);
    const int16 lane = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const float16 q1right = SEL16(SHIFT_LEFT(q1), (float16)(q1r),
                                  lane == (int16)(IMIN(n, 16) - 1));
    // rhs = K^T y + rho D^T q + mu (v - s), D^T q = q1 - q1[c+1] + q2 - q2[r+1]
    float16 r = load_upto16(b + i, n) + rho * (q1 - q1right + q2 - q2d);
    if (mu != 0.0f)
        r += mu * vs;
    store_upto16(out + i, r, n);
    admm_contrib16(contrib, d1, d2, z1, z2, n, H);
}
#endif
