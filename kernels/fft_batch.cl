// Helpers of the "batch" FFT mapping (clfza/fft/opencl.py, clfza/fft/codegen.py): transposes
// of complex arrays, fused with the real-to-complex / complex-to-real untangling of the
// half-length packing. The Stockham passes of this mapping are generated (codegen.py): one
// work-item per (line, butterfly), lines along contiguous memory.
//
// FT x FT work-groups. With LOCAL_TILES=1 (GPUs) a local tile makes both the reads and the
// writes contiguous (coalesced). With LOCAL_TILES=0 (CPU devices) each work-item moves its
// element directly: reads along contiguous memory, writes scattered within the FT x FT block,
// which stays in cache; on PoCL this is ~3x faster than the tiled form (barriers and strided
// local reads). Complex values are moved as two real scalars (vector types stop PoCL's
// work-group vectoriser). Global sizes are rounded up to multiples of FT; kernels guard edges.
// With LOCAL_TILES=0 each kernel also has a `_full` variant without edge guards (under a
// per-work-item guard PoCL's vectoriser masks every load and store, several times slower):
// the last group along each dimension is shifted back to end at the edge (CLAMP), so edge
// elements may be done twice, writing the same values; needs extents >= FT and src != dst.
#define CLAMP(d, ext) (min((int)get_group_id(d) * FT, (ext) - FT) + (int)get_local_id(d))

#ifndef FT
#define FT 16
#endif
#ifndef LOCAL_TILES
#define LOCAL_TILES 1
#endif

// dst (cols, rows) = scale * src (rows, cols)^T, complex; row strides lds (src) and ldd (dst)
// in complex values. Global size (>= cols, >= rows).
#if !LOCAL_TILES
inline void transpose_body(__global const real *src, __global real *dst, const int rows,
                           const int cols, const int lds, const int ldd, const real scale,
                           const int x, const int y, const bool guard)
{
    if (!guard || (x < cols && y < rows)) {
        const long i = 2 * ((long)y * lds + x), o = 2 * ((long)x * ldd + y);
        const real a = src[i], b = src[i + 1];
        dst[o] = scale * a;
        dst[o + 1] = scale * b;
    }
}

__kernel __attribute__((reqd_work_group_size(FT, FT, 1)))
void transpose_c_full(__global const real *src, __global real *dst, const int rows,
                      const int cols, const int lds, const int ldd, const real scale)
{
    transpose_body(src, dst, rows, cols, lds, ldd, scale, CLAMP(0, cols), CLAMP(1, rows),
                   false);
}

// the same with dimension 0 along dst rows (contiguous writes, strided reads)
__kernel __attribute__((reqd_work_group_size(FT, FT, 1)))
void transpose_c_fullw(__global const real *src, __global real *dst, const int rows,
                       const int cols, const int lds, const int ldd, const real scale)
{
    transpose_body(src, dst, rows, cols, lds, ldd, scale, CLAMP(1, cols), CLAMP(0, rows),
                   false);
}
#endif

__kernel __attribute__((reqd_work_group_size(FT, FT, 1)))
void transpose_c(__global const real *src, __global real *dst, const int rows, const int cols,
                 const int lds, const int ldd, const real scale)
{
    const int x = get_global_id(0), y = get_global_id(1);
#if LOCAL_TILES
    __local real tr[FT][FT + 1], ti[FT][FT + 1];
    const int lx = get_local_id(0), ly = get_local_id(1);
    real a = 0, b = 0;
    if (x < cols && y < rows) {
        const long o = 2 * ((long)y * lds + x);
        a = src[o];
        b = src[o + 1];
    }
    tr[ly][lx] = a;
    ti[ly][lx] = b;
    barrier(CLK_LOCAL_MEM_FENCE);
    const int ox = y - ly + lx, oy = x - lx + ly;  // dst element (oy, ox)
    if (ox < rows && oy < cols) {
        const long o = 2 * ((long)oy * ldd + ox);
        dst[o] = scale * tr[lx][ly];
        dst[o + 1] = scale * ti[lx][ly];
    }
#else
    transpose_body(src, dst, rows, cols, lds, ldd, scale, x, y, true);
#endif
}

