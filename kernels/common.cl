// Shared definitions, prepended to every clfza program.
// REAL_IS_DOUBLE selects float64 (needs cl_khr_fp64); the default is float32.
#ifdef REAL_IS_DOUBLE
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
typedef double real;
typedef double2 real2;
#define SQRT(x) sqrt(x)
#else
typedef float real;
typedef float2 real2;
// __builtin_sqrtf lets PoCL vectorise across work-items where sqrt() blocked it (DESIGN s.6);
// other compilers get the portable built-in.
#if defined(__clang__) && defined(CLFZA_POCL)
#define SQRT(x) __builtin_sqrtf(x)
#else
#define SQRT(x) sqrt(x)
#endif
#endif

// Periodic x-neighbours without gathers (DESIGN s.6). Wrapped indices (xi == 0 ? W - 1 : xi - 1)
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
