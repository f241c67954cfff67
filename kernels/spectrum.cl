// Pointwise spectrum operations on interleaved complex (real2) half-spectra.

// X[k] *= H[k]: a real transfer function applied to a complex spectrum (K = F^-1 H_T F).
__kernel void multiply_real(__global real2 *X, __global const real *H, const int n)
{
    const int k = get_global_id(0);
    if (k >= n) return;
    X[k] *= H[k];
}

// Y[k] = X[k] * H[k] (out of place).
__kernel void multiply_real_into(__global real2 *Y, __global const real2 *X,
                                 __global const real *H, const int n)
{
    const int k = get_global_id(0);
    if (k >= n) return;
    Y[k] = X[k] * H[k];
}