// Forward untangling fused with the transpose back to rows.
// Zt (m, nb) with row stride ldz: column y holds Z = FFT_m(z) of real row y read as m complex values.
// X (nb, m+1): X[y, k] = scale (E + twh[k] O), E = (Z[k] + conj Z[m-k]) / 2,
// O = -i (Z[k] - conj Z[m-k]) / 2, twh[k] = exp(-2 pi i k / (2m)), indices of Z mod m.
// Global size (>= nb, >= m+1): dimension 0 runs over y (the read side).
inline void r2c_untangle_one(__global const real *Zt, __global const real *twh, const int m,
                             const int ldz, const real scale, const int y, const int k,
                             real *outr, real *outi)
{
    const int ka = k == m ? 0 : k, kb = k == 0 ? 0 : m - k;
    const long oa = 2 * ((long)ka * ldz + y), ob = 2 * ((long)kb * ldz + y);
    const real zr = Zt[oa], zi = Zt[oa + 1], cr = Zt[ob], ci = Zt[ob + 1];
    const real tr_ = twh[2 * k], ti_ = twh[2 * k + 1];
    const real er = (real)0.5 * (zr + cr), ei = (real)0.5 * (zi - ci);
    const real dr = (real)0.5 * (zr - cr), di = (real)0.5 * (zi + ci);
    // o = -i d = (di, -dr)
    *outr = scale * (er + tr_ * di + ti_ * dr);
    *outi = scale * (ei - tr_ * dr + ti_ * di);
}

#if !LOCAL_TILES
__kernel __attribute__((reqd_work_group_size(FT, FT, 1)))
void r2c_untangle_t_full(__global const real *Zt, __global real *X, __global const real *twh,
                         const int m, const int nb, const int ldz, const real scale)
{
    const int y = CLAMP(0, nb), k = CLAMP(1, m + 1);
    real outr, outi;
    r2c_untangle_one(Zt, twh, m, ldz, scale, y, k, &outr, &outi);
    const long o = 2 * ((long)y * (m + 1) + k);
    X[o] = outr;
    X[o + 1] = outi;
}
#endif

__kernel __attribute__((reqd_work_group_size(FT, FT, 1)))
void r2c_untangle_t(__global const real *Zt, __global real *X, __global const real *twh,
                    const int m, const int nb, const int ldz, const real scale)
{
    const int y = get_global_id(0), k = get_global_id(1);
    real outr = 0, outi = 0;
    if (y < nb && k <= m) {
        r2c_untangle_one(Zt, twh, m, ldz, scale, y, k, &outr, &outi);
    }
#if LOCAL_TILES
    __local real tr[FT][FT + 1], ti[FT][FT + 1];
    const int lx = get_local_id(0), ly = get_local_id(1);
    tr[ly][lx] = outr;
    ti[ly][lx] = outi;
    barrier(CLK_LOCAL_MEM_FENCE);
    const int kk = k - ly + lx, yy = y - lx + ly;
    if (kk <= m && yy < nb) {
        const long o = 2 * ((long)yy * (m + 1) + kk);
        X[o] = tr[lx][ly];
        X[o + 1] = ti[lx][ly];
    }
#else
    if (y < nb && k <= m) {
        const long o = 2 * ((long)y * (m + 1) + k);
        X[o] = outr;
        X[o + 1] = outi;
    }
#endif
}

// Inverse untangling fused with the transpose to columns.
// X (nb, m+1) half spectra (rows) -> Zt (m, nb) with row stride ldz: Zt[k, y] = E + i O with E = X[k] + conj
// X[m-k], O = (X[k] - conj X[m-k]) conj(twh[k]); like numpy, Im X[0] and Im X[m] are ignored.
// Then z = IFFT_m(Zt[:, y]) (unnormalised) is real row y read as m complex values.
// Global size (>= m, >= nb): dimension 0 runs over k (the read side).
#define C2R_UNTANGLE(xr, xi, cr, ci, k, outr, outi)                                          \
    {                                                                                        \
        const real tr_ = twh[2 * (k)], ti_ = twh[2 * (k) + 1];                               \
        const real er = xr + cr, ei = xi + ci;                                               \
        const real dr = xr - cr, di = xi - ci;                                               \
        const real or_ = dr * tr_ + di * ti_, oi = di * tr_ - dr * ti_;                      \
        outr = er - oi;                                                                      \
        outi = ei + or_;                                                                     \
    }

