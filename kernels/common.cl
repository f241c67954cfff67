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
