// Batched 1-D complex FFTs (Stockham autosort, radix 2/4/8 and 3/5/7), real-to-complex and
// complex-to-real through the half-length complex packing, and Bluestein helpers.
//
// Layout: a batch of `nb` lines of length `n`; element i of line b sits at b*bs + i*es
// (in complex elements). Rows of a C-ordered (ny, nx) array: es = 1, bs = nx; its columns:
// es = nx, bs = 1. Kernels with a plane stride `ps` also take a stack of such batches (the
// columns of a (P, ny, nx) array: plane p at p*ps) as one more global dimension, so that
// P planes cost one launch per pass, not P; launched without that dimension, p = 0.
//
// Stockham pass (radix R, Ns = product of the radices already applied), butterfly j < n/R:
//     k = j % Ns;   v[r] = src[j + r*n/R] * w^(k*r*(n/(Ns*R)))   (w = exp(sign*2*pi*i/n))
//     v = DFT_R(v); dst[(j - k)*R + k + r*Ns] = v[r]
// The twiddle table tw[m] = exp(sign*2*pi*i*m/n), m < n, is computed on the host in float64
// (no accumulated rotation error); the index k*r*(n/(Ns*R)) is < n.
//
// The global-memory kernels take every size as an argument, so one program per dtype serves
// every plan (PoCL's cold builds cost ~0.6 s each); the local-memory line kernels (LOCAL_N
// below) are compiled once per line length and dtype.

// Buffers are passed as real pointers holding interleaved (re, im) pairs; LD/ST move one
// complex value between memory and a pair of scalars.

#define LD(p, i, re, im) { const real2 _v = vload2((i), (p)); re = _v.x; im = _v.y; }
#define ST(p, i, re, im) vstore2((real2)((re), (im)), (i), (p))
// (ar, ai) *= (br, bi)
#define CMULI(ar, ai, br, bi) { const real _t = (ar) * (br) - (ai) * (bi); \
                                (ai) = (ar) * (bi) + (ai) * (br); (ar) = _t; }

#define C8 ((real)0.70710678118654752440)

// ---------------------------------------------------------------------------------------------
// Small DFTs on private arrays (in place, natural order in and out); s = -1 forward, +1
// inverse. These use real2 arithmetic: on PoCL the scalar re/im form made the global passes
// 1.7x slower (it partly vectorised across work-items with gathers), and GPU compilers
// scalarise real2 anyway.

#define CMUL(a, b) ((real2)((a).x * (b).x - (a).y * (b).y, (a).x * (b).y + (a).y * (b).x))
#define CONJ(a) ((real2)((a).x, -(a).y))
// multiply by s*i (s = +-1): -i for the forward transform, +i for the inverse
#define ROT(a, s) ((real2)(-(s) * (a).y, (s) * (a).x))

inline void bfly2(real2 *v, const real s)
{
    const real2 a = v[0], b = v[1];
    v[0] = a + b;
    v[1] = a - b;
}

inline void bfly4(real2 *v, const real s)
{
    const real2 t0 = v[0] + v[2], t1 = v[0] - v[2];
    const real2 t2 = v[1] + v[3], t3 = ROT(v[1] - v[3], s);
    v[0] = t0 + t2;
    v[1] = t1 + t3;
    v[2] = t0 - t2;
    v[3] = t1 - t3;
}

inline void bfly8(real2 *v, const real s)
{
    // even/odd radix-4 halves, then combine with w8^k, w8 = C8 (1 + s i)
    real2 e[4] = {v[0], v[2], v[4], v[6]};
    real2 o[4] = {v[1], v[3], v[5], v[7]};
    bfly4(e, s);
    bfly4(o, s);
    const real2 o1 = C8 * (real2)(o[1].x - s * o[1].y, o[1].y + s * o[1].x);   // w8 o1
    const real2 o2 = ROT(o[2], s);                                              // w8^2 o2
    const real2 u = ROT(o[3], s);
    const real2 o3 = C8 * (real2)(u.x - s * u.y, u.y + s * u.x);                // w8^3 o3
    v[0] = e[0] + o[0];
    v[4] = e[0] - o[0];
    v[1] = e[1] + o1;
    v[5] = e[1] - o1;
    v[2] = e[2] + o2;
    v[6] = e[2] - o2;
    v[3] = e[3] + o3;
    v[7] = e[3] - o3;
}

