// Total-variation kernels: gradient/divergence, Chambolle's projection step (the paper's TV
// prox, DESIGN s.2), Beck-Teboulle's fast gradient projection (FGP) step on periodic
// differences (FISTA), and their finishing passes. Arrays are (NC, H, W) planes; NC (1 or 3) is
// a compile-time constant, and NC > 1 couples the channels inside the square roots (vectorial
// TV, Bresson & Chan). One work-item per pixel along contiguous rows (DESIGN s.6).
// Needs common.cl and reduce.cl in front (the backend concatenates them).

#define DT ((real)0.25)  // Chambolle's step

// ---------------------------------------------------------------------------------------------
// Reference (paper) boundary conventions, with clamped indices:
//   grad u = (u[x+1] - u[x], u[y+1] - u[y]) with the index clamped at the last column/row, so
//            the difference there is 0 (MATLAB u(:, [2:N, N]) - u);
//   div p  = p1[x] - p1[max(x-1,0)] + p2[y] - p2[max(y-1,0)], so the first column/row takes 0
//            for the missing neighbour difference (MATLAB p1 - p1(:, [1, 1:N-1]) + ...).
// ---------------------------------------------------------------------------------------------
inline real div_ref_at(__global const real *p1, __global const real *p2, const int o,
                       const int xi, const int yi, const int W)
{
    const int xm = max(xi - 1, 0), ym = max(yi - 1, 0);
    return p1[o + yi * W + xi] - p1[o + yi * W + xm] + p2[o + yi * W + xi] - p2[o + ym * W + xi];
}

__kernel void grad_fwd(__global const real *u, __global real *g1, __global real *g2,
                       const int W, const int H)
{
    const int xi = get_global_id(0), yi = get_global_id(1);
    if (xi >= W) return;
    const int xp = min(xi + 1, W - 1), yp = min(yi + 1, H - 1);
    for (int c = 0; c < NC; ++c) {
        const int o = c * W * H, i = o + yi * W + xi;
        g1[i] = u[o + yi * W + xp] - u[i];
        g2[i] = u[o + yp * W + xi] - u[i];
    }
}

__kernel void div_ref(__global const real *p1, __global const real *p2, __global real *out,
                      const int W, const int H)
{
    const int xi = get_global_id(0), yi = get_global_id(1);
    if (xi >= W) return;
    for (int c = 0; c < NC; ++c) {
        const int o = c * W * H;
        out[o + yi * W + xi] = div_ref_at(p1, p2, o, xi, yi, W);
    }
}

// z = div p - lam v at one pixel, v = x + s g (the gradient step is never materialised).
#define CHAM_Z(FIRST, o, X, Y) \
    ((FIRST ? (real)0 : div_ref_at(p1, p2, o, X, Y, W)) - lam * (x[o + (Y) * W + (X)] + \
                                                               s * g[o + (Y) * W + (X)]))

// One Chambolle iteration for ROF  min TV(u) + lam/2 ||v - u||^2,  v = x + s g:
//   z = div p - lam v;  q = (p + dt grad z) / (1 + dt |grad z|)
// p is read with a stencil, so q must be another buffer. chambolle_first: p = 0 (not read).
#define CHAMBOLLE_BODY(FIRST)                                                          \
    const int xi = get_global_id(0), yi = get_global_id(1);                            \
    if (xi >= W) return;                                                               \
    const int xp = min(xi + 1, W - 1), yp = min(yi + 1, H - 1);                        \
    real z1[NC], z2[NC];                                                               \
    real n2 = (real)0;                                                                 \
    for (int c = 0; c < NC; ++c) {                                                     \
        const int o = c * W * H;                                                       \
        const real z0 = CHAM_Z(FIRST, o, xi, yi);                                      \
        z1[c] = CHAM_Z(FIRST, o, xp, yi) - z0;                                         \
        z2[c] = CHAM_Z(FIRST, o, xi, yp) - z0;                                         \
        n2 += z1[c] * z1[c] + z2[c] * z2[c];                                           \
    }                                                                                  \
    const real den = (real)1 + DT * SQRT(n2);                                          \
    for (int c = 0; c < NC; ++c) {                                                     \
        const int i = c * W * H + yi * W + xi;                                         \
        const real a1 = FIRST ? (real)0 : p1[i];                                       \
        const real a2 = FIRST ? (real)0 : p2[i];                                       \
        q1[i] = (a1 + DT * z1[c]) / den;                                               \
        q2[i] = (a2 + DT * z2[c]) / den;                                               \
    }

__kernel void chambolle_step(__global const real *p1, __global const real *p2,
                             __global real *q1, __global real *q2,
                             __global const real *x, __global const real *g,
                             const real s, const real lam, const int W, const int H)
{
    CHAMBOLLE_BODY(0)
}

__kernel void chambolle_first(__global const real *p1, __global const real *p2,
                              __global real *q1, __global real *q2,
                              __global const real *x, __global const real *g,
                              const real s, const real lam, const int W, const int H)
{
    CHAMBOLLE_BODY(1)
}

