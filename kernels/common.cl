// Shared definitions, prepended to every clfza program.
// REAL_IS_DOUBLE selects float64 (needs cl_khr_fp64); the default is float32.
//
// Math as clang built-ins on PoCL (CLFZA_POCL, set by the runtime). PoCL's kernel library may be
// compiled for another CPU than the one it compiles kernels for (pip's PoCL 3.0: its library
// for skylake-avx512, kernels for the running CPU, e.g. icelake-client or rocketlake), and then
// LLVM refuses to inline any library function into a kernel ("conflicting attributes"): fabs,
// fmax, copysign, sqrt, shuffle, select, vload16, min stay out-of-line calls and PoCL's work-item
// loops are "not vectorized: call instruction" (soft_step, twist_combine, admm_update,
// reg_contrib, fgp_*, chambolle2_fused 2.6-4.8x slower on a 2-core Xeon,
// bench/results/kernels_builtins_pocl30_xeon.json). __builtin_fabsf & co. are LLVM
// intrinsics, never calls, and compute the same IEEE results (fmax = maxnum, NaN-ignoring, like
// the OpenCL built-in). Other compilers get the portable OpenCL built-ins.
// tests/test_pocl_remarks.py fails when a hot kernel has a call left in its loop.
#if defined(__clang__) && defined(CLFZA_POCL)
#define CLFZA_CLANG_BUILTINS 1
#endif

// float16 arguments and results of the inline helpers below (hsum16, sqrt16, store_tail, ...,
// and those of elementwise.cl, spectrum.cl and tv_fused.cl): clang warns at each call, "AVX
// vector argument of type 'float16' without 'avx512f' enabled changes the ABI" (-Wpsabi), when
// it compiles for a CPU without AVX-512 (pip's PoCL 3.0 on a CPU its LLVM 14 does not know, e.g.
// "AMD EPYC" of Zen 4: 59 warnings for elementwise.cl). The warning is about calls between code
// compiled with and without AVX-512, which disagree on how a 64-byte vector is passed. Here
// every caller and callee is in one program, compiled with the same target features, and
// inlined into the kernels: no such call exists, so the warning has no subject. Silenced for
// exactly that diagnostic, on clang-based CPU compilers (PoCL, Intel's CPU runtime).
#if defined(__clang__) && defined(CLFZA_CPU)
#pragma clang diagnostic ignored "-Wpsabi"
#endif

#ifdef REAL_IS_DOUBLE
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double real;
typedef double2 real2;
#ifdef CLFZA_CLANG_BUILTINS
#define SQRT(x) __builtin_sqrt(x)
#define FABS(x) __builtin_fabs(x)
#define FMAX(a, b) __builtin_fmax(a, b)
#define COPYSIGN(a, b) __builtin_copysign(a, b)
#endif
#else
typedef float real;
typedef float2 real2;
#ifdef CLFZA_CLANG_BUILTINS
#define SQRT(x) __builtin_sqrtf(x)
#define FABS(x) __builtin_fabsf(x)
#define FMAX(a, b) __builtin_fmaxf(a, b)
#define COPYSIGN(a, b) __builtin_copysignf(a, b)
#endif
#endif
#ifndef CLFZA_CLANG_BUILTINS
#define SQRT(x) sqrt(x)
#define FABS(x) fabs(x)
#define FMAX(a, b) fmax(a, b)
#define COPYSIGN(a, b) copysign(a, b)
#endif

// Periodic x-neighbours without gathers (docs/design.md s.6). Wrapped indices (xi == 0 ? W - 1 : xi - 1)
// or a choice between two loads (xi > 0 ? a[i - 1] : a[i + W - 1]) end up as one load from a
// selected address, which PoCL's vectoriser turns into a gather. Two conditional loads at affine
// addresses, each defaulting to the pixel's own value c (already loaded), then a select, stay
// vector loads (fgp_step at 2048^2: 13.1 -> 10.2 ms).
inline real left_per(__global const real *a, const int i, const int xi, const int W,
                     const real c)
{
    const real l = xi > 0 ? a[i - 1] : c;
    const real w = xi == 0 ? a[i + W - 1] : c;
    return xi > 0 ? l : w;
}

inline real right_per(__global const real *a, const int i, const int xi, const int W,
                      const real c)
{
    const real r = xi < W - 1 ? a[i + 1] : c;
    const real w = xi == W - 1 ? a[i + 1 - W] : c;
    return xi < W - 1 ? r : w;
}

// A software prefetch of the cache line holding *p (tv_fused.cl's strips, CPU devices only):
// clang's built-in on CPU devices whose compiler is clang (PoCL, Intel's CPU runtime; the
// runtime defines CLFZA_CPU), nothing elsewhere (Oclgrind cannot run llvm.prefetch). Never
// faults; the kernels still keep the address inside the buffer.
#if defined(__clang__) && defined(CLFZA_CPU)
#define PREFETCH_LINE(p) __builtin_prefetch(p)
#else
#define PREFETCH_LINE(p) ((void)(p))
#endif

