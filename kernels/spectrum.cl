// Pointwise spectrum operations on interleaved complex (real2) half-spectra.

// X[k] *= H[k]: a real transfer function applied to a complex spectrum (K = F^-1 H_T F).
__kernel void multiply_real(__global real2 *X, __global const real *H, const int n)
{
    const int k = get_global_id(0);
    if (k >= n) return;
    X[k] *= H[k];
}

#ifdef NC  // only in the solver backend's build (reduce.cl in front, NC defined)
// ---------------------------------------------------------------------------------------------
// Solver kernels on (NC, Hs, Ws) half-spectra of unnormalised rfft2s. They need reduce.cl
// (the solver backend builds common.cl + reduce.cl + spectrum.cl with NC defined).
// Parseval on the half spectrum: sum |r|^2 = (1/(H W)) sum_k w_k |R_k|^2 with w = 1 on column
// 0 (and on the last column when W is even: its Nyquist column), 2 elsewhere.
// ---------------------------------------------------------------------------------------------
inline real half_weight(const int kx, const int Ws, const int w_even)
{
    return (kx == 0 || (w_even && kx == Ws - 1)) ? (real)1 : (real)2;
}

// One frequency j of every channel: R = Y - H X, X <- H R (with step, X <- X + H R); returns
// sum_c |R|^2 (unweighted).
inline real resid_grad_at(__global real *X, __global const real *Y, const real h, const int j,
                          const int step, const int Ws, const int Hs)
{
    real acc = (real)0;
    for (int c = 0; c < NC; ++c) {
        const int k = 2 * (c * Ws * Hs + j);
        const real rr = Y[k] - h * X[k], ri = Y[k + 1] - h * X[k + 1];
        acc += rr * rr + ri * ri;
        X[k] = step ? X[k] + h * rr : h * rr;
        X[k + 1] = step ? X[k + 1] + h * ri : h * ri;
    }
    return acc;
}

// One frequency j of every channel: X <- a X; with want, returns sum_c |Y - H X|^2.
inline real admm_solve_at(__global real *X, __global const real *Y, const real h, const real a,
                          const int want, const int j, const int Ws, const int Hs)
{
    real acc = (real)0;
    for (int c = 0; c < NC; ++c) {
        const int k = 2 * (c * Ws * Hs + j);
        const real xr = a * X[k], xi = a * X[k + 1];
        X[k] = xr;
        X[k + 1] = xi;
        if (want) {
            const real rr = Y[k] - h * xr, ri = Y[k + 1] - h * xi;
            acc += rr * rr + ri * ri;
        }
    }
    return acc;
}

// The data term and its gradient from one spectrum (one FFT pair per evaluation):
// R = Y - H X (the residual's spectrum), contributions (sum w |R|^2; one plane), X <- H R (the
// spectrum of K^T (y - K x)), or with step X <- X + H R (of x + K^T (y - K x), the gradient step
// of unit length: FISTA's, whose L is 1).
__kernel void resid_grad_spec(__global real *X, __global const real *Y,
                              __global const real *Hf, __global real *contrib, const int step,
                              const int Ws, const int Hs, const int w_even)
{
    // X, Y: interleaved complex (re, im) as reals, so that PoCL vectorises across work-items
    X += frame_spectrum(Ws, Hs);
    Y += frame_spectrum(Ws, Hs);
    contrib += frame_contrib(1);
    const int kx = get_global_id(0), ky = get_global_id(1);
    if (kx < Ws) {
        const int j = ky * Ws + kx;
        // one plane (the backend folds only the first)
        contrib[j] = half_weight(kx, Ws, w_even) * resid_grad_at(X, Y, Hf[j], j, step, Ws,
                                                                 Hs);
    }
}

#ifndef REAL_IS_DOUBLE
// resid_grad_spec on CPUs: a work-item takes 8 frequencies of a row (16 interleaved floats) as
// float16 vectors (H duplicated per re/im lane) and writes one contribution. The per-frequency
// kernel's interleaved complex defeated the vectorisers: measured on a 2-core Xeon (kernel
// alone, 20 launches per finish), 512^2 / 2048^2: PoCL 3.1 0.22-0.26 -> 0.13-0.16 / 2.58 ->
// 0.87 ms, PoCL 3.0 0.16-0.21 -> 0.14-0.15 / 3.1-3.2 -> 0.97-1.06, Intel's runtime 0.138 ->
// 0.119 / 1.10 -> 0.85 (with vec_type_hint: without it Intel's compiler vectorised across
// work-items as well, 2.6 ms at 2048^2). A row's last work-item takes the rest lane by lane.
#define SPEC_LANES 8

// sum over 8 frequencies of w |R|^2 from q = (re^2, im^2) interleaved: weight 2 but on column
// 0 and the even width's Nyquist column (half_weight)
inline float weighted_sum8(const float16 q, const int kx0, const int Ws, const int w_even)
{
    return 2.0f * hsum16(q) - (kx0 == 0 ? q.s0 + q.s1 : 0.0f)
           - (w_even && kx0 + SPEC_LANES == Ws ? q.se + q.sf : 0.0f);
}

