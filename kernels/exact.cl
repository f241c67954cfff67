// The exact (finite-aperture, cropped-sensor) model on the model grid (clfza/exact.py):
// complex spectrum products, sums over the sensor window, the residual, and the pixel-wise
// updates of the crop-split ADMM (clfza/solvers/admm_crop.py). Arrays are (NC, H, W) on the
// grid; the sensor window is rows [oy, oy + sy), cols [ox, ox + sx).

inline int in_window(const int xi, const int yi, const int ox, const int oy, const int sx,
                     const int sy)
{
    return xi >= ox && xi < ox + sx && yi >= oy && yi < oy + sy;
}

// X *= Hs (cj = 0) or conj(Hs) (cj = 1), on NC half spectra of n values each
__kernel void spec_mul_complex(__global real2 *X, __global const real2 *Hs, const int cj,
                               const int n)
{
    const int k = get_global_id(0);
    if (k >= n) return;
    real2 h = Hs[k];
    if (cj) h.y = -h.y;
    for (int c = 0; c < NC; ++c) {
        const real2 x = X[c * n + k];
        X[c * n + k] = (real2)(x.x * h.x - x.y * h.y, x.x * h.y + x.y * h.x);
    }
}

// Per sensor row (one work-item each): sum hx, sum a (with use_a) and
// sum (Cy - hx)^2, written as out[(c * sy + row) * 3 + k]; the host adds the rows in float64.
__kernel void window_row_sums(__global const real *hx, __global const real *a,
                              __global const real *Cy, __global const real *shift,
                              __global real *out, const int use_a, const int ox, const int oy,
                              const int sx, const int sy, const int W, const int H)
{
    const int row = get_global_id(0);
    if (row >= sy) return;
    for (int c = 0; c < NC; ++c) {
        const int base = c * W * H + (oy + row) * W + ox;
        const real m0 = shift[c];  // ~ the window mean of hx: no cancellation in the squares
        real s0 = (real)0, s1 = (real)0, s2 = (real)0;
        for (int j = 0; j < sx; ++j) {
            const real h = hx[base + j];
            const real d = Cy[base + j] - h + m0;
            s0 += h;
            s2 += d * d;
            if (use_a) s1 += a[base + j];
        }
        out[(c * sy + row) * 3] = s0;
        out[(c * sy + row) * 3 + 1] = s1;
        out[(c * sy + row) * 3 + 2] = s2;
    }
}

// r = Cy - (hx - m[c]) on the sensor window, 0 elsewhere: C^T (y - P C hx)
__kernel void crop_residual(__global real *r, __global const real *hx, __global const real *Cy,
                            __global const real *m, const int ox, const int oy, const int sx,
                            const int sy, const int W, const int H)
{
    const int xi = get_global_id(0), yi = get_global_id(1);
    if (xi >= W) return;
    const int inside = in_window(xi, yi, ox, oy, sx, sy);
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        r[i] = inside ? Cy[i] - hx[i] + m[c] : (real)0;
    }
}

// v-update at t = hx + a: inside the sensor v = (Cy + mu1 t) / (1 + mu1) + corr[c] with
// corr = mean_S(Cy + mu1 t) / (mu1 (1 + mu1)) (Sherman-Morrison for P), outside v = t;
// then a = t - v and e = v - a (the next x-update's input).
__kernel void crop_v_update(__global const real *hx, __global real *v, __global real *a,
                            __global real *e, __global const real *Cy,
                            __global const real *corr, const real mu1, const int ox,
                            const int oy, const int sx, const int sy, const int W, const int H)
{
    const int xi = get_global_id(0), yi = get_global_id(1);
    if (xi >= W) return;
    const int inside = in_window(xi, yi, ox, oy, sx, sy);
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        const real t = hx[i] + a[i];
        const real vn = inside ? (Cy[i] + mu1 * t) / ((real)1 + mu1) + corr[c] : t;
        const real an = t - vn;
        v[i] = vn;
        a[i] = an;
        e[i] = vn - an;
    }
}