// Odd radix R: y[k] = x0 + sum_r (x_r + x_{R-r}) cos(2 pi r k / R)
//                         + s*i * sum_r (x_r - x_{R-r}) sin(2 pi r k / R),  r = 1..(R-1)/2
inline void bfly3(real2 *v, const real s)
{
    const real c1 = (real)-0.5, s1 = (real)0.86602540378443864676;
    const real2 a = v[1] + v[2], b = v[1] - v[2];
    const real2 m = v[0] + c1 * a;
    const real2 t = ROT(b, s) * s1;
    v[0] = v[0] + a;
    v[1] = m + t;
    v[2] = m - t;
}

inline void bfly5(real2 *v, const real s)
{
    const real c1 = (real)0.30901699437494742410, c2 = (real)-0.80901699437494742410;
    const real s1 = (real)0.95105651629515357212, s2 = (real)0.58778525229247312917;
    const real2 a1 = v[1] + v[4], b1 = v[1] - v[4];
    const real2 a2 = v[2] + v[3], b2 = v[2] - v[3];
    const real2 x0 = v[0];
    const real2 m1 = x0 + c1 * a1 + c2 * a2;
    const real2 m2 = x0 + c2 * a1 + c1 * a2;
    const real2 t1 = ROT(s1 * b1 + s2 * b2, s);
    const real2 t2 = ROT(s2 * b1 - s1 * b2, s);
    v[0] = x0 + a1 + a2;
    v[1] = m1 + t1;
    v[4] = m1 - t1;
    v[2] = m2 + t2;
    v[3] = m2 - t2;
}

inline void bfly7(real2 *v, const real s)
{
    const real c1 = (real)0.62348980185873353053, c2 = (real)-0.22252093395631440429,
               c3 = (real)-0.90096886790241912624;
    const real s1 = (real)0.78183148246802980871, s2 = (real)0.97492791218182360702,
               s3 = (real)0.43388373911755812048;
    const real2 a1 = v[1] + v[6], b1 = v[1] - v[6];
    const real2 a2 = v[2] + v[5], b2 = v[2] - v[5];
    const real2 a3 = v[3] + v[4], b3 = v[3] - v[4];
    const real2 x0 = v[0];
    // cos(2 pi r k/7) for k = 1, 2, 3: (c1 c2 c3), (c2 c3 c1), (c3 c1 c2)
    const real2 m1 = x0 + c1 * a1 + c2 * a2 + c3 * a3;
    const real2 m2 = x0 + c2 * a1 + c3 * a2 + c1 * a3;
    const real2 m3 = x0 + c3 * a1 + c1 * a2 + c2 * a3;
    // sin(2 pi r k/7): (s1 s2 s3), (s2 -s3 -s1), (s3 -s1 s2)
    const real2 t1 = ROT(s1 * b1 + s2 * b2 + s3 * b3, s);
    const real2 t2 = ROT(s2 * b1 - s3 * b2 - s1 * b3, s);
    const real2 t3 = ROT(s3 * b1 - s1 * b2 + s2 * b3, s);
    v[0] = x0 + a1 + a2 + a3;
    v[1] = m1 + t1;
    v[6] = m1 - t1;
    v[2] = m2 + t2;
    v[5] = m2 - t2;
    v[3] = m3 + t3;
    v[4] = m3 - t3;
}

// ---------------------------------------------------------------------------------------------
// Half-length packing of real rows (length 2m read as m complex values).
// Forward, twh[k] = exp(-2 pi i k / (2m)), k <= m:
//   Z = FFT_m(z),  E = (Z[k] + conj Z[m-k]) / 2,  O = -i (Z[k] - conj Z[m-k]) / 2,
//   X[k] = E + twh[k] O.
#define R2C_COMBINE(zr, zi, cr, ci, tr, ti, outr, outi)                                         \
    {   /* (zr, zi) = Z[k], (cr, ci) = Z[m-k] */                                              \
        const real er = (real)0.5 * ((zr) + (cr)), ei = (real)0.5 * ((zi) - (ci));             \
        const real dr = (real)0.5 * ((zr) - (cr)), di = (real)0.5 * ((zi) + (ci));             \
        /* o = -i d */                                                                        \
        const real or_ = di, oi = -dr;                                                        \
        outr = er + (tr) * or_ - (ti) * oi;                                                   \
        outi = ei + (tr) * oi + (ti) * or_;                                                   \
    }

