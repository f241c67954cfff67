// DnCNN (issue 38): 3x3 circular cross-correlation + folded BatchNorm bias + ReLU,
// channels-last, float32. Reference: clfza/denoisers/_reference.py (dncnn_reference, folded=True).
//
// Layouts (clfza/denoisers/_opencl.py): images (N, H, W); activations (N, H, W, F) with
// F = 64 features, in two ping-pong buffers that every layer reuses; weights of a 64 -> 64 layer
// w[tap][c][o] with tap = 3 di + dj (the flax kernel (3, 3, in, out) as stored, BatchNorm's scale
// folded in), of the first layer w0[tap][o], of the last wl[tap][c]; biases b[o].
// out[n, y, x, o] = sum_{di, dj, c} a[n, (y + di - 1) mod H, (x + dj - 1) mod W, c] w[di, dj, c, o].
//
// Launches: dncnn_first and dncnn_last over (W, H, N), one pixel per work-item, 64 outputs
// (first) or 64 inputs (last) as four float16 vectors; the 64 -> 64 layers either
//  - dncnn_mid (CPU devices): PX consecutive pixels of a row per work-item, all 64 outputs in
//    4 PX float16 accumulators (vectorised over output channels), range (ceil(W / PX), H, N); or
//  - dncnn_mid_tiled (GPUs): a 16 x 16 output tile per work-group of 16 x 8 work-items, each two
//    pixels (rows ly, ly + 8) x OG output channels; the input tile with its 1-pixel circular halo
//    goes through local memory, CB channels at a time; range (16 ceil(W/16), 8 ceil(H/16),
//    N * 64 / OG) with work-groups (16, 8, 1).

#define F 64
#ifndef PX
#define PX 4
#endif
#ifndef OG
#define OG 32
#endif
#ifndef CB
#define CB 16
#endif
#define TW 16
#define TH 16
#define LY 8

// Plain multiply-adds (contracted to FMAs: OpenCL's FP_CONTRACT is on by default) and a ReLU as
// a vector select: fma() and fmax() of a float16 are library calls on PoCL, and pip's PoCL 3.0
// cannot even compile them for some CPUs (LLVM "Cannot select ... fma"; see common.cl).
inline float16 relu16(const float16 v) { return v > (float16)(0.0f) ? v : (float16)(0.0f); }
inline float4 relu4(const float4 v) { return v > (float4)(0.0f) ? v : (float4)(0.0f); }

inline int wrap(const int v, const int n)
{
    const int r = v % n;
    return r < 0 ? r + n : r;
}

// first layer: 1 input channel (the image; the N variants' constant sigma channel is the bias
// sigma * sbias, exact under circular padding), ReLU
__kernel
void dncnn_first(__global const float *restrict img, __global const float16 *restrict w0,
                 __global const float16 *restrict b0, __global const float16 *restrict sbias,
                 const float sigma, __global float16 *restrict out, const int W, const int H)
{
    const int x = get_global_id(0), y = get_global_id(1), n = get_global_id(2);
    if (x >= W || y >= H) return;
    __global const float *im = img + (size_t)n * H * W;
    float16 acc[4];
    for (int g = 0; g < 4; g++) acc[g] = b0[g] + sigma * sbias[g];
    for (int di = 0; di < 3; di++) {
        const int yy = wrap(y + di - 1, H);
        for (int dj = 0; dj < 3; dj++) {
            const float v = im[yy * W + wrap(x + dj - 1, W)];
            for (int g = 0; g < 4; g++) acc[g] += v * w0[(di * 3 + dj) * 4 + g];
        }
    }
    __global float16 *o = out + (((size_t)n * H + y) * W + x) * 4;
    for (int g = 0; g < 4; g++) o[g] = relu16(acc[g]);
}

// last layer: 64 -> 1 channel, fused with the residual: out = img - conv(a, wl)
__kernel
void dncnn_last(__global const float16 *restrict a, __global const float16 *restrict wl,
                __global const float *restrict img, __global float *restrict out, const int W,
                const int H)
{
    const int x = get_global_id(0), y = get_global_id(1), n = get_global_id(2);
    if (x >= W || y >= H) return;
    float16 acc = (float16)(0.0f);
    for (int di = 0; di < 3; di++) {
        const size_t row = ((size_t)n * H + wrap(y + di - 1, H)) * W;
        for (int dj = 0; dj < 3; dj++) {
            __global const float16 *p = a + (row + wrap(x + dj - 1, W)) * 4;
            __global const float16 *q = wl + (di * 3 + dj) * 4;
            for (int g = 0; g < 4; g++) acc += p[g] * q[g];
        }
    }
    const float8 h8 = acc.lo + acc.hi;
    const float4 h4 = h8.lo + h8.hi;
    const float2 h2 = h4.lo + h4.hi;
    const size_t i = ((size_t)n * H + y) * W + x;
    out[i] = img[i] - (h2.x + h2.y);
}

