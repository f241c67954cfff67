// Batched 1-D complex FFTs (Stockham autosort, radix 2/4/8 and 3/5/7), real-to-complex and
// complex-to-real through the half-length complex packing, and Bluestein helpers.
//
// Layout: a batch of `nb` lines of length `n`; element i of line b sits at b*bs + i*es
// (in complex elements). Rows of a C-ordered (ny, nx) array: es = 1, bs = nx; its columns:
// es = nx, bs = 1.
//
// Stockham pass (radix R, Ns = product of the radices already applied), butterfly j < n/R:
//     k = j % Ns;   v[r] = src[j + r*n/R] * w^(k*r*(n/(Ns*R)))   (w = exp(sign*2*pi*i/n))
//     v = DFT_R(v); dst[(j - k)*R + k + r*Ns] = v[r]
// The twiddle table tw[m] = exp(sign*2*pi*i*m/n), m < n, is computed on the host in float64
// (no accumulated rotation error); the index k*r*(n/(Ns*R)) is < n.
//
// Everything that varies per plan (n, strides, the radix sequence) is a kernel argument, so
// one program per dtype serves every size (PoCL's cold builds cost ~0.6 s each).

#define CMUL(a, b) ((real2)((a).x * (b).x - (a).y * (b).y, (a).x * (b).y + (a).y * (b).x))
#define CONJ(a) ((real2)((a).x, -(a).y))
// multiply by sign*i (sign = +-1): -i for the forward transform, +i for the inverse
#define ROT(a, s) ((real2)(-(s) * (a).y, (s) * (a).x))

#define C8 ((real)0.70710678118654752440)

// ---------------------------------------------------------------------------------------------
// Small DFTs on private arrays (in place, natural order in and out).

inline void bfly2(real2 *v)
{
    real2 a = v[0], b = v[1];
    v[0] = a + b;
    v[1] = a - b;
}

inline void bfly4(real2 *v, real s)
{
    real2 t0 = v[0] + v[2], t1 = v[0] - v[2];
    real2 t2 = v[1] + v[3], t3 = ROT(v[1] - v[3], s);
    v[0] = t0 + t2;
    v[1] = t1 + t3;
    v[2] = t0 - t2;
    v[3] = t1 - t3;
}

