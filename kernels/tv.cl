// Total-variation kernels: gradient/divergence, Chambolle's projection step (the paper's TV
// prox, docs/design.md s.2), Beck-Teboulle's fast gradient projection (FGP) step on periodic
// differences (FISTA), and their finishing passes. Arrays are (NC, H, W) planes; NC (1 or 3) is
// a compile-time constant, and NC > 1 couples the channels inside the square roots (vectorial
// TV, Bresson & Chan). One work-item per pixel along contiguous rows (docs/design.md s.6).
// Needs common.cl and reduce.cl in front (the backend concatenates them).

#define DT ((real)0.25)  // Chambolle's step

// ---------------------------------------------------------------------------------------------
// Reference (paper) boundary conventions:
//   grad u = (u[x+1] - u[x], u[y+1] - u[y]), 0 at the last column/row (MATLAB
//            u(:, [2:N, N]) - u);
//   div p  = p1[x] - p1[x-1] + p2[y] - p2[y-1], the first column/row taking 0 for the missing
//            neighbour difference (MATLAB p1 - p1(:, [1, 1:N-1]) + ...).
// Vectorisation (docs/design.md s.6): neighbours are loaded at affine addresses (i +- 1, i +- W) under a
// condition and the boundary case is a select. Clamped indices (min(x + 1, W - 1)) are not
// affine in the work-item id and made PoCL's vectoriser emit gathers (2-3x slower at 2048^2).
// ---------------------------------------------------------------------------------------------
inline real div_ref_at(__global const real *p1, __global const real *p2, const int i,
                       const int xi, const int yi, const int W)
{
    const real a1 = p1[i], a2 = p2[i];
    return a1 - (xi > 0 ? p1[i - 1] : a1) + a2 - (yi > 0 ? p2[i - W] : a2);
}

__kernel void grad_fwd(__global const real *u, __global real *g1, __global real *g2,
                       const int W, const int H)
{
    const int xi = get_global_id(0), yi = get_global_id(1);
    if (xi >= W) return;
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        const real u0 = u[i];
        g1[i] = xi < W - 1 ? u[i + 1] - u0 : (real)0;
        g2[i] = yi < H - 1 ? u[i + W] - u0 : (real)0;
    }
}

__kernel void div_ref(__global const real *p1, __global const real *p2, __global real *out,
                      const int W, const int H)
{
    const int xi = get_global_id(0), yi = get_global_id(1);
    if (xi >= W) return;
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        out[i] = div_ref_at(p1, p2, i, xi, yi, W);
    }
}

// One Chambolle iteration for ROF  min TV(u) + lam/2 ||v - u||^2,  v = x + s g (never
// materialised):  z = div p - lam v;  q = (p + dt grad z) / (1 + dt |grad z|).
// p is read with a stencil, so q must be another buffer. FIRST: p = 0 (not read).
// Launched with exactly (W, H) work-items (no `xi >= W` guard, which masks every access).
// With CHANGE, also the contribution (|q - p|^2 summed over channels and components, |q|^2)
// for the adaptive inner stop (tv_tol).
// A batch of frames (reduce.cl, above frame_image; TwIST's batch): the work-item's frame, its
// step s times the frame's FPAR_MU factor and lam times its FPAR_THR factor (1 for one frame:
// the arguments themselves), and a frame whose FPAR_ACTIVE is 0 returns at once (a frame that
// takes no prox this round, or has stopped: its dual and output stay as they were).
#define CHAMBOLLE_FRAME()                                                               \
    __global const real *fp = frame_par(fpar);                                          \
    if (fp[FPAR_ACTIVE] == (real)0) return;                                             \
    s *= fp[FPAR_MU];                                                                   \
    lam *= fp[FPAR_THR];                                                                \
    const size_t fo = frame_image(W, H);                                                \
    x += fo;                                                                            \
    g += fo
