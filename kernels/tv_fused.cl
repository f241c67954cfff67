// Paper mode's TV prox in one pass for CPU devices: x_ist = Psi(x + s g) with exactly two
// Chambolle iterations from a zero dual (docs/design.md s.2: tvdenoise(v, 2/th, 2), the simulation
// setting), without storing the dual.
//
// Why a separate kernel: unfused, the prox is three kernels and 15 array passes
// (chambolle_first, chambolle_step, chambolle_finish in tv.cl; ~11 ms at 2048^2 on a 2-core
// CPU). Fusing them needs each pixel's neighbours' intermediate values. Two fusions that rely
// on PoCL's implicit vectoriser were measured and dropped: a local-memory tile with barriers
// (50-73 ms: PoCL does not vectorise work-item loops split by barriers) and recomputing the
// neighbours' duals per pixel (8.6 ms for the last step alone: three dual updates per pixel).
// Here the vectorisation is explicit instead: a work-item owns 12 output columns and walks
// down a strip of rows, holding a 16-wide window of columns (2 halo columns on each side) in
// float16 vectors. Vertical neighbours come from the rows it already holds (a rolling
// window), horizontal ones from lane shifts. A quarter of the lanes are halo, so each dual
// update is computed 4/3 times per output pixel, at full SIMD width, with no stores but
// x_ist: 2 array reads and 1 write. The kernel is bound by its two sqrt and two divisions per
// window row (16 lanes), so the halo is as narrow as the dependencies allow: an output lane
// needs the second dual one lane left, which needs the first dual's divergence one lane
// right, which needs the first dual one lane left, which needs v one lane right: lanes
// 2..13 of a window are complete. (The first version kept 4 halo lanes and 8 outputs: 1.5x
// the arithmetic per output pixel.)
// Also measured and dropped: doing TwIST's two-step combination and its TV sums in the same
// pass (twist_combine's work, 4.7 ms on its own) saved only 1.5 ms of a 35 ms iteration.
//
// Reference boundary rules (tv.cl): gradient forward, 0 at the last column/row; divergence
// p[x] - p[x-1] with the first column/row taking 0 for its missing difference; computed in
// global coordinates through lane masks, so tiles and strips change nothing.
//
// Rolling state entering step t (the IST estimate of row t is written at step t):
//   va, vb, vc = v(t), v(t+1), v(t+2);  p1a, p1b = first dual at t, t+1;
//   da, db = div(first dual) at t, t+1;  p2m = second dual at t-1 (its y component only).
// Step t loads v(t+3), forms the first dual at t+2 and its divergence (one chain) and the
// second dual at t and x_ist(t) = v(t) - div(second dual)(t) / lam (another, independent of
// the first: each ends in a sqrt and a division, whose latency bound the unskewed step; 0.25 ->
// 0.23 ms at 512^2 on Intel's runtime, 0.107 -> 0.091 ms at 256^2 on both PoCLs, same-run A/B
// on a 2-core Xeon). The strip starts three rows early; what those warm-up rows compute from
// the missing rows above is never used for a stored row (the first stored row needs the
// second dual one row up, which needs the first dual's divergence there, which is complete).
// Rows outside the image load 0 and their differences are masked, as the reference's
// boundary rule says.
//
// float32 only (the backend uses it for float32 on CPU devices, NC = 1, 2 inner iterations,
// widths of at least 16; ceil(W / 12) work-items per row).

#ifndef REAL_IS_DOUBLE
#define DT 0.25f
#define OUT_W 12  // output columns per work-item: window lanes HALO .. HALO + OUT_W - 1
#define HALO 2    // window = columns [x0 - HALO, x0 + OUT_W + HALO)

// Vector helpers (LOAD16, STORE8G, SEL16, SHIFT_LEFT, sqrt16, ...): common.cl.

inline float16 shift_left(const float16 a)   // a[x + 1] (lane 15 repeats: never used)
{
    return SHIFT_LEFT(a);
}