// Kernels written in float16 vectors, 16 columns of a row per work-item (admm_update16,
// twist_combine16, admm_update_rhs16, resid_grad_spec8, admm_solve_spec8), are not to be
// vectorised again across work-items: Intel's CPU compiler did so without a hint (resid_grad_spec8
// 0.85 -> 2.6 ms at 2048^2, spectrum.cl). vec_type_hint(float16) stopped it but made its build log
// warn "Kernel can't be vectorized due to unsupported vec type hint" on every build; its own
// intel_vec_len_hint(1) asks for the same (the build log says "was not vectorized" for these
// kernels under both) without a warning. Other compilers keep vec_type_hint (PoCL and GPUs
// take it as a hint; an unknown attribute would be a warning there). The runtime defines
// CLFZA_INTEL_CPU on Intel's CPU runtime.
#ifdef CLFZA_INTEL_CPU
#define KERNEL_VEC16 __kernel __attribute__((intel_vec_len_hint(1)))
#else
#define KERNEL_VEC16 __kernel __attribute__((vec_type_hint(float16)))
#endif

#ifndef REAL_IS_DOUBLE
// float32 vector helpers (tv_fused.cl's one-pass kernels, spectrum.cl's row-vector kernels).
// On PoCL (CLFZA_CLANG_BUILTINS) as clang vector built-ins and plain operators: PoCL 3.0 from
// pip did not inline shuffle, vload16, vstore8, select, sqrt or min into tv_fused.cl's kernels
// ("conflicting attributes"), and each lane shift or load became a call (2.9x slower at 512^2,
// 3.3x at 2048^2 on a 2-core Xeon). Elsewhere the portable OpenCL built-ins. Same results bit
// for bit: lane moves, loads and stores, a select, and IEEE sqrt per lane.
#ifdef CLFZA_CLANG_BUILTINS
// 4-byte aligned vectors: loads/stores at any float address (vload16/vstore8 semantics)
typedef float16 __attribute__((aligned(4))) float16_u;
typedef float8 __attribute__((aligned(4))) float8_u;
#define LOAD16(p) (*(const float16_u *)(p))
#define LOAD16G(p) (*(__global const float16_u *)(p))
typedef float4 __attribute__((aligned(4))) float4_u;
typedef float2 __attribute__((aligned(4))) float2_u;
#define STORE8G(v, p) (*(__global float8_u *)(p) = (v))
#define STORE4G(v, p) (*(__global float4_u *)(p) = (v))
#define STORE2G(v, p) (*(__global float2_u *)(p) = (v))
#define STORE16P(v, p) (*(float16_u *)(p) = (v))
#define LOAD8G(p) (*(__global const float8_u *)(p))
#define STORE16G(v, p) (*(__global float16_u *)(p) = (v))
#define DUP8(a) __builtin_shufflevector(a, a, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7, 7)
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
#define STORE2G(v, p) vstore2(v, 0, p)
#define STORE16P(v, p) vstore16(v, 0, p)
#define LOAD8G(p) vload8(0, p)
#define STORE16G(v, p) vstore16(v, 0, p)
#define DUP8(a) shuffle(a, (uint16)(0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7, 7))
#define SEL16(a, b, m) select(a, b, m)
#define SHIFT_LEFT(a) shuffle(a, (uint16)(1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 15))
#define SHIFT_RIGHT(a) shuffle(a, (uint16)(0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14))
#define IMIN(a, b) min(a, b)
#define sqrt16(a) sqrt(a)
#endif

// the sum of a vector's lanes
inline float hsum16(const float16 v)
{
    const float8 a = v.lo + v.hi;
    const float4 b = a.lo + a.hi;
    const float2 c = b.lo + b.hi;
    return c.x + c.y;
}

// lanes first .. first + n - 1 of v to o[0 .. n - 1] (a row's last work-item, fewer columns)
inline void store_tail(__global float *o, const float16 v, const int first, const int n)
{
    float buf[16];
    STORE16P(v, buf);
    for (int k = 0; k < n; ++k)
        o[k] = buf[first + k];
}

// o[0 .. 15] of a row, or o[0 .. n - 1] and zeros when n < 16 lanes remain
inline float16 load_upto16(__global const float *o, const int n)
{
    if (n >= 16)
        return LOAD16G(o);
    float buf[16];
    for (int k = 0; k < 16; ++k)
        buf[k] = k < n ? o[k] : 0.0f;
    return LOAD16(buf);
}

inline void store_upto16(__global float *o, const float16 v, const int n)
{
    if (n >= 16)
        STORE16G(v, o);
    else
        store_tail(o, v, 0, n);
}
#endif
