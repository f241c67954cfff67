// Memory-bandwidth probe for the machine's speed limit (docs/design.md s.5, s.6).
// STREAM triad a = b + s c, one element per work-item along contiguous memory so that PoCL
// vectorises across work-items. Counts 3 arrays of traffic per element.

__kernel void triad(__global real *a, __global const real *b, __global const real *c,
                    const real s, const int n)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    a[i] = b[i] + s * c[i];
}