inline float16 shift_right(const float16 a)  // a[x - 1] (lane 0 repeats: never used)
{
    return SHIFT_RIGHT(a);
}

// Software prefetch of row t of a 16-lane window (its first and last cache line) when t lies
// in the image; rows are P floats apart (the array's row pitch). A strip walks down rows with
// one or two cache lines per row and array: at 2048^2 every row is a new 4 KB page, where the
// hardware's stream prefetchers do not follow, so each row's loads waited for memory (the
// one-pass FGP moved ~7 GB/s after a cache flush). The distance (rows ahead, 0 = none) and
// whether the stored rows are prefetched too are tuned per device (clfza.cl.tuning:
// prox_prefetch, fgp_prefetch).
inline void prefetch_row(__global const float *a, const int t, const int c0, const int W,
                         const int H, const int P)
{
    if (t < 0 || t >= H)
        return;
    const size_t row = (size_t)t * P;
    PREFETCH_LINE(a + row + (c0 > 0 ? c0 : 0));
    PREFETCH_LINE(a + row + (c0 + 15 < W ? c0 + 15 : W - 1));
}

// v = x + s g on row t over the window; 0 outside the image.
inline float16 load_v(__global const float *x, __global const float *g, const float s,
                      const int t, const int x0, const int W, const int H)
{
    if (t < 0 || t >= H)
        return (float16)(0.0f);
    const int c0 = x0 - HALO;
    const size_t row = (size_t)t * W;
    if (c0 >= 0 && c0 + 16 <= W)
        return LOAD16G(x + row + c0) + s * LOAD16G(g + row + c0);
    float buf[16];
    for (int k = 0; k < 16; ++k) {
        const int c = c0 + k;
        buf[k] = (c >= 0 && c < W) ? x[row + c] + s * g[row + c] : 0.0f;
    }
    return LOAD16(buf);
}