inline void bfly8(real2 *v, real s)
{
    // even/odd radix-4 halves, then combine with w8^k
    real2 e[4] = {v[0], v[2], v[4], v[6]};
    real2 o[4] = {v[1], v[3], v[5], v[7]};
    bfly4(e, s);
    bfly4(o, s);
    real2 o1 = C8 * (real2)(o[1].x - s * o[1].y, o[1].y + s * o[1].x);   // w8 * o1
    real2 o2 = ROT(o[2], s);                                              // w8^2 * o2
    real2 o3t = ROT(o[3], s);
    real2 o3 = C8 * (real2)(o3t.x - s * o3t.y, o3t.y + s * o3t.x);        // w8^3 * o3
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
inline void bfly3(real2 *v, real s)
{
    const real c1 = (real)-0.5, s1 = (real)0.86602540378443864676;
    real2 a = v[1] + v[2], b = v[1] - v[2];
    real2 y0 = v[0] + a;
    real2 m = v[0] + c1 * a;
    real2 t = ROT(b, s) * s1;
    v[0] = y0;
    v[1] = m + t;
    v[2] = m - t;
}

inline void bfly5(real2 *v, real s)
{
    const real c1 = (real)0.30901699437494742410, c2 = (real)-0.80901699437494742410;
    const real s1 = (real)0.95105651629515357212, s2 = (real)0.58778525229247312917;
    real2 a1 = v[1] + v[4], b1 = v[1] - v[4];
    real2 a2 = v[2] + v[3], b2 = v[2] - v[3];
    real2 x0 = v[0];
    real2 m1 = x0 + c1 * a1 + c2 * a2;
    real2 m2 = x0 + c2 * a1 + c1 * a2;
    real2 t1 = ROT(s1 * b1 + s2 * b2, s);
    real2 t2 = ROT(s2 * b1 - s1 * b2, s);
    v[0] = x0 + a1 + a2;
    v[1] = m1 + t1;
    v[4] = m1 - t1;
    v[2] = m2 + t2;
    v[3] = m2 - t2;
}

inline void bfly7(real2 *v, real s)
{
    const real c1 = (real)0.62348980185873353053, c2 = (real)-0.22252093395631440429,
               c3 = (real)-0.90096886790241912624;
    const real s1 = (real)0.78183148246802980871, s2 = (real)0.97492791218182360702,
               s3 = (real)0.43388373911755812048;
    real2 a1 = v[1] + v[6], b1 = v[1] - v[6];
    real2 a2 = v[2] + v[5], b2 = v[2] - v[5];
    real2 a3 = v[3] + v[4], b3 = v[3] - v[4];
    real2 x0 = v[0];
    real2 m1 = x0 + c1 * a1 + c2 * a2 + c3 * a3;
    real2 m2 = x0 + c2 * a1 + c3 * a2 + c1 * a3;   // cos(4 pi k/7): k=1,2,3 -> c2, c3, c1
    real2 m3 = x0 + c3 * a1 + c1 * a2 + c2 * a3;   // cos(6 pi k/7): c3, c1, c2
    real2 t1 = ROT(s1 * b1 + s2 * b2 + s3 * b3, s);
    real2 t2 = ROT(s2 * b1 - s3 * b2 - s1 * b3, s);  // sin(4 pi k/7): s2, -s3, -s1
    real2 t3 = ROT(s3 * b1 - s1 * b2 + s2 * b3, s);  // sin(6 pi k/7): s3, -s1, s2
    v[0] = x0 + a1 + a2 + a3;
    v[1] = m1 + t1;
    v[6] = m1 - t1;
    v[2] = m2 + t2;
    v[5] = m2 - t2;
    v[3] = m3 + t3;
    v[4] = m3 - t3;
}

// ---------------------------------------------------------------------------------------------
// One Stockham pass in global memory, one butterfly per work-item.
// batch_fast != 0: dimension 0 runs over the batch (columns: contiguous across work-items),
// else dimension 0 runs over the butterflies of a line (rows).

#define PASS_KERNEL(R, BODY)                                                                    \
__kernel void stockham_pass##R(__global const real2 *src, __global real2 *dst,                 \
                               __global const real2 *tw, const int n, const int ns,            \
                               const int es, const int bs, const int nb,                       \
                               const int batch_fast, const real s, const real scale)           \
{                                                                                               \
    const int nq = n / R;                                                                       \
    int b, j;                                                                                   \
    if (batch_fast) { b = get_global_id(0); j = get_global_id(1); }                            \
    else { j = get_global_id(0); b = get_global_id(1); }                                        \
    if (b >= nb || j >= nq) return;                                                             \
    src += (long)b * bs;                                                                        \
    dst += (long)b * bs;                                                                        \
    const int k = j % ns;                                                                       \
    const int tstep = k * (nq / ns);                                                            \
    real2 v[R];                                                                                 \
    for (int r = 0; r < R; r++) v[r] = src[(long)(j + r * nq) * es];                            \
    for (int r = 1; r < R; r++) v[r] = CMUL(v[r], tw[r * tstep]);                               \
    BODY;                                                                                       \
    const int d = (j - k) * R + k;                                                              \
    for (int r = 0; r < R; r++) dst[(long)(d + r * ns) * es] = v[r] * scale;                    \
}

PASS_KERNEL(2, bfly2(v))
PASS_KERNEL(3, bfly3(v, s))
PASS_KERNEL(4, bfly4(v, s))
PASS_KERNEL(5, bfly5(v, s))
PASS_KERNEL(7, bfly7(v, s))
PASS_KERNEL(8, bfly8(v, s))

// ---------------------------------------------------------------------------------------------
// Whole lines in local memory: one work-group per line, T = ceil(n/8) work-items, every
// Stockham pass between barriers. The radix sequence is packed 4 bits per pass in `radices`
// (first pass in the low bits). Each work-item keeps at most 16 values in registers per pass:
// B(R) = ceil(8/R) butterflies of R points.

#define LPASS_LOAD(R, B, BODY)                                                                  \
    for (int i = 0; i < B; i++) {                                                               \
        const int j = lid + i * T;                                                              \
        if (j < nq) {                                                                           \
            const int k = j % ns;                                                               \
            const int tstep = k * (nq / ns);                                                    \
            real2 *v = w + i * R;                                                               \
            for (int r = 0; r < R; r++) v[r] = buf[j + r * nq];                                 \
            for (int r = 1; r < R; r++) v[r] = CMUL(v[r], tw[r * tstep]);                       \
            BODY;                                                                               \
        }                                                                                       \
    }

#define LPASS_STORE(R, B)                                                                       \
    for (int i = 0; i < B; i++) {                                                               \
        const int j = lid + i * T;                                                              \
        if (j < nq) {                                                                           \
            const int k = j % ns;                                                               \
            const int d = (j - k) * R + k;                                                      \
            for (int r = 0; r < R; r++) buf[d + r * ns] = w[i * R + r];                         \
        }                                                                                       \
    }