// w = proj(x + s): max(., 0) with nonneg, 0 outside [oy - m, oy + sy + m) x [ox - m, ...)
// with support; s = x + s - w
__kernel void crop_w_update(__global const real *x, __global real *w, __global real *s,
                            const int nonneg, const int support, const int ox, const int oy,
                            const int sx, const int sy, const int W, const int H)
{
    const int xi = get_global_id(0), yi = get_global_id(1);
    if (xi >= W) return;
    const int keep = !support || in_window(xi, yi, ox, oy, sx, sy);
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        const real t = x[i] + s[i];
        real wn = nonneg ? FMAX(t, (real)0) : t;
        wn = keep ? wn : (real)0;
        w[i] = wn;
        s[i] = t - wn;
    }
}

// x-update in Fourier space: X = (X + mu1 conj(Hs) E) inv;  E = Hs X (for H x)
__kernel void crop_x_spec(__global real2 *X, __global real2 *E, __global const real2 *Hs,
                          __global const real *inv, const real mu1, const int n)
{
    const int k = get_global_id(0);
    if (k >= n) return;
    const real2 h = Hs[k];
    const real iv = inv[k];
    for (int c = 0; c < NC; ++c) {
        const int j = c * n + k;
        const real2 e = E[j], x = X[j];
        // conj(h) e = (h.x e.x + h.y e.y, h.x e.y - h.y e.x)
        const real2 xn = (real2)((x.x + mu1 * (h.x * e.x + h.y * e.y)) * iv,
                                 (x.y + mu1 * (h.x * e.y - h.y * e.x)) * iv);
        X[j] = xn;
        E[j] = (real2)(xn.x * h.x - xn.y * h.y, xn.x * h.y + xn.y * h.x);
    }
}

#ifndef REAL_IS_DOUBLE
// crop_x_spec on CPUs in float32: 8 frequencies per work-item as float16 vectors of (re, im)
// pairs split into their real and imaginary lanes (.even, .odd), the same arithmetic per
// frequency; the last work-item takes the n % 8 left over one by one (why, measured:
// docs/measurements.md, clfza.solvers._admm_crop_ops).
#define CROP_LANES 8
KERNEL_VEC16
void crop_x_spec8(__global float *X, __global float *E, __global const float *Hs,
                  __global const float *inv, const float mu1, const int n)
{
    const int k0 = get_global_id(0) * CROP_LANES;
    if (k0 + CROP_LANES <= n) {
        const float16 hv = LOAD16G(Hs + 2 * k0);
        const float8 hr = hv.even, hi = hv.odd, iv = LOAD8G(inv + k0);
        for (int c = 0; c < NC; ++c) {
            const size_t j = 2 * ((size_t)c * n + k0);
            const float16 ev = LOAD16G(E + j), xv = LOAD16G(X + j);
            const float8 er = ev.even, ei = ev.odd;
            const float8 nr = (xv.even + mu1 * (hr * er + hi * ei)) * iv;
            const float8 ni = (xv.odd + mu1 * (hr * ei - hi * er)) * iv;
            float16 out;
            out.even = nr;
            out.odd = ni;
            STORE16G(out, X + j);
            out.even = nr * hr - ni * hi;
            out.odd = nr * hi + ni * hr;
            STORE16G(out, E + j);
        }
    } else {
        for (int k = k0; k < n; ++k) {
            const float h_r = Hs[2 * k], h_i = Hs[2 * k + 1], v = inv[k];
            for (int c = 0; c < NC; ++c) {
                const size_t j = 2 * ((size_t)c * n + k);
                const float e_r = E[j], e_i = E[j + 1];
                const float n_r = (X[j] + mu1 * (h_r * e_r + h_i * e_i)) * v;
                const float n_i = (X[j + 1] + mu1 * (h_r * e_i - h_i * e_r)) * v;
                X[j] = n_r;
                X[j + 1] = n_i;
                E[j] = n_r * h_r - n_i * h_i;
                E[j + 1] = n_r * h_i + n_i * h_r;
            }
        }
    }
}
#endif

// The APG's gradient point (clfza/solvers/_apg_exact.py): b = x + g inside the object region
// (the launch window), off outside it with support (b = x + g everywhere without).
__kernel void apg_point(__global real *b, __global const real *x, __global const real *g,
                        const real off, const int support, const int ox, const int oy,
                        const int sx, const int sy, const int W, const int H)
{
    const int xi = get_global_id(0), yi = get_global_id(1);
    if (xi >= W) return;
    const int keep = !support || in_window(xi, yi, ox, oy, sx, sy);
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        b[i] = keep ? x[i] + g[i] : off;
    }
}