__kernel void chambolle2_fused(__global float *out, __global const float *x,
                               __global const float *g, float s, float lam,
                               const int strip, const int pf, const int pfw,
                               __global const float *fpar, const int W, const int H)
{
    // a batch of frames (reduce.cl, above frame_image; tv.cl's CHAMBOLLE_FRAME): the frame's
    // arrays, its step s and lam times its FPAR_MU and FPAR_THR factors (1 for one frame);
    // a frame whose FPAR_ACTIVE is 0 returns at once
    __global const float *fp = frame_par(fpar);
    if (fp[FPAR_ACTIVE] == 0.0f) return;
    s *= fp[FPAR_MU];
    lam *= fp[FPAR_THR];
    {
        const size_t fo = frame_image(W, H);
        out += fo;
        x += fo;
        g += fo;
    }
    const int x0 = get_global_id(0) * OUT_W;
    const int y0 = get_global_id(1) * strip;
    const int y1 = IMIN(y0 + strip, H);
    const int16 col = (int16)(x0 - HALO) + (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13,
                                                   14, 15);
    const int16 hl = col > (int16)(0);         // has a left neighbour
    const int16 hr = col < (int16)(W - 1);     // has a right neighbour
    const float16 zero = (float16)(0.0f);
    const float ilam = 1.0f / lam;  // one vector division less per row (of three)

    // skewed (see the FGP kernel below): step t forms the first dual at t + 2 and its
    // divergence (one chain) and the second dual and x_ist at t (another) from rows earlier
    // steps formed. Entering step t: v(t .. t+2), first dual at t and t + 1, its divergence
    // at t and t + 1, the second dual's y at t - 1.
    const int t0 = y0 - 3;
    float16 va = load_v(x, g, s, t0, x0, W, H);
    float16 vb = load_v(x, g, s, t0 + 1, x0, W, H);
    float16 vc = load_v(x, g, s, t0 + 2, x0, W, H);
    // first dual at t0 + 1 (its row below is vc); at t0 it is never used for a stored row
    float16 p1a_x = zero, p1a_y = zero, p1b_x, p1b_y;
    {
        const float16 z0 = -lam * vb;
        const float16 z1 = SEL16(zero, -lam * shift_left(vb) - z0, hr);
        const float16 z2 = (t0 + 1 < H - 1) ? -lam * vc - z0 : zero;
        const float16 rden = 1.0f / (1.0f + DT * sqrt16(z1 * z1 + z2 * z2));
        p1b_x = DT * z1 * rden;
        p1b_y = DT * z2 * rden;
    }
    float16 da = zero, db = zero, p2m_y = zero;

    for (int t = t0; t < y1; ++t) {
        if (pf > 0) {  // the rows loaded (and with pfw stored) pf steps from now
            prefetch_row(x, t + 3 + pf, x0 - HALO, W, H, W);
            prefetch_row(g, t + 3 + pf, x0 - HALO, W, H, W);
            if (pfw)
                prefetch_row(out, t + pf, x0, W, H, W);
        }
        const float16 vd = load_v(x, g, s, t + 3, x0, W, H);
        // first dual at t + 2 (from the zero dual: z = -lam v) and its divergence
        float16 p1c_x, p1c_y;
        {
            const float16 z0 = -lam * vc;
            const float16 z1 = SEL16(zero, -lam * shift_left(vc) - z0, hr);
            const float16 z2 = (t + 2 < H - 1) ? -lam * vd - z0 : zero;
            const float16 rden = 1.0f / (1.0f + DT * sqrt16(z1 * z1 + z2 * z2));
            p1c_x = DT * z1 * rden;
            p1c_y = DT * z2 * rden;
        }
        const float16 dc = SEL16(zero, p1c_x - shift_right(p1c_x), hl)
                           + ((t + 2 > 0) ? p1c_y - p1b_y : zero);
        // second dual at t: z = div p - lam v
        float16 p2_x, p2_y;
        {
            const float16 z0 = da - lam * va;
            const float16 z1 = SEL16(zero, shift_left(da) - lam * shift_left(va) - z0, hr);
            const float16 z2 = (t < H - 1) ? db - lam * vb - z0 : zero;
            const float16 rden = 1.0f / (1.0f + DT * sqrt16(z1 * z1 + z2 * z2));
            p2_x = (p1a_x + DT * z1) * rden;
            p2_y = (p1a_y + DT * z2) * rden;
        }
        if (t >= y0) {
            const float16 dv = SEL16(zero, p2_x - shift_right(p2_x), hl)
                               + ((t > 0) ? p2_y - p2m_y : zero);
            const float16 u = va - dv * ilam;
            __global float *o = out + (size_t)t * W + x0;
            if (x0 + OUT_W <= W) {
                STORE8G(u.s23456789, o);
                STORE4G(u.sabcd, o + 8);
            } else {  // the last work-item of a row: W - x0 < OUT_W columns
                store_tail(o, u, HALO, W - x0);
            }
        }
        va = vb;
        vb = vc;
        vc = vd;
        p1a_x = p1b_x;
        p1a_y = p1b_y;
        p1b_x = p1c_x;
        p1b_y = p1c_y;
        da = db;
        db = dc;
        p2m_y = p2_y;
    }
}