#define CHAMBOLLE_DUALS() p1 += fo; p2 += fo; q1 += fo; q2 += fo
#define CHAMBOLLE_BODY(FIRST, CHANGE)                                                   \
    const int xi = get_global_id(0), yi = get_global_id(1);                             \
    const int hl = xi > 0, hu = yi > 0, hr = xi < W - 1, hd = yi < H - 1;               \
    real z1[NC], z2[NC], c1[NC], c2[NC];                                                \
    real n2 = (real)0;                                                                  \
    for (int c = 0; c < NC; ++c) {                                                      \
        const int i = c * W * H + yi * W + xi;                                          \
        const real v0 = x[i] + s * g[i];                                                \
        const real vr = hr ? x[i + 1] + s * g[i + 1] : v0;                              \
        const real vd = hd ? x[i + W] + s * g[i + W] : v0;                              \
        real d0 = (real)0, dr = (real)0, dd = (real)0;                                  \
        c1[c] = (real)0;                                                                \
        c2[c] = (real)0;                                                                \
        if (!FIRST) {                                                                   \
            const real a1 = p1[i], a2 = p2[i];                                          \
            const real a1r = hr ? p1[i + 1] : a1, a2r = hr ? p2[i + 1] : a2;            \
            const real a1d = hd ? p1[i + W] : a1, a2d = hd ? p2[i + W] : a2;            \
            d0 = a1 - (hl ? p1[i - 1] : a1) + a2 - (hu ? p2[i - W] : a2);               \
            dr = a1r - a1 + a2r - ((hr && hu) ? p2[i + 1 - W] : a2r);                   \
            dd = a1d - ((hd && hl) ? p1[i + W - 1] : a1d) + a2d - a2;                   \
            c1[c] = a1;                                                                 \
            c2[c] = a2;                                                                 \
        }                                                                               \
        const real z0 = d0 - lam * v0, zr = dr - lam * vr, zd = dd - lam * vd;          \
        z1[c] = hr ? zr - z0 : (real)0;                                                 \
        z2[c] = hd ? zd - z0 : (real)0;                                                 \
        n2 += z1[c] * z1[c] + z2[c] * z2[c];                                            \
    }                                                                                   \
    const real den = (real)1 + DT * SQRT(n2);                                           \
    real dq = (real)0, nq = (real)0;                                                    \
    for (int c = 0; c < NC; ++c) {                                                      \
        const int i = c * W * H + yi * W + xi;                                          \
        const real b1 = (c1[c] + DT * z1[c]) / den, b2 = (c2[c] + DT * z2[c]) / den;    \
        q1[i] = b1;                                                                     \
        q2[i] = b2;                                                                     \
        if (CHANGE) {                                                                   \
            dq += (b1 - c1[c]) * (b1 - c1[c]) + (b2 - c2[c]) * (b2 - c2[c]);            \
            nq += b1 * b1 + b2 * b2;                                                    \
        }                                                                               \
    }                                                                                   \
    if (CHANGE) {                                                                       \
        contrib[yi * W + xi] = dq;                                                      \
        contrib[W * H + yi * W + xi] = nq;                                              \
    }

__kernel void chambolle_step(__global const real *p1, __global const real *p2,
                             __global real *q1, __global real *q2,
                             __global const real *x, __global const real *g,
                             real s, real lam, __global const real *fpar, const int W,
                             const int H)
{
    __global real *contrib = 0;
    CHAMBOLLE_FRAME();
    CHAMBOLLE_DUALS();
    CHAMBOLLE_BODY(0, 0)
}

__kernel void chambolle_first(__global const real *p1, __global const real *p2,
                              __global real *q1, __global real *q2,
                              __global const real *x, __global const real *g,
                              real s, real lam, __global const real *fpar, const int W,
                              const int H)
{
    __global real *contrib = 0;
    CHAMBOLLE_FRAME();
    CHAMBOLLE_DUALS();
    CHAMBOLLE_BODY(1, 0)
}

