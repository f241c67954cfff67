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
// Rolling state entering row t (the IST estimate of row t is written at step t):
//   va = v(t), vb = v(t+1);  p1a = first dual at t;  da = div(first dual) at t;
//   p2m = second dual at t-1 (its y component only is needed).
// Step t loads v(t+2), forms the first dual at t+1 and its divergence, the second dual at t,
// and x_ist(t) = v(t) - div(second dual)(t) / lam. The strip starts two rows early; what those
// warm-up rows compute from the missing rows above is never used for a stored row (the first
// stored row only needs the second dual one row up, which is complete). Rows outside the
// image load 0 and their differences are masked, as the reference's boundary rule says.
//
// float32 only (the backend uses it for float32 on CPU devices, NC = 1, 2 inner iterations,
// widths of at least 16; ceil(W / 12) work-items per row).

#ifndef REAL_IS_DOUBLE
#define DT 0.25f
#define OUT_W 12  // output columns per work-item: window lanes HALO .. HALO + OUT_W - 1
#define HALO 2    // window = columns [x0 - HALO, x0 + OUT_W + HALO)

// Vector helpers. On PoCL (CLFZA_CLANG_BUILTINS, common.cl) as clang vector built-ins and
// plain operators: PoCL 3.0 from pip did not inline shuffle, vload16, vstore8, select, sqrt or
// min into this kernel ("conflicting attributes"), and each lane shift or load became a call
// (2.9x slower at 512^2, 3.3x at 2048^2 on a 2-core Xeon). Elsewhere the portable OpenCL
// built-ins. Same results bit for bit:
// lane moves, loads and stores, a select, and IEEE sqrt per lane.
#ifdef CLFZA_CLANG_BUILTINS
// 4-byte aligned vectors: loads/stores at any float address (vload16/vstore8 semantics)
typedef float16 __attribute__((aligned(4))) float16_u;
typedef float8 __attribute__((aligned(4))) float8_u;
#define LOAD16(p) (*(const float16_u *)(p))
#define LOAD16G(p) (*(__global const float16_u *)(p))
typedef float4 __attribute__((aligned(4))) float4_u;
#define STORE8G(v, p) (*(__global float8_u *)(p) = (v))
#define STORE4G(v, p) (*(__global float4_u *)(p) = (v))
#define STORE16P(v, p) (*(float16_u *)(p) = (v))
#define SEL16(a, b, m) ((m) ? (b) : (a))  // select(a, b, m), m a comparison's -1/0 lanes
#define SHIFT_LEFT(a) __builtin_shufflevector(a, a, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, \
                                              14, 15, 15)
#define SHIFT_RIGHT(a) __builtin_shufflevector(a, a, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, \
                                               12, 13, 14)
#define IMIN(a, b) ((a) < (b) ? (a) : (b))
// per lane (clang 14 has no vector sqrt built-in). Where the library does inline (PoCL 3.1)
// this measured ~7% slower on this kernel than sqrt(float16) (2048^2: 11.9 -> 12.7 ms; ~1.5%
// of a TwIST iteration), against 2.7x faster on pip's PoCL 3.0.
inline float16 sqrt16(const float16 a)
{
    return (float16)(__builtin_sqrtf(a.s0), __builtin_sqrtf(a.s1), __builtin_sqrtf(a.s2),
                     __builtin_sqrtf(a.s3), __builtin_sqrtf(a.s4), __builtin_sqrtf(a.s5),
                     __builtin_sqrtf(a.s6), __builtin_sqrtf(a.s7), __builtin_sqrtf(a.s8),
                     __builtin_sqrtf(a.s9), __builtin_sqrtf(a.sa), __builtin_sqrtf(a.sb),
                     __builtin_sqrtf(a.sc), __builtin_sqrtf(a.sd), __builtin_sqrtf(a.se),
                     __builtin_sqrtf(a.sf));
}
#else
#define LOAD16(p) vload16(0, p)
#define LOAD16G(p) vload16(0, p)
#define STORE8G(v, p) vstore8(v, 0, p)
#define STORE4G(v, p) vstore4(v, 0, p)
#define STORE16P(v, p) vstore16(v, 0, p)
#define SEL16(a, b, m) select(a, b, m)
#define SHIFT_LEFT(a) shuffle(a, (uint16)(1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 15))
#define SHIFT_RIGHT(a) shuffle(a, (uint16)(0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14))
#define IMIN(a, b) min(a, b)
#define sqrt16(a) sqrt(a)
#endif

inline float16 shift_left(const float16 a)   // a[x + 1] (lane 15 repeats: never used)
{
    return SHIFT_LEFT(a);
}

inline float16 shift_right(const float16 a)  // a[x - 1] (lane 0 repeats: never used)
{
    return SHIFT_RIGHT(a);
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
                               __global const float *g, const float s, const float lam,
                               const int strip, const int W, const int H)
{
    const int x0 = get_global_id(0) * OUT_W;
    const int y0 = get_global_id(1) * strip;
    const int y1 = IMIN(y0 + strip, H);
    const int16 col = (int16)(x0 - HALO) + (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13,
                                                   14, 15);
    const int16 hl = col > (int16)(0);         // has a left neighbour
    const int16 hr = col < (int16)(W - 1);     // has a right neighbour
    const float16 zero = (float16)(0.0f);
    const float ilam = 1.0f / lam;  // one vector division less per row (of three)

    float16 va = load_v(x, g, s, y0 - 2, x0, W, H);
    float16 vb = load_v(x, g, s, y0 - 1, x0, W, H);
    // first dual at y0 - 2 (its row below is vb)
    float16 p1a_x, p1a_y;
    {
        const float16 z0 = -lam * va;
        const float16 z1 = SEL16(zero, -lam * shift_left(va) - z0, hr);
        const float16 z2 = (y0 - 2 < H - 1) ? -lam * vb - z0 : zero;
        const float16 rden = 1.0f / (1.0f + DT * sqrt16(z1 * z1 + z2 * z2));
        p1a_x = DT * z1 * rden;
        p1a_y = DT * z2 * rden;
    }
    float16 da = zero, p2m_y = zero;

    for (int t = y0 - 2; t < y1; ++t) {
        const float16 vc = load_v(x, g, s, t + 2, x0, W, H);
        // first dual at t + 1 (from the zero dual: z = -lam v)
        float16 p1b_x, p1b_y;
        {
            const float16 z0 = -lam * vb;
            const float16 z1 = SEL16(zero, -lam * shift_left(vb) - z0, hr);
            const float16 z2 = (t + 1 < H - 1) ? -lam * vc - z0 : zero;
            const float16 rden = 1.0f / (1.0f + DT * sqrt16(z1 * z1 + z2 * z2));
            p1b_x = DT * z1 * rden;
            p1b_y = DT * z2 * rden;
        }
        // its divergence at t + 1
        const float16 db = SEL16(zero, p1b_x - shift_right(p1b_x), hl)
                           + ((t + 1 > 0) ? p1b_y - p1a_y : zero);
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
                float buf[16];
                STORE16P(u, buf);
                for (int k = 0; k < W - x0; ++k)
                    o[k] = buf[HALO + k];
            }
        }
        va = vb;
        vb = vc;
        p1a_x = p1b_x;
        p1a_y = p1b_y;
        da = db;
        p2m_y = p2_y;
    }
}
#endif
