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