// ---------------------------------------------------------------------------------------------
// FISTA's TV prox in one pass for CPU devices: FGP (Beck & Teboulle 2009; tv.cl's fgp_step and
// fgp_finish, the reference's periodic differences) with exactly 2 inner iterations from the
// warm dual p0, its result z = P_C(b - wt D^T p2) and the sums (TV(z), ||z||_1):
//   p1 = P_ball(p0 + D x(p0) / (8 wt)),  p2 = P_ball(p1 + D x(p1) / (8 wt))  (the first step's
//   momentum is 0, so the second reads p1 itself), x(p) = P_C(b - wt D^T p),
//   D x = (x - x[c-1], x - x[r-1]), D^T d = d1 - d1[c+1] + d2 - d2[r+1], all wrapped.
// Split, that is 3 kernels and 14.5 array passes (fgp_prox 11-19 ms at 2048^2 on a 2-core
// Xeon); here b and p0 are read once and p2 and z written once: 6 passes.
//
// The same layout as chambolle2_fused: a work-item walks down a strip of rows holding a 16-lane
// window of columns in float16 vectors (rows from a rolling window, columns from lane shifts).
// z's TV at a lane needs z one lane left, z needs p2 one lane right, p2 needs x(p1) one lane
// left, x(p1) needs p1 one lane right, p1 needs x(p0) one lane left, x(p0) needs p0 one lane
// right: 3 halo lanes each side, 10 output columns. Periodic boundaries make every loaded lane
// valid: rows and columns are taken mod H and W (a window over an edge loads lane by lane).
// Rows: z at row t needs p2 at t and t + 1, p2 at t + 1 needs x(p1) at t and t + 1 and p1 at
// t + 1 and t + 2, p1 at t + 2 needs x(p0) at t + 1 and t + 2, x(p0) at t + 2 needs p0 at
// t + 2 and t + 3; and TV needs z at t - 1. Done row by row in that order, each step is one
// chain of five dependent stages, each ending in a sqrt and a division (or feeding one): the
// kernel was bound by their latency, not by memory (the same time per pixel at 128^2 and
// 2048^2; removing the sqrt and divisions, for timing only, took 26-34 % off). So the stages
// run skewed, as three independent chains per step: step t loads p0 at t + 4 and b at t + 3
// and forms x(p0)(t+3), p1(t+3) | x(p1)(t+1), p2(t+1) | z(t-1) from rows earlier steps formed
// (the first dual two rows ahead of the second, z one row behind). Measured against the
// unskewed step on a 2-core Xeon at 512^2: 0.48 -> 0.42 ms on Intel's runtime, 0.51 -> 0.41 on
// PoCL 3.1, 0.54 -> 0.41 on PoCL 3.0 (same-run A/B; two windows per work-item, the other way to
// get independent chains, was slower). A strip starts 7 rows early, so that the first stored
// row's chains are complete (the warm-up rows start from zeros and are not stored), and runs
// one step past its last row.
//
// Outputs: z, the new dual (qx, qy; not p0's buffers: neighbouring strips still read p0), and
// per work-item partial sums of TV(z) and |z| over its own columns (contrib[wid] and
// contrib[nwi + wid]). float32, one channel, 2 inner iterations.
//
// The dual's rows are PQ >= W floats apart (the backend's dual_pitch: W + 16 when W is a
// multiple of 256). A strip reads and writes the same columns of ~135 consecutive rows; with a
// row pitch of 8 KB (W = 2048) those lines fall in 16 of the L2's 2048 sets, get evicted before
// the neighbouring strip (the work-item to the right, sharing half of each line) reads them,
// and each line is fetched and, partly written, owned twice. Padding the four dual arrays
// (the kernel's other two, b and z, are the solver's and the FFT's, at pitch W): fgp2_fused at
// 2048^2 12.0-12.8 -> 10.0-10.4 ms on a 2-core Xeon (Intel's runtime, both PoCLs); all six
// padded would give 9.0-9.9. At 512^2 and 1024^2 within noise.
#define FGP_OUT_W 10
#define FGP_HALO 3
#define FGP_SUM_ROWS 16  // rows per first-level partial sum

// a row of the window, periodic: rows and columns mod H and W
inline float16 load_per(__global const float *a, const int t, const int c0, const int W,
                        const int H, const int P)
{
    // t lies in [-8, H + 5) and the window in [-FGP_HALO, W + 16): wrapping by one period is
    // enough (the integer divisions of t % H and c % W, per row and per lane of the edge
    // windows, took ~10% of the kernel at 512^2)
    int r = t < 0 ? t + H : (t >= H ? t - H : t);
    if (r < 0 || r >= H) {  // H < 8: more than one period away
        r = t % H;
        r = r < 0 ? r + H : r;
    }
    const size_t row = (size_t)r * P;
    if (c0 >= 0 && c0 + 16 <= W)
        return LOAD16G(a + row + c0);
    float buf[16];
    for (int k = 0; k < 16; ++k) {
        const int c = c0 + k;
        buf[k] = a[row + (c < 0 ? c + W : (c >= W ? c - W : c))];
    }
    return LOAD16(buf);
}

