// Zone-plate masks (Eqs. 1, 9) and the transfer function H_T (Eq. 17) synthesised on the device.
//
// Both quadratic phases are separable: pi (x^2 + y^2) / r1^2 = pi (phx[i] + phy[j]). The host
// passes each axis phase reduced modulo 2 in float64, so the float32 sum stays below 4 and
// cospi/sinpi are accurate to a few ulp for any grid size.

// T = 1/2 + 1/2 cos(pi (phx + phy) + phase) for a GZP (binary == 0), or
// T = 1/2 + 1/2 sgn(cos(...)) for a binary FZA (binary == 1); zero outside the aperture
// (integer pixel radius test: (i - cx)^2 + (j - cy)^2 <= r2max, exact for any size).
__kernel void zone_plate(__global real *out,
                         __global const real *phx, __global const real *phy,
                         const int nx, const int cx, const int cy,
                         const long r2max, const real phase_over_pi, const int binary)
{
    const int i = get_global_id(0);
    const int j = get_global_id(1);
    if (i >= nx) return;
    const long dx = i - cx, dy = j - cy;
    real t = (real)0;
    if (dx * dx + dy * dy <= r2max) {
        real c = cospi(phx[i] + phy[j] + phase_over_pi);
        if (binary) c = (c > (real)0) ? (real)1 : ((c < (real)0) ? (real)-1 : (real)0);
        t = (real)0.5 + (real)0.5 * c;
    }
    out[(size_t)j * nx + i] = t;
}

// Half-spectrum transfer function H_T(u, v) = sin(pi r1'^2 (u^2 + v^2)) on the rfft grid
// (rows: all fftfreq v, columns: u >= 0). pu[i] = r1'^2 u_i^2 mod 2, pv[j] = r1'^2 v_j^2 mod 2.
// power = 1 writes H_T, power = 2 writes H_T^2 (the normal operator K^T K).
__kernel void transfer_function(__global real *out,
                                __global const real *pu, __global const real *pv,
                                const int nxh, const int power)
{
    const int i = get_global_id(0);
    const int j = get_global_id(1);
    if (i >= nxh) return;
    real h = sinpi(pu[i] + pv[j]);
    out[(size_t)j * nxh + i] = (power == 2) ? h * h : h;
}