// chambolle_step that also leaves the contributions (|q - p|^2, |q|^2) of the dual's change.
__kernel void chambolle_step_change(__global const real *p1, __global const real *p2,
                                    __global real *q1, __global real *q2,
                                    __global const real *x, __global const real *g,
                                    real s, real lam, __global const real *fpar,
                                    __global real *contrib, const int W, const int H)
{
    CHAMBOLLE_FRAME();
    CHAMBOLLE_DUALS();
    contrib += frame_contrib(2);
    CHAMBOLLE_BODY(0, 1)
}

// u = v - div p / lam, v = x + s g.
__kernel void chambolle_finish(__global real *u, __global const real *x, __global const real *g,
                               real s, real lam, __global const real *p1,
                               __global const real *p2, __global const real *fpar,
                               const int W, const int H)
{
    CHAMBOLLE_FRAME();
    u += fo;
    p1 += fo;
    p2 += fo;
    const int xi = get_global_id(0), yi = get_global_id(1);
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        u[i] = x[i] + s * g[i] - div_ref_at(p1, p2, i, xi, yi, W) / lam;
    }
}

// ---------------------------------------------------------------------------------------------
// FGP (Beck & Teboulle 2009) for  min 1/2 ||x - b||^2 + wt TV(x) [+ x >= 0]  with the periodic
// backward differences of Phi: D x = (x - x[x-1], x - x[y-1]) (wrapped),
// D^T d = d1 - d1[x+1] + d2 - d2[y+1] (wrapped). x(p) = P_C(b - wt D^T p);
// p_new = P_ball(r + D x(r) / (8 wt)); r_next = p_new + mom (p_new - p_old).
// Periodic neighbours (docs/design.md s.6): along y the wrapped row is a row offset (up, dn), uniform
// over a work-group row. Along x, left_per/right_per make two conditional loads at affine
// addresses, each with the pixel's own value c (loaded anyway) as the default as in the
// Chambolle kernels, and select between them. Wrapped indices (xi == 0 ? W - 1 : xi - 1), and
// a choice between two loads (xi > 0 ? a[i - 1] : a[i + W - 1], or a wrap-around element loaded
// beforehand), both end up as one load from a selected address, which PoCL's vectoriser turns
// into a gather (fgp_step at 2048^2: 13.1 -> 10.2 ms, fgp_finish 12.7 -> 8.9 ms).
// ---------------------------------------------------------------------------------------------

// x(p) at one pixel from its loads: P_C(b - wt (p1 - p1[x+1] + p2 - p2[y+1])).
inline real fgp_x(const real b0, const real p1c, const real p1r, const real p2c,
                  const real p2d, const real wt, const int nonneg)
{
    const real dtp = p1c - p1r + p2c - p2d;
    const real v = b0 - wt * dtp;
    return nonneg ? FMAX(v, (real)0) : v;
}

// x(p) at (x, y), (x-1, y) and (x, y-1) (wrapped) for the pixel i: the three terms of D x.
// (x-1)+1 and (y-1)+1 wrap back to i. up/dn: offsets to the rows above/below (wrapped).
#define FGP_X3(b, p1, p2, i, x0, xl, xu)                                                   \
    const real b0 = b[i], p1c = p1[i], p2c = p2[i], p2dc = p2[i + dn];                    \
    const real bu = b[i + up], p1u = p1[i + up], p2u = p2[i + up];                        \
    const real x0 = fgp_x(b0, p1c, right_per(p1, i, xi, W, p1c), p2c, p2dc, wt, nonneg);  \
    const real xl = fgp_x(left_per(b, i, xi, W, b0), left_per(p1, i, xi, W, p1c), p1c,    \
                          left_per(p2, i, xi, W, p2c), left_per(p2, i + dn, xi, W, p2dc), \
                          wt, nonneg);                                                    \
    const real xu = fgp_x(bu, p1u, right_per(p1, i + up, xi, W, p1u), p2u, p2c, wt, nonneg);