// Inverse: E = X[k] + conj X[m-k],  O = (X[k] - conj X[m-k]) conj(twh[k]),  Z = E + i O,
//   z = IFFT_m(Z) unnormalised (the caller's scale holds 1/(2m) and any other factor).
// Like numpy/pocketfft the imaginary parts of X[0] and X[m] are ignored.
#define C2R_COMBINE(row, k, m, tr, ti, outr, outi)                                              \
    {                                                                                           \
        real xr, xi, cr, ci;                                                                    \
        LD(row, k, xr, xi);                                                                     \
        LD(row, (m) - (k), cr, ci);                                                             \
        ci = -ci;                                                                               \
        if ((k) == 0) { xi = 0; ci = 0; }                                                       \
        const real er = xr + cr, ei = xi + ci;                                                  \
        const real dr = xr - cr, di = xi - ci;                                                  \
        const real or_ = dr * (tr) + di * (ti), oi = di * (tr) - dr * (ti);                     \
        outr = er - oi;                                                                         \
        outi = ei + or_;                                                                        \
    }

#ifndef LOCAL_N
// ---------------------------------------------------------------------------------------------
// One Stockham pass in global memory, one butterfly per work-item.
// batch_fast != 0: dimension 0 runs over the batch (columns: contiguous across work-items),
// else dimension 0 runs over the butterflies of a line (rows).

// Dimension 2 (when launched) runs over planes ps apart.

#define PASS_KERNEL(R)                                                                          \
__kernel void stockham_pass##R(__global const real2 *src,                                     \
                               __global real2 *dst, __global const real2 *tw,                  \
                               const int n, const int ns,                                      \
                               const int es, const int bs, const int nb, const int ps,         \
                               const int batch_fast, const real s, const real scale)           \
{                                                                                               \
    const int nq = n / R;                                                                       \
    int b, j;                                                                                   \
    if (batch_fast) { b = get_global_id(0); j = get_global_id(1); }                            \
    else { j = get_global_id(0); b = get_global_id(1); }                                        \
    if (b >= nb || j >= nq) return;                                                             \
    const long o = (long)b * bs + (long)get_global_id(2) * ps;                                  \
    src += o;                                                                                   \
    dst += o;                                                                                   \
    const int k = j % ns;                                                                       \
    const int tstep = k * (nq / ns);                                                            \
    real2 v[R];                                                                                 \
    for (int r = 0; r < R; r++) v[r] = src[(long)(j + r * nq) * es];                            \
    for (int r = 1; r < R; r++) v[r] = CMUL(v[r], tw[r * tstep]);                               \
    bfly##R(v, s);                                                                              \
    const int d = (j - k) * R + k;                                                              \
    for (int r = 0; r < R; r++) dst[(long)(d + r * ns) * es] = v[r] * scale;                    \
}

PASS_KERNEL(2)
PASS_KERNEL(3)
PASS_KERNEL(4)
PASS_KERNEL(5)
PASS_KERNEL(7)
PASS_KERNEL(8)

#endif  // !LOCAL_N

// ---------------------------------------------------------------------------------------------
// Whole lines in local memory, compiled per line length: -DLOCAL_N=n -DLOCAL_T=ceil(n/8)
// -DNPASS=p and the radix and stride of every pass (-DR0=.. -DS0=1 -DR1=.. -DS1=R0 ...), so
// that all index arithmetic is constant. One work-group of LOCAL_T work-items per line; the
// passes run between barriers in straight-line code (PoCL's barrier handling rejects
// data-dependent control flow around barriers). Each work-item holds at most 16 values per
// pass: ceil(8/R) butterflies of R points.
#ifdef LOCAL_N

#define BFLY(R) BFLY_(R)
#define BFLY_(R) bfly##R

