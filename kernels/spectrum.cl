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
// R = Y - H X (the residual's spectrum), contributions (sum w |R|^2; one plane), X <- H R (the spectrum of
// K^T (y - K x)).
__kernel void resid_grad_spec(__global real *X, __global const real *Y,
                              __global const real *Hf, __global real *contrib,
                              const int Ws, const int Hs, const int w_even)
{
    // X, Y: interleaved complex (re, im) as reals, so that PoCL vectorises across work-items
    const int kx = get_global_id(0), ky = get_global_id(1);
    real acc_x = (real)0;
    if (kx < Ws) {
        const int j = ky * Ws + kx;
        const real h = Hf[j];
        const real w = half_weight(kx, Ws, w_even);
        for (int c = 0; c < NC; ++c) {
            const int k = 2 * (c * Ws * Hs + j);
            const real rr = Y[k] - h * X[k], ri = Y[k + 1] - h * X[k + 1];
            acc_x += w * (rr * rr + ri * ri);
            X[k] = h * rr;
            X[k + 1] = h * ri;
        }
    }
    if (kx < Ws)
        contrib[ky * Ws + kx] = acc_x;  // one plane (the backend folds only the first)
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