// u = v - div p / lam, v = x + s g.
__kernel void chambolle_finish(__global real *u, __global const real *x, __global const real *g,
                               const real s, const real lam, __global const real *p1,
                               __global const real *p2, const int W, const int H)
{
    const int xi = get_global_id(0), yi = get_global_id(1);
    if (xi >= W) return;
    for (int c = 0; c < NC; ++c) {
        const int o = c * W * H, i = o + yi * W + xi;
        u[i] = x[i] + s * g[i] - div_ref_at(p1, p2, o, xi, yi, W) / lam;
    }
}

// ---------------------------------------------------------------------------------------------
// FGP (Beck & Teboulle 2009) for  min 1/2 ||x - b||^2 + wt TV(x) [+ x >= 0]  with the periodic
// backward differences of Phi: D x = (x - x[x-1], x - x[y-1]) (wrapped),
// D^T d = d1 - d1[x+1] + d2 - d2[y+1] (wrapped). x(p) = P_C(b - wt D^T p);
// p_new = P_ball(r + D x(r) / (8 wt)); r_next = p_new + mom (p_new - p_old).
// ---------------------------------------------------------------------------------------------
inline real fgp_x(__global const real *b, __global const real *r1, __global const real *r2,
                  const real wt, const int nonneg, const int o, const int xi, const int yi,
                  const int W, const int H)
{
    const int xp = xi == W - 1 ? 0 : xi + 1, yp = yi == H - 1 ? 0 : yi + 1;
    const int i = o + yi * W + xi;
    const real dtp = r1[i] - r1[o + yi * W + xp] + r2[i] - r2[o + yp * W + xi];
    const real v = b[i] - wt * dtp;
    return nonneg ? fmax(v, (real)0) : v;
}

// r (stencil) -> p_new, r_out. p_old/p_new may alias (pointwise); r must not alias either.
__kernel void fgp_step(__global const real *b, __global const real *r1, __global const real *r2,
                       __global const real *po1, __global const real *po2,
                       __global real *pn1, __global real *pn2,
                       __global real *ro1, __global real *ro2,
                       const real wt, const real mom, const int nonneg, const int W, const int H)
{
    const int xi = get_global_id(0), yi = get_global_id(1);
    if (xi >= W) return;
    const int xm = xi == 0 ? W - 1 : xi - 1, ym = yi == 0 ? H - 1 : yi - 1;
    const real k = (real)1 / ((real)8 * wt);
    real a1[NC], a2[NC];
    real n2 = (real)0;
    for (int c = 0; c < NC; ++c) {
        const int o = c * W * H, i = o + yi * W + xi;
        const real x0 = fgp_x(b, r1, r2, wt, nonneg, o, xi, yi, W, H);
        const real xl = fgp_x(b, r1, r2, wt, nonneg, o, xm, yi, W, H);
        const real xu = fgp_x(b, r1, r2, wt, nonneg, o, xi, ym, W, H);
        a1[c] = r1[i] + k * (x0 - xl);
        a2[c] = r2[i] + k * (x0 - xu);
        n2 += a1[c] * a1[c] + a2[c] * a2[c];
    }
    const real sc = (real)1 / fmax((real)1, SQRT(n2));
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        const real q1 = a1[c] * sc, q2 = a2[c] * sc;
        const real o1 = po1[i], o2 = po2[i];
        pn1[i] = q1;
        pn2[i] = q2;
        ro1[i] = q1 + mom * (q1 - o1);
        ro2[i] = q2 + mom * (q2 - o2);
    }
}

// z = P_C(b - wt D^T p), with contributions (Phi(z), ||z||_1) (circular TV of the result).
__kernel void fgp_finish(__global real *z, __global const real *b, __global const real *p1,
                         __global const real *p2, const real wt, const int nonneg,
                         __global real *contrib, const int W, const int H)
{
    const int xi = get_global_id(0), yi = get_global_id(1);
    real acc_x = (real)0, acc_y = (real)0;
    if (xi < W) {
        const int xm = xi == 0 ? W - 1 : xi - 1, ym = yi == 0 ? H - 1 : yi - 1;
        real n2 = (real)0;
        for (int c = 0; c < NC; ++c) {
            const int o = c * W * H;
            const real x0 = fgp_x(b, p1, p2, wt, nonneg, o, xi, yi, W, H);
            const real dx = x0 - fgp_x(b, p1, p2, wt, nonneg, o, xm, yi, W, H);
            const real dy = x0 - fgp_x(b, p1, p2, wt, nonneg, o, xi, ym, W, H);
            n2 += dx * dx + dy * dy;
            acc_y += fabs(x0);
            z[o + yi * W + xi] = x0;
        }
        acc_x = SQRT(n2);
    }
    if (xi < W) {
        contrib[yi * W + xi] = acc_x;
        contrib[W * H + yi * W + xi] = acc_y;
    }
}