inline void local_core(__local real2 *buf, __global const real2 *tw, const int n,
                       const ulong radices, const int npass, const real s)
{
    const int lid = get_local_id(0);
    const int T = get_local_size(0);
    real2 w[16];
    int ns = 1;
    for (int p = 0; p < npass; p++) {
        const int R = (int)((radices >> (4 * p)) & 15UL);
        const int nq = n / R;
        switch (R) {
        case 8: LPASS_LOAD(8, 1, bfly8(v, s)) break;
        case 4: LPASS_LOAD(4, 2, bfly4(v, s)) break;
        case 2: LPASS_LOAD(2, 4, bfly2(v)) break;
        case 3: LPASS_LOAD(3, 3, bfly3(v, s)) break;
        case 5: LPASS_LOAD(5, 2, bfly5(v, s)) break;
        default: LPASS_LOAD(7, 2, bfly7(v, s)) break;
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        switch (R) {
        case 8: LPASS_STORE(8, 1) break;
        case 4: LPASS_STORE(4, 2) break;
        case 2: LPASS_STORE(2, 4) break;
        case 3: LPASS_STORE(3, 3) break;
        case 5: LPASS_STORE(5, 2) break;
        default: LPASS_STORE(7, 2) break;
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        ns *= R;
    }
}

// Complex lines, any strides; src may equal dst (each group reads its line before writing).
__kernel void fft_local_c2c(__global const real2 *src, __global real2 *dst,
                            __global const real2 *tw, const int n, const int es, const int bs,
                            const ulong radices, const int npass, const real s,
                            const real scale, __local real2 *buf)
{
    const int lid = get_local_id(0);
    const int T = get_local_size(0);
    const long base = (long)get_group_id(0) * bs;
    for (int i = lid; i < n; i += T) buf[i] = src[base + (long)i * es];
    barrier(CLK_LOCAL_MEM_FENCE);
    local_core(buf, tw, n, radices, npass, s);
    for (int i = lid; i < n; i += T) dst[base + (long)i * es] = buf[i] * scale;
}

// Real rows of length 2m (read as m complex) -> half spectra of m+1 values (rows of dst, row
// stride dbs). twh[k] = exp(-2 pi i k / (2m)), k <= m.
//   Z = FFT_m(z),  E = (Z[k] + conj Z[m-k]) / 2,  O = -i (Z[k] - conj Z[m-k]) / 2,
//   X[k] = E + twh[k] O.
inline real2 r2c_combine(const real2 zk, const real2 zc, const real2 t)
{
    const real2 e = (real)0.5 * (zk + zc);
    const real2 d = (real)0.5 * (zk - zc);
    const real2 o = (real2)(d.y, -d.x);
    return e + CMUL(t, o);
}

__kernel void fft_local_r2c(__global const real2 *src, __global real2 *dst,
                            __global const real2 *tw, __global const real2 *twh, const int m,
                            const int dbs, const ulong radices, const int npass,
                            const real scale, __local real2 *buf)
{
    const int lid = get_local_id(0);
    const int T = get_local_size(0);
    const long b = get_group_id(0);
    for (int i = lid; i < m; i += T) buf[i] = src[b * m + i];
    barrier(CLK_LOCAL_MEM_FENCE);
    local_core(buf, tw, m, radices, npass, (real)-1);
    for (int k = lid; k <= m; k += T) {
        const real2 zk = buf[k == m ? 0 : k];
        const real2 zc = CONJ(buf[k == 0 ? 0 : m - k]);
        dst[b * dbs + k] = r2c_combine(zk, zc, twh[k]) * scale;
    }
}

// Half spectra (m+1 values, row stride sbs) -> real rows of length 2m (written as m complex).
//   E = X[k] + conj X[m-k],  O = (X[k] - conj X[m-k]) conj(twh[k]),  Z = E + i O,
//   z = IFFT_m(Z) (unnormalised; the caller's scale holds 1/(2m) and any other factor).
// Like numpy/pocketfft the imaginary parts of X[0] and X[m] are ignored.
inline real2 c2r_combine(__global const real2 *row, const int k, const int m, const real2 t)
{
    real2 xk = row[k];
    real2 xc = CONJ(row[m - k]);
    if (k == 0) { xk.y = 0; xc.y = 0; }
    const real2 e = xk + xc;
    const real2 o = CMUL(xk - xc, CONJ(t));
    return e + (real2)(-o.y, o.x);
}

__kernel void fft_local_c2r(__global const real2 *src, __global real2 *dst,
                            __global const real2 *tw, __global const real2 *twh, const int m,
                            const int sbs, const ulong radices, const int npass,
                            const real scale, __local real2 *buf)
{
    const int lid = get_local_id(0);
    const int T = get_local_size(0);
    const long b = get_group_id(0);
    __global const real2 *row = src + b * sbs;
    for (int k = lid; k < m; k += T) buf[k] = c2r_combine(row, k, m, twh[k]);
    barrier(CLK_LOCAL_MEM_FENCE);
    local_core(buf, tw, m, radices, npass, (real)1);
    for (int i = lid; i < m; i += T) dst[b * m + i] = buf[i] * scale;
}

// The same packing steps as separate kernels, for lines that do not fit in local memory or
// whose half length needs Bluestein. Z: (nb, m) contiguous; X: (nb, m+1) contiguous.
__kernel void r2c_post(__global const real2 *Z, __global real2 *X, __global const real2 *twh,
                       const int m, const int nb, const real scale)
{
    const int k = get_global_id(0);
    const int b = get_global_id(1);
    if (k > m || b >= nb) return;
    __global const real2 *z = Z + (long)b * m;
    const real2 zk = z[k == m ? 0 : k];
    const real2 zc = CONJ(z[k == 0 ? 0 : m - k]);
    X[(long)b * (m + 1) + k] = r2c_combine(zk, zc, twh[k]) * scale;
}

__kernel void c2r_pre(__global const real2 *X, __global real2 *Z, __global const real2 *twh,
                      const int m, const int nb)
{
    const int k = get_global_id(0);
    const int b = get_global_id(1);
    if (k >= m || b >= nb) return;
    Z[(long)b * m + k] = c2r_combine(X + (long)b * (m + 1), k, m, twh[k]);
}

// ---------------------------------------------------------------------------------------------
// Odd real lengths: full complex transforms of real data.

// x (nb, n) real -> Z (nb, n) complex with zero imaginary part
__kernel void real_to_complex(__global const real *x, __global real2 *Z, const int n,
                              const int nb)
{
    const int i = get_global_id(0);
    const int b = get_global_id(1);
    if (i >= n || b >= nb) return;
    const long o = (long)b * n + i;
    Z[o] = (real2)(x[o], (real)0);
}

// Z (nb, n) -> X (nb, nh): the first nh columns
__kernel void crop_cols(__global const real2 *Z, __global real2 *X, const int n, const int nh,
                        const int nb)
{
    const int k = get_global_id(0);
    const int b = get_global_id(1);
    if (k >= nh || b >= nb) return;
    X[(long)b * nh + k] = Z[(long)b * n + k];
}

// X (nb, n/2+1) half spectra -> Z (nb, n) full Hermitian spectra (Im X[0] ignored; for even n
// also Im X[n/2]).
__kernel void hermitian_expand(__global const real2 *X, __global real2 *Z, const int n,
                               const int nb)
{
    const int k = get_global_id(0);
    const int b = get_global_id(1);
    if (k >= n || b >= nb) return;
    const int nh = n / 2 + 1;
    __global const real2 *row = X + (long)b * nh;
    real2 v = (k < nh) ? row[k] : CONJ(row[n - k]);
    if (k == 0 || 2 * k == n) v.y = 0;
    Z[(long)b * n + k] = v;
}

// x (nb, n) = scale * Re Z
__kernel void take_real(__global const real2 *Z, __global real *x, const int n, const int nb,
                        const real scale)
{
    const int i = get_global_id(0);
    const int b = get_global_id(1);
    if (i >= n || b >= nb) return;
    const long o = (long)b * n + i;
    x[o] = Z[o].x * scale;
}

// ---------------------------------------------------------------------------------------------
// Bluestein (chirp-z): X[k] = w[k] sum_m (x[m] w[m]) conj(w[k-m]), w[m] = exp(s i pi m^2 / n),
// as a circular convolution of length L (a power of two >= 2n-1).

// A (nb, L) = x * w, zero padded
__kernel void bluestein_pre(__global const real2 *src, __global real2 *A,
                            __global const real2 *w, const int n, const int L, const int es,
                            const int bs, const int nb)
{
    const int m = get_global_id(0);
    const int b = get_global_id(1);
    if (m >= L || b >= nb) return;
    real2 v = (real2)(0, 0);
    if (m < n) v = CMUL(src[(long)b * bs + (long)m * es], w[m]);
    A[(long)b * L + m] = v;
}

// A[b, :] *= F[:]
__kernel void bluestein_mul(__global real2 *A, __global const real2 *F, const int L,
                            const int nb)
{
    const int m = get_global_id(0);
    const int b = get_global_id(1);
    if (m >= L || b >= nb) return;
    const long o = (long)b * L + m;
    A[o] = CMUL(A[o], F[m]);
}

// dst = scale * w * A[:, :n]
__kernel void bluestein_post(__global const real2 *A, __global real2 *dst,
                             __global const real2 *w, const int n, const int L, const int es,
                             const int bs, const int nb, const real scale)
{
    const int k = get_global_id(0);
    const int b = get_global_id(1);
    if (k >= n || b >= nb) return;
    dst[(long)b * bs + (long)k * es] = CMUL(A[(long)b * L + k], w[k]) * scale;
}