KERNEL_VEC16
void resid_grad_spec8(__global float *X, __global const float *Y, __global const float *Hf,
                      __global float *contrib, const int step, const int Ws, const int Hs,
                      const int w_even)
{
    X += frame_spectrum(Ws, Hs);
    Y += frame_spectrum(Ws, Hs);
    contrib += frame_contrib(1);
    const int gx = get_global_id(0), ky = get_global_id(1);
    const int kx0 = gx * SPEC_LANES;
    const int j0 = ky * Ws + kx0;
    float acc = 0.0f;
    if (kx0 + SPEC_LANES <= Ws) {
        const float16 h = DUP8(LOAD8G(Hf + j0));
        for (int c = 0; c < NC; ++c) {
            const int k = 2 * (c * Ws * Hs + j0);
            const float16 x = LOAD16G(X + k);
            const float16 r = LOAD16G(Y + k) - h * x;
            STORE16G(step ? x + h * r : h * r, X + k);
            acc += weighted_sum8(r * r, kx0, Ws, w_even);
        }
    } else {
        for (int kx = kx0; kx < Ws; ++kx) {
            const int j = j0 + kx - kx0;
            acc += half_weight(kx, Ws, w_even) * resid_grad_at(X, Y, Hf[j], j, step, Ws, Hs);
        }
    }
    contrib[ky * get_global_size(0) + gx] = acc;
}
#endif

// ADMM's x-update's inverse spectrum, inv = 1 / (H^2 + rho |D|^2 + mu) (0 where the sum is not
// positive; clfza.solvers._admm_ops._inverse is the float64 specification), filled on the device
// for frame f = get_global_id(2) from the shared H^2, the separable |D|^2 = dsym[kx] +
// dsym[Ws + ky] (4 sin^2(pi kx / W) and 4 sin^2(pi ky / H), from the host in float64) and the
// frame's penalties pen[2 f] = rho, pen[2 f + 1] = mu: two scalars per frame go to the device,
// not a host-computed inverse. Once per setup, not per iteration (the solve reads inv).
inline real admm_inverse(const real h2, const real d, const real rho, const real mu)
{
    const real den = h2 + rho * d + mu;
    return den > (real)0 ? (real)1 / den : (real)0;
}

__kernel void admm_inverse_fill(__global real *inv, __global const real *H2,
                                __global const real *dsym, __global const real *pen,
                                const int Ws, const int Hs)
{
    const int kx = get_global_id(0), ky = get_global_id(1);
    const size_t f = get_global_id(2);
    if (kx < Ws && ky < Hs) {
        const int j = ky * Ws + kx;
        inv[f * Ws * Hs + j] = admm_inverse(H2[j], dsym[kx] + dsym[Ws + ky], pen[2 * f],
                                            pen[2 * f + 1]);
    }
}

// ADMM's x-update in Fourier space: X <- X * inv, inv = 1 / (H^2 + rho |D|^2 + mu); with
// want != 0 also contributions (sum w |Y - H X|^2, 0), the data term of the new x. A batch's
// frames have their own inv (their own penalties; inv_frames != 0), or share one.
__kernel void admm_solve_spec(__global real *X, __global const real *Y,
                              __global const real *Hf, __global const real *inv,
                              __global real *contrib, const int want, const int inv_frames,
                              const int Ws, const int Hs, const int w_even)
{
    X += frame_spectrum(Ws, Hs);
    Y += frame_spectrum(Ws, Hs);
    inv += inv_frames ? get_global_id(2) * (size_t)Ws * Hs : 0;
    contrib += frame_contrib(1);
    const int kx = get_global_id(0), ky = get_global_id(1);
    if (kx < Ws) {
        const int j = ky * Ws + kx;
        const real r2 = admm_solve_at(X, Y, Hf[j], inv[j], want, j, Ws, Hs);
        if (want)
            contrib[j] = half_weight(kx, Ws, w_even) * r2;  // one plane
    }
}

#ifndef REAL_IS_DOUBLE
// admm_solve_spec on CPUs, 8 frequencies per work-item as resid_grad_spec8 (one contribution
// each; 1 / (H^2 + rho |D|^2 + mu) and H duplicated per re/im lane)
KERNEL_VEC16
void admm_solve_spec8(__global float *X, __global const float *Y, __global const float *Hf,
                      __global const float *inv, __global float *contrib, const int want,
                      const int inv_frames, const int Ws, const int Hs, const int w_even)
{
    X += frame_spectrum(Ws, Hs);
    Y += frame_spectrum(Ws, Hs);
    inv += inv_frames ? get_global_id(2) * (size_t)Ws * Hs : 0;
    contrib += frame_contrib(1);
    const int gx = get_global_id(0), ky = get_global_id(1);
    const int kx0 = gx * SPEC_LANES;
    const int j0 = ky * Ws + kx0;
    float acc = 0.0f;
    if (kx0 + SPEC_LANES <= Ws) {
        const float16 a = DUP8(LOAD8G(inv + j0)), h = DUP8(LOAD8G(Hf + j0));
        for (int c = 0; c < NC; ++c) {
            const int k = 2 * (c * Ws * Hs + j0);
            const float16 x = a * LOAD16G(X + k);
            STORE16G(x, X + k);
            if (want) {
                const float16 r = LOAD16G(Y + k) - h * x;
                acc += weighted_sum8(r * r, kx0, Ws, w_even);
            }
        }
    } else {
        for (int kx = kx0; kx < Ws; ++kx) {
            const int j = j0 + kx - kx0;
            acc += half_weight(kx, Ws, w_even) * admm_solve_at(X, Y, Hf[j], inv[j], want, j,
                                                               Ws, Hs);
        }
    }
    if (want)
        contrib[ky * get_global_size(0) + gx] = acc;
}
#endif
#endif  // NC
