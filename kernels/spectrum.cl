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

// The data term and its gradient from one spectrum (one FFT pair per evaluation):
// R = Y - H X (the residual's spectrum), contributions (sum w |R|^2; one plane),
// X <- H R (the spectrum of K^T (y - K x)); with KEEP also R itself, for TwIST's fallbacks
// without an FFT (resid_combine_spec). One row per work-item: summing RROWS rows per
// contribution (reduce.cl) made these kernels slower at 2048^2 (1.6 -> 2.0-2.3 ms).
#define RESID_GRAD_SPEC_BODY(KEEP)                                                      \
    /* X, Y: interleaved complex (re, im) as reals, so that PoCL vectorises across  */  \
    /* work-items */                                                                    \
    const int kx = get_global_id(0), ky = get_global_id(1);                             \
    real acc_x = (real)0;                                                               \
    if (kx < Ws) {                                                                      \
        const int j = ky * Ws + kx;                                                     \
        const real h = Hf[j];                                                           \
        const real w = half_weight(kx, Ws, w_even);                                     \
        for (int c = 0; c < NC; ++c) {                                                  \
            const int k = 2 * (c * Ws * Hs + j);                                        \
            const real rr = Y[k] - h * X[k], ri = Y[k + 1] - h * X[k + 1];              \
            acc_x += w * (rr * rr + ri * ri);                                           \
            X[k] = h * rr;                                                              \
            X[k + 1] = h * ri;                                                          \
            if (KEEP) {                                                                 \
                R[k] = rr;                                                              \
                R[k + 1] = ri;                                                          \
            }                                                                           \
        }                                                                               \
        contrib[j] = acc_x; /* one plane (the backend folds only the first) */          \
    }

__kernel void resid_grad_spec(__global real *X, __global const real *Y,
                              __global const real *Hf, __global real *contrib,
                              const int Ws, const int Hs, const int w_even)
{
    __global real *R = 0;
    RESID_GRAD_SPEC_BODY(0)
}

__kernel void resid_grad_spec_keep(__global real *X, __global const real *Y,
                                   __global const real *Hf, __global real *R,
                                   __global real *contrib, const int Ws, const int Hs,
                                   const int w_even)
{
    RESID_GRAD_SPEC_BODY(1)
}

// The residual spectrum of an affine combination, R <- a R + b2 R2 + b1 R1 (a + b2 + b1 = 1),
// and its contributions (sum w |R|^2, one plane): K is linear, so TwIST's
// monotone fallback to x_ist = (x_new - c2 x_{t-1} - c1 x_t) / cb gets its data term from the
// residuals kept for the three without an FFT pair.
__kernel void resid_combine_spec(__global real *R, __global const real *R2,
                                 __global const real *R1, const real a, const real b2,
                                 const real b1, __global real *contrib, const int Ws,
                                 const int Hs, const int w_even)
{
    const int kx = get_global_id(0), ky = get_global_id(1);
    real acc_x = (real)0;
    if (kx < Ws) {
        const int j = ky * Ws + kx;
        const real w = half_weight(kx, Ws, w_even);
        for (int c = 0; c < NC; ++c) {
            const int k = 2 * (c * Ws * Hs + j);
            const real rr = a * R[k] + b2 * R2[k] + b1 * R1[k];
            const real ri = a * R[k + 1] + b2 * R2[k + 1] + b1 * R1[k + 1];
            acc_x += w * (rr * rr + ri * ri);
            R[k] = rr;
            R[k + 1] = ri;
        }
        contrib[j] = acc_x;
    }
}

// ADMM's x-update in Fourier space: X <- X * inv, inv = 1 / (H^2 + rho |D|^2 + mu); with
// want != 0 also contributions (sum w |Y - H X|^2, 0), the data term of the new x.
__kernel void admm_solve_spec(__global real *X, __global const real *Y,
                              __global const real *Hf, __global const real *inv,
                              __global real *contrib, const int want,
                              const int Ws, const int Hs, const int w_even)
{
    const int kx = get_global_id(0), ky = get_global_id(1);
    real acc_x = (real)0;
    if (kx < Ws) {
        const int j = ky * Ws + kx;
        const real a = inv[j];
        const real h = Hf[j];
        const real w = half_weight(kx, Ws, w_even);
        for (int c = 0; c < NC; ++c) {
            const int k = 2 * (c * Ws * Hs + j);
            const real xr = a * X[k], xi = a * X[k + 1];
            X[k] = xr;
            X[k + 1] = xi;
            if (want) {
                const real rr = Y[k] - h * xr, ri = Y[k + 1] - h * xi;
                acc_x += w * (rr * rr + ri * ri);
            }
        }
    }
    if (want && kx < Ws)
        contrib[ky * Ws + kx] = acc_x;  // one plane
}
#endif  // NC