// A batch of frames (reduce.cl, above frame_image): the work-item's frame, its weight wt times
// the frame's threshold factor (1 for one frame: the argument itself), and a stopped frame
// returns at once. fo: the frame's offset into the image-shaped arrays.
#define FGP_FRAME()                                                                         \
    __global const real *fp = frame_par(fpar);                                              \
    if (fp[FPAR_ACTIVE] == (real)0) return;                                                 \
    wt *= fp[FPAR_THR];                                                                     \
    const size_t fo = frame_image(W, H)

// r (stencil) -> p_new, r_out. p_old/p_new may alias (pointwise); r must not alias either.
// with_r = 0: p_new only (p_old and r_out untouched). The backend asks for r_out only when a
// next step reads it and the momentum is not 0: the first step's momentum is 0 (r_next =
// p_new exactly) and the last step's r_out has no reader, so 2 inner iterations need none
// (4 array passes of the 9 two steps would spend on it, and 4 reads of p_old).
__kernel void fgp_step(__global const real *b, __global const real *r1, __global const real *r2,
                       __global const real *po1, __global const real *po2,
                       __global real *pn1, __global real *pn2,
                       __global real *ro1, __global real *ro2,
                       real wt, const real mom, const int nonneg, const int with_r,
                       __global const real *fpar, const int W, const int H)
{
    FGP_FRAME();
    b += fo; r1 += fo; r2 += fo; po1 += fo; po2 += fo; pn1 += fo; pn2 += fo;
    ro1 += fo; ro2 += fo;
    const int xi = get_global_id(0), yi = get_global_id(1);
    if (xi >= W) return;
    const int up = yi > 0 ? -W : (H - 1) * W, dn = yi < H - 1 ? W : (1 - H) * W;
    const real k = (real)1 / ((real)8 * wt);
    real a1[NC], a2[NC];
    real n2 = (real)0;
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        FGP_X3(b, r1, r2, i, x0, xl, xu)
        a1[c] = p1c + k * (x0 - xl);
        a2[c] = p2c + k * (x0 - xu);
        n2 += a1[c] * a1[c] + a2[c] * a2[c];
    }
    const real sc = (real)1 / FMAX((real)1, SQRT(n2));
    for (int c = 0; c < NC; ++c) {
        const int i = c * W * H + yi * W + xi;
        const real q1 = a1[c] * sc, q2 = a2[c] * sc;
        if (with_r) {  // uniform over the launch
            const real o1 = po1[i], o2 = po2[i];
            ro1[i] = q1 + mom * (q1 - o1);
            ro2[i] = q2 + mom * (q2 - o2);
        }
        pn1[i] = q1;
        pn2[i] = q2;
    }
}

// z = P_C(b - wt D^T p), with contributions (Phi(z), ||z||_1) (circular TV of the result).
__kernel void fgp_finish(__global real *z, __global const real *b, __global const real *p1,
                         __global const real *p2, real wt, const int nonneg,
                         __global const real *fpar, __global real *contrib, const int W,
                         const int H)
{
    FGP_FRAME();
    z += fo; b += fo; p1 += fo; p2 += fo;
    contrib += frame_contrib(2);
    const int xi = get_global_id(0), yi = get_global_id(1);
    real acc_x = (real)0, acc_y = (real)0;
    if (xi < W) {
        const int up = yi > 0 ? -W : (H - 1) * W, dn = yi < H - 1 ? W : (1 - H) * W;
        real n2 = (real)0;
        for (int c = 0; c < NC; ++c) {
            const int i = c * W * H + yi * W + xi;
            FGP_X3(b, p1, p2, i, x0, xl, xu)
            const real dx = x0 - xl;
            const real dy = x0 - xu;
            n2 += dx * dx + dy * dy;
            acc_y += FABS(x0);
            z[i] = x0;
        }
        acc_x = SQRT(n2);
    }
    if (xi < W) {
        contrib[yi * W + xi] = acc_x;
        contrib[W * H + yi * W + xi] = acc_y;
    }
}