// x(p) on a row: P_C(b - wt (px - px[c+1] + py - py[r+1]))
inline float16 fgp_x16(const float16 b, const float16 px, const float16 py,
                       const float16 py_below, const float wt, const int nonneg)
{
    const float16 v = b - wt * (px - shift_left(px) + py - py_below);
    return nonneg ? SEL16(v, (float16)(0.0f), v < (float16)(0.0f)) : v;
}

// one FGP dual step on a row: P_ball(p + k D x), D x = (x - x[c-1], x - x[r-1]), k = 1/(8 wt)
inline void fgp_p16(float16 *qx, float16 *qy, const float16 px, const float16 py,
                    const float16 x, const float16 x_above, const float k)
{
    const float16 a1 = px + k * (x - shift_right(x));
    const float16 a2 = py + k * (x - x_above);
    const float16 n = sqrt16(a1 * a1 + a2 * a2);
    const float16 sc = 1.0f / SEL16(n, (float16)(1.0f), n < (float16)(1.0f));
    *qx = a1 * sc;
    *qy = a2 * sc;
}

// lanes FGP_HALO .. FGP_HALO + 9 of v to columns x0 .. x0 + 9 of a row (those < W)
inline void store10(__global float *o, const float16 v, const int x0, const int W)
{
    if (x0 + FGP_OUT_W <= W) {
        STORE8G(v.s3456789a, o);
        STORE2G(v.sbc, o + 8);
    } else {
        store_tail(o, v, FGP_HALO, W - x0);
    }
}