// a 64 -> 64 layer on CPU devices: PX pixels x 64 outputs per work-item, ReLU(conv + b)
__kernel
void dncnn_mid(__global const float *restrict a, __global const float16 *restrict w,
               __global const float16 *restrict b, __global float16 *restrict out, const int W,
               const int H)
{
    const int x0 = get_global_id(0) * PX, y = get_global_id(1), n = get_global_id(2);
    if (x0 >= W || y >= H) return;
    int col[PX + 2];
#pragma unroll
    for (int k = 0; k < PX + 2; k++) col[k] = wrap(x0 + k - 1, W) * F;
    float16 acc[PX][4];
#pragma unroll
    for (int p = 0; p < PX; p++) {
#pragma unroll
        for (int g = 0; g < 4; g++) acc[p][g] = b[g];
    }
    for (int di = 0; di < 3; di++) {
        __global const float *row = a + ((size_t)n * H + wrap(y + di - 1, H)) * W * F;
        __global const float16 *wr = w + di * 3 * F * 4;
        for (int c = 0; c < F; c++) {
            float v[PX + 2];
#pragma unroll
            for (int k = 0; k < PX + 2; k++) v[k] = row[col[k] + c];
#pragma unroll
            for (int dj = 0; dj < 3; dj++) {
                __global const float16 *wt = wr + (dj * F + c) * 4;
#pragma unroll
                for (int g = 0; g < 4; g++) {
                    const float16 wg = wt[g];
#pragma unroll
                    for (int p = 0; p < PX; p++) acc[p][g] += v[p + dj] * wg;
                }
            }
        }
    }
    __global float16 *o = out + (((size_t)n * H + y) * W + x0) * 4;
#pragma unroll
    for (int p = 0; p < PX; p++) {
        if (x0 + p < W) {
#pragma unroll
            for (int g = 0; g < 4; g++) o[p * 4 + g] = relu16(acc[p][g]);
        }
    }
}

// a 64 -> 64 layer on GPUs: tiled through local memory (see the top of this file)
__kernel __attribute__((reqd_work_group_size(TW, LY, 1)))
void dncnn_mid_tiled(__global const float *restrict a, __global const float4 *restrict w,
                     __global const float4 *restrict b, __global float4 *restrict out,
                     const int W, const int H)
{
    __local float tile[CB][TH + 2][TW + 2];
    const int lx = get_local_id(0), ly = get_local_id(1);
    const int bx = get_group_id(0) * TW, by = get_group_id(1) * TH;
    const int ngroups = F / OG;
    const int n = get_global_id(2) / ngroups, og = get_global_id(2) % ngroups;
    const int lid = ly * TW + lx;
    __global const float *an = a + (size_t)n * H * W * F;
    float4 acc0[OG / 4], acc1[OG / 4];
#pragma unroll
    for (int q = 0; q < OG / 4; q++) {
        acc0[q] = b[og * (OG / 4) + q];
        acc1[q] = acc0[q];
    }
    for (int c0 = 0; c0 < F; c0 += CB) {
        barrier(CLK_LOCAL_MEM_FENCE);
        // the (TH + 2) x (TW + 2) x CB input tile, channel fastest in global memory
        for (int i = lid; i < (TH + 2) * (TW + 2) * CB; i += TW * LY) {
            const int c = i % CB, pix = i / CB;
            const int tx = pix % (TW + 2), ty = pix / (TW + 2);
            const int gx = wrap(bx + tx - 1, W), gy = wrap(by + ty - 1, H);
            tile[c][ty][tx] = an[((size_t)gy * W + gx) * F + c0 + c];
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        for (int c = 0; c < CB; c++) {
#pragma unroll
            for (int di = 0; di < 3; di++) {
#pragma unroll
                for (int dj = 0; dj < 3; dj++) {
                    const float v0 = tile[c][ly + di][lx + dj];
                    const float v1 = tile[c][ly + LY + di][lx + dj];
                    __global const float4 *wt = w + ((di * 3 + dj) * F + c0 + c) * (F / 4)
                                                + og * (OG / 4);
#pragma unroll
                    for (int q = 0; q < OG / 4; q++) {
                        const float4 wq = wt[q];
                        acc0[q] += v0 * wq;
                        acc1[q] += v1 * wq;
                    }
                }
            }
        }
    }
    const int x = bx + lx, y0 = by + ly, y1 = by + ly + LY;
    if (x < W && y0 < H) {
        __global float4 *o = out + (((size_t)n * H + y0) * W + x) * (F / 4) + og * (OG / 4);
#pragma unroll
        for (int q = 0; q < OG / 4; q++) o[q] = relu4(acc0[q]);
    }
    if (x < W && y1 < H) {
        __global float4 *o = out + (((size_t)n * H + y1) * W + x) * (F / 4) + og * (OG / 4);
#pragma unroll
        for (int q = 0; q < OG / 4; q++) o[q] = relu4(acc1[q]);
    }
}