#define LPASS(R, NS)                                                                            \
    {                                                                                           \
        const int nq = LOCAL_N / (R);                                                           \
        for (int i = 0; i < (8 + (R) - 1) / (R); i++) {                                         \
            const int j = lid + i * LOCAL_T;                                                    \
            if (j < nq) {                                                                       \
                real2 *v = w + i * (R);                                                         \
                for (int r = 0; r < (R); r++) v[r] = buf[j + r * nq];                           \
                if ((NS) > 1) {                                                                 \
                    const int tstep = (j % (NS)) * (nq / (NS));                                 \
                    for (int r = 1; r < (R); r++) v[r] = CMUL(v[r], tw[r * tstep]);             \
                }                                                                               \
                BFLY(R)(v, s);                                                                  \
            }                                                                                   \
        }                                                                                       \
        barrier(CLK_LOCAL_MEM_FENCE);                                                           \
        for (int i = 0; i < (8 + (R) - 1) / (R); i++) {                                         \
            const int j = lid + i * LOCAL_T;                                                    \
            if (j < nq) {                                                                       \
                const int k = j % (NS);                                                         \
                const int d = (j - k) * (R) + k;                                                \
                for (int r = 0; r < (R); r++) buf[d + r * (NS)] = w[i * (R) + r];               \
            }                                                                                   \
        }                                                                                       \
        barrier(CLK_LOCAL_MEM_FENCE);                                                           \
    }

inline void local_core_at(__local real2 *buf, __global const real2 *tw, const real s,
                          const int lid)
{
    real2 w[16];
#if NPASS > 0
    LPASS(R0, S0)
#endif
#if NPASS > 1
    LPASS(R1, S1)
#endif
#if NPASS > 2
    LPASS(R2, S2)
#endif
#if NPASS > 3
    LPASS(R3, S3)
#endif
#if NPASS > 4
    LPASS(R4, S4)
#endif
#if NPASS > 5
    LPASS(R5, S5)
#endif
#if NPASS > 6
    LPASS(R6, S6)
#endif
#if NPASS > 7
    LPASS(R7, S7)
#endif
#if NPASS > 8
    LPASS(R8, S8)
#endif
#if NPASS > 9
    LPASS(R9, S9)
#endif
#if NPASS > 10
    LPASS(R10, S10)
#endif
#if NPASS > 11
    LPASS(R11, S11)
#endif
#if NPASS > 12
#error "at most 12 passes in local memory"
#endif
}

inline void local_core(__local real2 *buf, __global const real2 *tw, const real s)
{
    local_core_at(buf, tw, s, get_local_id(0));
}