__kernel void fgp2_fused(__global float *z, __global float *qx, __global float *qy,
                         __global const float *b, __global const float *p0x,
                         __global const float *p0y, float wt, const int nonneg,
                         const int strip, const int pf, const int pfw,
                         __global const float *fpar, __global float *contrib, const int W,
                         const int H, const int PQ)
{
    // a batch of frames (reduce.cl, above frame_image): the frame's arrays, its weight wt
    // times its threshold factor (1 for one frame); a stopped frame returns at once
    __global const float *fp = frame_par(fpar);
    if (fp[FPAR_ACTIVE] == 0.0f) return;
    wt *= fp[FPAR_THR];
    {
        const size_t fo = frame_image(W, H), fq = get_global_id(2) * (size_t)H * PQ;
        z += fo;
        b += fo;
        qx += fq;
        qy += fq;
        p0x += fq;
        p0y += fq;
        contrib += frame_contrib(2);
    }
    const int gx = get_global_id(0), gy = get_global_id(1);
    const int wid = gy * get_global_size(0) + gx;
    const int nwi = get_global_size(0) * get_global_size(1);
    const int x0 = gx * FGP_OUT_W;
    const int c0 = x0 - FGP_HALO;
    const int y0 = gy * strip;
    const int y1 = IMIN(y0 + strip, H);
    const float k = 1.0f / (8.0f * wt);
    const int16 lane = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const int16 own = (lane >= (int16)(FGP_HALO)) & (lane < (int16)(FGP_HALO + FGP_OUT_W))
                      & (lane + (int16)(c0) < (int16)(W));
    const float16 zero = (float16)(0.0f);
    const int s = y0 - 7;
    // entering step t: p0(t+3), b(t-1 .. t+2), x(p0)(t+2), p1(t+1), p1(t+2), x(p1)(t),
    // p2(t-1), p2(t), z(t-2)
    float16 P0x = load_per(p0x, s + 3, c0, W, H, PQ), P0y = load_per(p0y, s + 3, c0, W, H, PQ);
    float16 Bm = load_per(b, s - 1, c0, W, H, W), Bt = load_per(b, s, c0, W, H, W);
    float16 Bt1 = load_per(b, s + 1, c0, W, H, W), Bt2 = load_per(b, s + 2, c0, W, H, W);
    float16 X0 = zero, P1ax = zero, P1ay = zero, P1bx = zero, P1by = zero, X1 = zero;
    float16 P2ax = zero, P2ay = zero, P2bx = zero, P2by = zero, Zp = zero;
    // the sums in two levels: rows into acc (at most FGP_SUM_ROWS), acc into tot, so that a
    // float32 partial sum's rounding does not grow with the strip height. FISTA's monotone
    // test compares objectives built from them, and near convergence it flips on differences
    // at that level: strips of 128 rows summed in one level moved the stress report's
    // 1000-iteration float32 FISTA run (256^2) 0.0076 dB from float64, against 3e-6 dB for
    // strips of 32 rows, the split kernels, and 128 rows summed in two levels
    float16 acc_tv = zero, acc_l1 = zero, tot_tv = zero, tot_l1 = zero;
    for (int t = s; t <= y1; ++t) {
        if (pf > 0) {  // the rows loaded (and with pfw stored) pf steps from now; not wrapped
            prefetch_row(p0x, t + 4 + pf, c0, W, H, PQ);
            prefetch_row(p0y, t + 4 + pf, c0, W, H, PQ);
            prefetch_row(b, t + 3 + pf, c0, W, H, W);
            if (pfw) {
                prefetch_row(z, t - 1 + pf, x0, W, H, W);
                prefetch_row(qx, t - 1 + pf, x0, W, H, PQ);
                prefetch_row(qy, t - 1 + pf, x0, W, H, PQ);
            }
        }
        const float16 P0nx = load_per(p0x, t + 4, c0, W, H, PQ);
        const float16 P0ny = load_per(p0y, t + 4, c0, W, H, PQ);
        const float16 Bt3 = load_per(b, t + 3, c0, W, H, W);
        // three independent chains: the first dual two rows ahead of the second, z one behind
        const float16 X0n = fgp_x16(Bt3, P0x, P0y, P0ny, wt, nonneg);      // x(p0)(t+3)
        float16 P1nx, P1ny, P2nx, P2ny;
        fgp_p16(&P1nx, &P1ny, P0x, P0y, X0n, X0, k);                      // p1(t+3)
        const float16 X1n = fgp_x16(Bt1, P1ax, P1ay, P1by, wt, nonneg);   // x(p1)(t+1)
        fgp_p16(&P2nx, &P2ny, P1ax, P1ay, X1n, X1, k);                    // p2(t+1)
        const float16 Z = fgp_x16(Bm, P2ax, P2ay, P2by, wt, nonneg);      // z(t-1)
        if (t > y0) {
            const size_t rq = (size_t)(t - 1) * PQ + x0;
            store10(qx + rq, P2ax, x0, W);
            store10(qy + rq, P2ay, x0, W);
            store10(z + (size_t)(t - 1) * W + x0, Z, x0, W);
            const float16 dx = Z - shift_right(Z), dy = Z - Zp;
            acc_tv += SEL16(zero, sqrt16(dx * dx + dy * dy), own);
            acc_l1 += SEL16(zero, SEL16(Z, -Z, Z < zero), own);
            if ((t - y0) % FGP_SUM_ROWS == 0) {
                tot_tv += acc_tv;
                tot_l1 += acc_l1;
                acc_tv = zero;
                acc_l1 = zero;
            }
        }
        P0x = P0nx;
        P0y = P0ny;
        X0 = X0n;
        P1ax = P1bx;
        P1ay = P1by;
        P1bx = P1nx;
        P1by = P1ny;
        X1 = X1n;
        P2ax = P2bx;
        P2ay = P2by;
        P2bx = P2nx;
        P2by = P2ny;
        Zp = Z;
        Bm = Bt;
        Bt = Bt1;
        Bt1 = Bt2;
        Bt2 = Bt3;
    }
    contrib[wid] = hsum16(tot_tv + acc_tv);
    contrib[nwi + wid] = hsum16(tot_l1 + acc_l1);
}
#endif