inline void c2r_untangle_one(__global const real *X, __global real *Zt,
                             __global const real *twh, const int m, const int ldz,
                             const int k, const int y)
{
    const long oa = 2 * ((long)y * (m + 1) + k), ob = 2 * ((long)y * (m + 1) + m - k);
    real xr = X[oa], xi = X[oa + 1], cr = X[ob], ci = -X[ob + 1];
    if (k == 0) { xi = 0; ci = 0; }
    real outr, outi;
    C2R_UNTANGLE(xr, xi, cr, ci, k, outr, outi);
    const long o = 2 * ((long)k * ldz + y);
    Zt[o] = outr;
    Zt[o + 1] = outi;
}

#if !LOCAL_TILES
__kernel __attribute__((reqd_work_group_size(FT, FT, 1)))
void c2r_untangle_t_full(__global const real *X, __global real *Zt, __global const real *twh,
                         const int m, const int nb, const int ldz)
{
    c2r_untangle_one(X, Zt, twh, m, ldz, CLAMP(0, m), CLAMP(1, nb));
}

// the same with dimension 0 along y (contiguous writes of Zt)
__kernel __attribute__((reqd_work_group_size(FT, FT, 1)))
void c2r_untangle_t_fullw(__global const real *X, __global real *Zt, __global const real *twh,
                          const int m, const int nb, const int ldz)
{
    c2r_untangle_one(X, Zt, twh, m, ldz, CLAMP(1, m), CLAMP(0, nb));
}
#endif

__kernel __attribute__((reqd_work_group_size(FT, FT, 1)))
void c2r_untangle_t(__global const real *X, __global real *Zt, __global const real *twh,
                    const int m, const int nb, const int ldz)
{
#if LOCAL_TILES
    __local real ar[FT][FT + 1], ai[FT][FT + 1], br[FT][FT + 1], bi[FT][FT + 1];
    const int lx = get_local_id(0), ly = get_local_id(1);
    const int k0 = get_group_id(0) * FT, y0 = get_group_id(1) * FT;
    {
        const int y = y0 + ly;
        const int ka = k0 + lx;                 // X[y, k0 + lx]
        const int kb = m - k0 - (FT - 1) + lx;  // X[y, m - k] for k = k0 + FT-1-lx
        real a0 = 0, a1 = 0, b0 = 0, b1 = 0;
        if (y < nb && ka < m) {
            const long o = 2 * ((long)y * (m + 1) + ka);
            a0 = X[o];
            a1 = X[o + 1];
        }
        if (y < nb && kb >= 1 && kb <= m) {
            const long o = 2 * ((long)y * (m + 1) + kb);
            b0 = X[o];
            b1 = X[o + 1];
        }
        ar[ly][lx] = a0;
        ai[ly][lx] = a1;
        br[ly][lx] = b0;
        bi[ly][lx] = b1;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    {
        const int y = y0 + lx, k = k0 + ly;
        if (y < nb && k < m) {
            real xr = ar[lx][ly], xi = ai[lx][ly];
            real cr = br[lx][FT - 1 - ly], ci = -bi[lx][FT - 1 - ly];
            if (k == 0) { xi = 0; ci = 0; }
            real outr, outi;
            C2R_UNTANGLE(xr, xi, cr, ci, k, outr, outi);
            const long o = 2 * ((long)k * ldz + y);
            Zt[o] = outr;
            Zt[o + 1] = outi;
        }
    }
#else
    const int k = get_global_id(0), y = get_global_id(1);
    if (y < nb && k < m) c2r_untangle_one(X, Zt, twh, m, ldz, k, y);
#endif
}