#if LOCAL_C > 1
// LOCAL_C adjacent lines per work-group for lines that are batched along contiguous memory
// (the columns of a C-ordered array: es = row length, bs = 1): every global read and write
// covers LOCAL_C consecutive complex values (a cache line on CPUs) instead of one. Work-group
// LOCAL_T * LOCAL_C; line c of the group is handled by work-items c*LOCAL_T .. +LOCAL_T-1.
// In place is allowed. nb need not be a multiple of LOCAL_C. Dimension 1 (groups of one)
// runs over planes ps apart.
__kernel __attribute__((reqd_work_group_size(LOCAL_T * LOCAL_C, 1, 1)))
void fft_local_cols(__global const real2 *src, __global real2 *dst, __global const real2 *tw,
                    const int es, const int nb, const int ps, const real s, const real scale)
{
    __local real2 buf[LOCAL_C * LOCAL_N];
    const int lid = get_local_id(0);
    const int b0 = get_group_id(0) * LOCAL_C;
    const long po = (long)get_group_id(1) * ps;
    src += po;
    dst += po;
    const int nc = min(LOCAL_C, nb - b0);
    for (int i = lid; i < LOCAL_C * LOCAL_N; i += LOCAL_T * LOCAL_C) {
        const int c = i % LOCAL_C, row = i / LOCAL_C;
        if (c < nc) buf[c * LOCAL_N + row] = src[(long)row * es + b0 + c];
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    const int c = lid / LOCAL_T;
    local_core_at(buf + c * LOCAL_N, tw, s, lid - c * LOCAL_T);
    for (int i = lid; i < LOCAL_C * LOCAL_N; i += LOCAL_T * LOCAL_C) {
        const int cc = i % LOCAL_C, row = i / LOCAL_C;
        if (cc < nc) dst[(long)row * es + b0 + cc] = buf[cc * LOCAL_N + row] * scale;
    }
}
#endif

// Complex lines, any strides; src may equal dst (each group reads its line before writing).
// Dimension 1 (groups of one) runs over planes ps apart.
__kernel __attribute__((reqd_work_group_size(LOCAL_T, 1, 1)))
void fft_local_c2c(__global const real2 *src, __global real2 *dst, __global const real2 *tw,
                   const int es, const int bs, const int ps, const real s, const real scale)
{
    __local real2 buf[LOCAL_N];
    const int lid = get_local_id(0);
    const long base = (long)get_group_id(0) * bs + (long)get_group_id(1) * ps;
    for (int i = lid; i < LOCAL_N; i += LOCAL_T) buf[i] = src[base + (long)i * es];
    barrier(CLK_LOCAL_MEM_FENCE);
    local_core(buf, tw, s);
    for (int i = lid; i < LOCAL_N; i += LOCAL_T) dst[base + (long)i * es] = buf[i] * scale;
}

// Real rows of length 2m = 2*LOCAL_N (read as m complex) -> half spectra of m+1 values (row
// stride dbs). The rows of a plane stack are just more rows (no plane dimension).
__kernel __attribute__((reqd_work_group_size(LOCAL_T, 1, 1)))
void fft_local_r2c(__global const real2 *src, __global real *dst, __global const real2 *tw,
                   __global const real *twh, const int dbs, const real scale)
{
    __local real2 buf[LOCAL_N];
    const int m = LOCAL_N;
    const int lid = get_local_id(0);
    const long b = get_group_id(0);
    for (int i = lid; i < m; i += LOCAL_T) buf[i] = src[b * m + i];
    barrier(CLK_LOCAL_MEM_FENCE);
    local_core(buf, tw, (real)-1);
    for (int k = lid; k <= m; k += LOCAL_T) {
        const real2 z = buf[k == m ? 0 : k], c = buf[k == 0 ? 0 : m - k];
        real tr, ti, outr, outi;
        LD(twh, k, tr, ti);
        R2C_COMBINE(z.x, z.y, c.x, c.y, tr, ti, outr, outi);
        ST(dst, b * dbs + k, outr * scale, outi * scale);
    }
}

// Half spectra (m+1 values, row stride sbs) -> real rows of length 2m (written as m complex).
__kernel __attribute__((reqd_work_group_size(LOCAL_T, 1, 1)))
void fft_local_c2r(__global const real *src, __global real2 *dst, __global const real2 *tw,
                   __global const real *twh, const int sbs, const real scale)
{
    __local real2 buf[LOCAL_N];
    const int m = LOCAL_N;
    const int lid = get_local_id(0);
    const long b = get_group_id(0);
    __global const real *row = src + 2 * b * sbs;
    for (int k = lid; k < m; k += LOCAL_T) {
        real tr, ti, outr, outi;
        LD(twh, k, tr, ti);
        C2R_COMBINE(row, k, m, tr, ti, outr, outi);
        buf[k] = (real2)(outr, outi);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    local_core(buf, tw, (real)1);
    for (int i = lid; i < m; i += LOCAL_T) dst[b * m + i] = buf[i] * scale;
}

#endif  // LOCAL_N

#ifndef LOCAL_N
// ---------------------------------------------------------------------------------------------
// The packing steps as separate kernels, for lines that do not fit in local memory or whose
// half length needs Bluestein. Z: (nb, m) contiguous; X: (nb, m+1) contiguous.
__kernel void r2c_post(__global const real *Z, __global real *X, __global const real *twh,
                       const int m, const int nb, const real scale)
{
    const int k = get_global_id(0);
    const int b = get_global_id(1);
    if (k > m || b >= nb) return;
    __global const real *z = Z + 2 * (long)b * m;
    real zr, zi, cr, ci, tr, ti, outr, outi;
    LD(z, k == m ? 0 : k, zr, zi);
    LD(z, k == 0 ? 0 : m - k, cr, ci);
    LD(twh, k, tr, ti);
    R2C_COMBINE(zr, zi, cr, ci, tr, ti, outr, outi);
    ST(X, (long)b * (m + 1) + k, outr * scale, outi * scale);
}

__kernel void c2r_pre(__global const real *X, __global real *Z, __global const real *twh,
                      const int m, const int nb)
{
    const int k = get_global_id(0);
    const int b = get_global_id(1);
    if (k >= m || b >= nb) return;
    __global const real *row = X + 2 * (long)b * (m + 1);
    real tr, ti, outr, outi;
    LD(twh, k, tr, ti);
    C2R_COMBINE(row, k, m, tr, ti, outr, outi);
    ST(Z, (long)b * m + k, outr, outi);
}

// ---------------------------------------------------------------------------------------------
// Odd real lengths: full complex transforms of real data.

// x (nb, n) real -> Z (nb, n) complex with zero imaginary part
__kernel void real_to_complex(__global const real *x, __global real *Z, const int n,
                              const int nb)
{
    const int i = get_global_id(0);
    const int b = get_global_id(1);
    if (i >= n || b >= nb) return;
    const long o = (long)b * n + i;
    ST(Z, o, x[o], (real)0);
}

// Z (nb, n) -> X (nb, nh): the first nh columns
__kernel void crop_cols(__global const real *Z, __global real *X, const int n, const int nh,
                        const int nb)
{
    const int k = get_global_id(0);
    const int b = get_global_id(1);
    if (k >= nh || b >= nb) return;
    real re, im;
    LD(Z, (long)b * n + k, re, im);
    ST(X, (long)b * nh + k, re, im);
}

// X (nb, n/2+1) half spectra -> Z (nb, n) full Hermitian spectra (Im X[0] ignored; for even n
// also Im X[n/2]).
__kernel void hermitian_expand(__global const real *X, __global real *Z, const int n,
                               const int nb)
{
    const int k = get_global_id(0);
    const int b = get_global_id(1);
    if (k >= n || b >= nb) return;
    const int nh = n / 2 + 1;
    __global const real *row = X + 2 * (long)b * nh;
    real re, im;
    if (k < nh) {
        LD(row, k, re, im);
    } else {
        LD(row, n - k, re, im);
        im = -im;
    }
    if (k == 0 || 2 * k == n) im = 0;
    ST(Z, (long)b * n + k, re, im);
}

// x (nb, n) = scale * Re Z
__kernel void take_real(__global const real *Z, __global real *x, const int n, const int nb,
                        const real scale)
{
    const int i = get_global_id(0);
    const int b = get_global_id(1);
    if (i >= n || b >= nb) return;
    const long o = (long)b * n + i;
    x[o] = Z[2 * o] * scale;
}

// ---------------------------------------------------------------------------------------------
// Bluestein (chirp-z): X[k] = w[k] sum_m (x[m] w[m]) conj(w[k-m]), w[m] = exp(s i pi m^2 / n),
// as a circular convolution of length L (a power of two >= 2n-1). Dimension 2 of pre and
// post (when launched) runs over planes ps apart in src/dst; A holds the lines of all planes
// contiguously (line b of plane p is row p*nb + b), so its transforms and product need none.

// A (P*nb, L) = x * w, zero padded
__kernel void bluestein_pre(__global const real *src, __global real *A,
                            __global const real *w, const int n, const int L, const int es,
                            const int bs, const int nb, const int ps)
{
    const int m = get_global_id(0);
    const int b = get_global_id(1);
    const int p = get_global_id(2);
    if (m >= L || b >= nb) return;
    real vr = 0, vi = 0;
    if (m < n) {
        real wr, wi;
        LD(src, (long)p * ps + (long)b * bs + (long)m * es, vr, vi);
        LD(w, m, wr, wi);
        CMULI(vr, vi, wr, wi);
    }
    ST(A, ((long)p * nb + b) * L + m, vr, vi);
}

// A[b, :] *= F[:]
__kernel void bluestein_mul(__global real *A, __global const real *F, const int L,
                            const int nb)
{
    const int m = get_global_id(0);
    const int b = get_global_id(1);
    if (m >= L || b >= nb) return;
    const long o = (long)b * L + m;
    real ar, ai, fr, fi;
    LD(A, o, ar, ai);
    LD(F, m, fr, fi);
    CMULI(ar, ai, fr, fi);
    ST(A, o, ar, ai);
}

// dst = scale * w * A[:, :n]
__kernel void bluestein_post(__global const real *A, __global real *dst,
                             __global const real *w, const int n, const int L, const int es,
                             const int bs, const int nb, const int ps, const real scale)
{
    const int k = get_global_id(0);
    const int b = get_global_id(1);
    const int p = get_global_id(2);
    if (k >= n || b >= nb) return;
    real ar, ai, wr, wi;
    LD(A, ((long)p * nb + b) * L + k, ar, ai);
    LD(w, k, wr, wi);
    CMULI(ar, ai, wr, wi);
    ST(dst, (long)p * ps + (long)b * bs + (long)k * es, ar * scale, ai * scale);
}

#endif  // !LOCAL_N
