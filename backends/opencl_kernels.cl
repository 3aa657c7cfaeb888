/* Kernels of the OpenCL backend (backends/opencl.py builds them once per metric kind).

   Compile-time defines, set by the host:
     METRIC_ELLIPSE        the metric is elliptic (l2, l2-axial); else polygonal
     K                     number of facets of a polygonal metric (any convex polygon)
     STRIDE                floats per site record (see below)
     BW, BH                pixels of one block of label_blocks (BW = BH = 4, 8 or 16)
     STRIP                 blocks side by side per work-item of label_blocks
     USE_INT64_ATOMICS     the device has cl_khr_int64_base_atomics; else the moment sums
                           are kept as split 32-bit counters (low word + carries)

   A site record (STRIDE floats), sorted by grid cell on the host:
     [0..1] p_hi = float32(p)            [2..3] p_lo = float32(p - p_hi)
     polygon: [4 + 2k, 5 + 2k] facet k,  d = max_k f_k . v
     ellipse: [4..6] = (l11, l21, l22),  the Cholesky factor of the site's quadratic
              form Q = L L^T, so d^2 = (l11 vx + l21 vy)^2 + (l22 vy)^2: a sum of squares,
              no cancellation in float32.
   v = x - p is formed first as (x - p_hi) - p_lo: x - p_hi is exact in float32 when
   both are close, so v carries float64-like accuracy into the dot products.

   Plain ?: instead of fmin/fmax/fabs: PoCL stops vectorising the work-group loop on
   those (measured: about 4x slower). */

#ifdef USE_INT64_ATOMICS
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable
#endif

/* The distance of a site record at offset v = (vx, vy) from its site: d for polygons,
   d^2 for ellipses (the comparison and the search bound take that into account).  One
   expression for one pixel (T = float) and for a row of pixels at one vy (T = a vector
   type): the block and the pixel kernels give the same labels. */
#ifdef METRIC_ELLIPSE
#define DISTANCE_AT_OFFSET(NAME, T)                                                     \
    inline T NAME(__global const float *rec, const T vx, const float vy)                \
    {                                                                                   \
        const T u = rec[4] * vx + rec[5] * vy;                                          \
        const float w = rec[6] * vy;                                                    \
        return u * u + w * w;                                                           \
    }
#else
#define DISTANCE_AT_OFFSET(NAME, T)                                                     \
    inline T NAME(__global const float *rec, const T vx, const float vy)                \
    {                                                                                   \
        T d = rec[4] * vx + rec[5] * vy;                                                \
        _Pragma("unroll") for (int k = 1; k < K; ++k)                                   \
        {                                                                               \
            const T e = rec[4 + 2 * k] * vx + rec[5 + 2 * k] * vy;                      \
            d = e > d ? e : d;                                                          \
        }                                                                               \
        return d;                                                                       \
    }
#endif
DISTANCE_AT_OFFSET(offset_distance, float)

/* The distance of a site record from pixel centre (px, py). */
inline float site_distance(__global const float *rec, const float px, const float py)
{
    return offset_distance(rec, (px - rec[0]) - rec[2], (py - rec[1]) - rec[3]);
}

/* ------------------------------------------------------------------------ moments */

/* A site's five sums share one 64-byte record (one cache line: the five atomics of a
   run or a block touch one line, not five). */
#ifdef USE_INT64_ATOMICS
typedef ulong acc_t;
inline void add_sum(volatile __global ulong *acc, const int q, const int n, const int site,
                    const ulong v)
{
    atom_add(acc + 8 * site + q, v);
}
#else
typedef uint acc_t;
/* A 64-bit sum as two 32-bit counters: low words at [16*site + q], high words at
   [16*site + 8 + q].  Each addition that wraps the low word adds one carry, so
   total = high * 2^32 + low whatever the order of the atomics. */
inline void add_sum(volatile __global uint *acc, const int q, const int n, const int site,
                    const ulong v)
{
    const uint vlo = (uint)v;
    const uint old = atomic_add(acc + 16 * site + q, vlo);
    const uint carry = old > 0xffffffffu - vlo ? 1u : 0u;
    const uint vhi = (uint)(v >> 32) + carry;
    if (vhi)
        atomic_add(acc + 16 * site + 8 + q, vhi);
}
#endif

/* Σ_{j=0..m} j^2 (0 for m < 0) */
inline ulong sum_squares(const long m)
{
    if (m < 0)
        return 0;
    const ulong u = (ulong)m;
    return u * (u + 1) * (2 * u + 1) / 6;
}

/* The sums of the run of pixels a..b of a row, times `sign`: 1 adds them, (ulong)-1 takes
   them away (the sums are kept modulo 2^64, the split counters too, so any order of
   additions and subtractions ends at the same sums). */
inline void flush_run(volatile __global acc_t *acc, const int n, const int site,
                      const int a, const int b, const int row, const ulong sign)
{
    const ulong len = (ulong)(b - a + 1);
    const ulong r = (ulong)row;
    add_sum(acc, 0, n, site, sign * len);
    add_sum(acc, 1, n, site, sign * ((ulong)(a + b) * len / 2));
    add_sum(acc, 2, n, site, sign * (r * len));
    add_sum(acc, 3, n, site, sign * (sum_squares(b) - sum_squares((long)a - 1)));
    add_sum(acc, 4, n, site, sign * (r * r * len));
}

/* The arguments of both label kernels, in the order the host sets them.  The region's
   mask: a byte per pixel for label_pixels, a bit per pixel in words per block for
   label_blocks (start_block says how).  With bits_stride > 0 (label_blocks, BW 8 or 16)
   label_blocks also leaves, for the walled step's row_runs, a bit per pixel of each row
   whose row below is in the same block: whether the pixel has the label below it
   (below_bits, bits_stride bytes a row, bit x % 8 of byte x / 8 for column x). */
#define LABEL_KERNEL_ARGS                                                               \
    const int width, const int height, const int ncx, const int ncy, const float cell,  \
        const float reach, const float slack, __global const int *cell_start,           \
        __global const float *cell_reach, __global const float *records,                \
        __global const float4 *site_pos,                                                \
        __global const int *site_index, __global const uchar *mask, const int use_mask, \
        __global int *labels, __global const int *site_rank, const int n, const int seed, \
        volatile __global acc_t *acc, const int sums, __global uchar *below_bits,       \
        const int bits_stride

/* One work-item per pixel: the nearest site, searched over a uniform grid of cells ring
   by ring (Chebyshev rings of cells around the pixel's cell).

   Stopping bound: every site satisfies |x - p_i| <= reach * d_i(x) with
   reach = circumradius * max_i s_i (gauge(v) >= |v| / circumradius, d_i = gauge / s_i),
   which holds for any angle, scale and aspect.  Once the rings 0..r have been searched,
   every unsearched site lies outside the block of cells and so at least `out` (the
   pixel's distance to the block's edge, edges on the raster border excluded) away: it
   cannot be nearer (or tie) once out > reach * best.  A cell in a ring is skipped the
   same way with its own reach (circumradius times the largest s_i in that cell), which
   keeps the search local where scales vary.  Both reaches carry a relative margin and
   `slack` (pixels, from the host) an absolute one against float32 rounding (of d, and of
   cell edges far from the origin), so near-ties are always evaluated and go to the lower
   index. */
__kernel void label_pixels(LABEL_KERNEL_ARGS)
{
    /* site_pos, site_rank, n, seed: label_blocks' site boxes and seeds (not used here:
       one pixel's search is already short, and a GPU runs it one lane per pixel); acc,
       sums: label_blocks' moments (here row_moments sums them) */
    const int j = get_global_id(0);
    const int i = get_global_id(1);
    if (j >= width || i >= height)
        return;
    const int pix = i * width + j;
    if (use_mask && !mask[pix]) {
        labels[pix] = -1;
        return;
    }
    const float px = (float)j + 0.5f;
    const float py = (float)i + 0.5f;
    int cx = (int)(px / cell);
    int cy = (int)(py / cell);
    cx = cx < ncx ? cx : ncx - 1;
    cy = cy < ncy ? cy : ncy - 1;

    float best = INFINITY;
    int best_idx = 0x7fffffff;
    float best_dist = INFINITY; /* d of the best site so far, after the last ring */

    for (int r = 0;; ++r) {
        const int y0 = cy - r > 0 ? cy - r : 0;
        const int y1 = cy + r < ncy - 1 ? cy + r : ncy - 1;
        for (int gy = y0; gy <= y1; ++gy) {
            const int on_edge_row = (gy == cy - r) || (gy == cy + r);
            const int step = on_edge_row ? 1 : 2 * r;
            /* y gap between the pixel and this row of cells */
            const float top = gy * cell, bottom = (gy + 1) * cell;
            const float gapy = py < top ? top - py : (py > bottom ? py - bottom : 0.0f);
            for (int gx = cx - r; gx <= cx + r; gx += step) {
                if (gx < 0 || gx >= ncx)
                    continue;
                const float left = gx * cell, right = (gx + 1) * cell;
                const float gapx = px < left ? left - px : (px > right ? px - right : 0.0f);
                const int c = gy * ncx + gx;
                const float cell_lim = cell_reach[c] * best_dist + slack;
                if (gapx * gapx + gapy * gapy > cell_lim * cell_lim)
                    continue;
                const int s1 = cell_start[c + 1];
                for (int s = cell_start[c]; s < s1; ++s) {
                    const float d = site_distance(records + s * STRIDE, px, py);
                    const int idx = site_index[s];
                    if (d < best || (d == best && idx < best_idx)) {
                        best = d;
                        best_idx = idx;
                    }
                }
            }
        }
#ifdef METRIC_ELLIPSE
        best_dist = sqrt(best);
#else
        best_dist = best > 0.0f ? best : 0.0f;
#endif
        const float lim = reach * best_dist + slack;
        /* distance from the pixel to the edge of the searched block of cells; an edge
           on the raster border has nothing beyond it */
        float out = INFINITY;
        if (cx - r > 0) {
            const float e = px - (cx - r) * cell;
            out = e < out ? e : out;
        }
        if (cx + r < ncx - 1) {
            const float e = (cx + r + 1) * cell - px;
            out = e < out ? e : out;
        }
        if (cy - r > 0) {
            const float e = py - (cy - r) * cell;
            out = e < out ? e : out;
        }
        if (cy + r < ncy - 1) {
            const float e = (cy + r + 1) * cell - py;
            out = e < out ? e : out;
        }
        if (out == INFINITY || out > lim)
            break;
    }
    labels[pix] = best_idx;
}

/* The same search for CPUs: one work-item per STRIP blocks of BW x BH pixels side by
   side.  Every pixel of a block visits the same sites, so the innermost loop runs over
   the block's pixels for one site, a row as one vector (a per-pixel loop over sites, as
   in label_pixels, is a serial argmin that CPUs run one lane wide).

   The search is the ring search above, with two cuts that leave the result unchanged
   (the nearest site under (d, index) does not depend on the order sites are tried, and
   a site is skipped only where the bound proves it cannot win or tie any pixel):
   - seeds: the sites that owned the block's four corner pixels in the previous call
     (the `labels` buffer still holds them; `seed` = 1 when they are labels of these
     sites) are tried first, so the bound is tight from the start; a Lloyd step moves
     sites little, and those sites are usually the owners again;
   - every site is tested on its own against the block's box (its distance to the box
     of pixel centres against its own reach times the largest best d of the block),
     not only its cell; the sites near a strip are listed once for its blocks.
   Without seeds, a block searches rings of cells until one held a site; then the
   bound above decides which further sites are tried (step 3, label_blocks). */

/* A row of a block as one BW-wide vector (BW = 4, 8 or 16): the searches and sums below
   work a row at a time, which PoCL's loop vectoriser does not always find on its own. */
#define CAT_(a, b) a##b
#define CAT(a, b) CAT_(a, b)
typedef CAT(int, BW) rowi;
typedef CAT(uint, BW) rowu;
typedef CAT(float, BW) rowf;
#define load_row CAT(vload, BW)
__constant int LANES[16] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15};

/* the largest, the sum and the smallest of a row's lanes, by halving */
inline float hmaxf(rowf v)
{
#if BW == 16
    const float8 a = v.lo > v.hi ? v.lo : v.hi;
    const float4 b = a.lo > a.hi ? a.lo : a.hi;
#elif BW == 8
    const float4 b = v.lo > v.hi ? v.lo : v.hi;
#else
    const float4 b = v;
#endif
    const float2 c = b.lo > b.hi ? b.lo : b.hi;
    return c.x > c.y ? c.x : c.y;
}

inline int hsum(rowi v)
{
#if BW == 16
    const int4 b = (v.lo + v.hi).lo + (v.lo + v.hi).hi;
#elif BW == 8
    const int4 b = v.lo + v.hi;
#else
    const int4 b = v;
#endif
    const int2 c = b.lo + b.hi;
    return c.x + c.y;
}

inline uint hmin(rowu v)
{
#if BW == 16
    const uint4 b = min(min(v.lo, v.hi).lo, min(v.lo, v.hi).hi);
#elif BW == 8
    const uint4 b = min(v.lo, v.hi);
#else
    const uint4 b = v;
#endif
    const uint2 c = min(b.lo, b.hi);
    return min(c.x, c.y);
}

DISTANCE_AT_OFFSET(row_distance, rowf)

/* Try one site on every pixel of a block, a row at a time (BEST, BEST_IDX: the block's
   bests; PXS: its pixel x centres; Y0: its top row). */
#define TRY_SITE(BEST, BEST_IDX, PXS, Y0, REC, IDX)                                     \
    {                                                                                   \
        __global const float *rec_ = (REC);                                             \
        const int idx_ = (IDX);                                                         \
        const rowf vx_ = ((PXS) - rec_[0]) - rec_[2];                                   \
        for (int yy = 0; yy < BH; ++yy) {                                               \
            const float vy_ = (((float)((Y0) + yy) + 0.5f) - rec_[1]) - rec_[3];        \
            const rowf d = row_distance(rec_, vx_, vy_);                                \
            const rowf b = load_row(0, (BEST)[yy]);                                     \
            const rowi bi = load_row(0, (BEST_IDX)[yy]);                                \
            const rowi better = d < b | (d == b & idx_ < bi);                           \
            CAT(vstore, BW)(better ? d : b, 0, (BEST)[yy]);                             \
            CAT(vstore, BW)(better ? (rowi)(idx_) : bi, 0, (BEST_IDX)[yy]);              \
        }                                                                               \
    }

/* The largest best d over the block's live pixels, as a distance (sqrt for ellipses). */
inline float worst_of(const float best[BH][BW], const int live[BH][BW])
{
    rowf wv = 0.0f;
    for (int yy = 0; yy < BH; ++yy) {
        const rowf b = load_row(0, best[yy]);
        const rowf bl = load_row(0, live[yy]) != 0 ? b : (rowf)(0.0f);
        wv = bl > wv ? bl : wv;
    }
    const float worst = hmaxf(wv);
#ifdef METRIC_ELLIPSE
    return sqrt(worst);
#else
    return worst > 0.0f ? worst : 0.0f;
#endif
}

/* The moments of a work-item's blocks: each block is summed once per label in it (a
   block spans a few cells): each pass takes the lowest label not yet summed and sums all
   its pixels at once, in block-local coordinates that fit an int, shifted to the
   raster's origin in 64 bits.  The sums gather in a small table of the work-item's
   labels (its blocks share most of them) and go to the device's sums with one atomic
   each when the table is full and at the end: a few atomics per label and work-item,
   not one per run of a row (row_moments), and the labels are not read back. */
#define TABLE 8
typedef struct {
    int used;
    int site[TABLE];
    ulong sum[TABLE][5];
} sums_table;

inline void flush_table(volatile __global acc_t *acc, const int n, sums_table *t)
{
    for (int e = 0; e < t->used; ++e)
        for (int q = 0; q < 5; ++q)
            add_sum(acc, q, n, t->site[e], t->sum[e][q]);
    t->used = 0;
}

inline void block_sums(volatile __global acc_t *acc, const int n, sums_table *t,
                       const int best_idx[BH][BW], const int live[BH][BW], const int x0,
                       const int y0)
{
    const rowi xs = load_row(0, LANES), xs2 = xs * xs;
    rowi lab[BH]; /* -1: outside the region, or summed already */
    for (int yy = 0; yy < BH; ++yy)
        lab[yy] = load_row(0, best_idx[yy]) | (load_row(0, live[yy]) == 0);
    for (;;) {
        rowu low = (rowu)(0xffffffffu); /* -1 as unsigned is above every label */
        for (int yy = 0; yy < BH; ++yy)
            low = min(low, CAT(as_uint, BW)(lab[yy]));
        const int site = (int)hmin(low);
        if (site == -1)
            break;
        rowi c = 0, sy = 0, syy = 0; /* per lane (column): count, Σ yy, Σ yy² */
        for (int yy = 0; yy < BH; ++yy) {
            const rowi m = lab[yy] == site; /* -1 where this label */
            c -= m;
            sy += m & yy;
            syy += m & (yy * yy);
            lab[yy] |= m;
        }
        const rowi sx = c * xs, sxx = c * xs2;
        int e = 0;
        while (e < t->used && t->site[e] != site)
            ++e;
        if (e == TABLE) {
            flush_table(acc, n, t);
            e = 0;
        }
        if (e == t->used) {
            t->used = e + 1;
            t->site[e] = site;
            for (int q = 0; q < 5; ++q)
                t->sum[e][q] = 0;
        }
        const ulong len = (ulong)hsum(c), X = (ulong)x0, Y = (ulong)y0;
        const ulong lx = (ulong)hsum(sx), lxx = (ulong)hsum(sxx);
        const ulong ly = (ulong)hsum(sy), lyy = (ulong)hsum(syy);
        t->sum[e][0] += len;
        t->sum[e][1] += len * X + lx;
        t->sum[e][2] += len * Y + ly;
        t->sum[e][3] += len * X * X + 2 * X * lx + lxx;
        t->sum[e][4] += len * Y * Y + 2 * Y * ly + lyy;
    }
}

/* Steps 1 and 2 of the block at (x0, y0): its live pixels, its seeds and their bests,
   or the rings' without seeds.  0 if no pixel of it is live (its labels are written). */
inline int start_block(const int width, const int height, const int ncx, const int ncy,
                       const float cell, __global const int *cell_start,
                       __global const float *records, __global const int *site_index,
                       __global const ushort *mask_words, const int use_mask, __global int *labels,
                       __global const int *site_rank, const int n, const int seed, const int x0,
                       const int y0, float best[BH][BW], int best_idx[BH][BW], int live[BH][BW],
                       int seeds[4])
{
    const int xn = x0 + BW < width ? BW : width - x0; /* pixels of the block inside */
    const int yn = y0 + BH < height ? BH : height - y0;

    /* which pixels count: inside the raster and the region (1, else 0); the region's
       mask comes a bit per pixel, BH 16-bit words per block, side by side (bit x of word
       yy: pixel (x0 + x, y0 + yy), 0 off the raster): a strip's blocks read one or two
       cache lines of it, not a line for each of their rows */
    const rowi lanes = load_row(0, LANES);
    const rowi bit = (rowi)(1) << lanes;
    __global const ushort *words = mask_words + ((y0 / BH) * ((width + BW - 1) / BW) + x0 / BW) * BH;
    rowi any = 0;
    for (int yy = 0; yy < BH; ++yy) {
        rowi in = (lanes < xn) & (rowi)(yy < yn ? -1 : 0); /* -1 where live */
        if (use_mask)
            in &= ((rowi)(words[yy]) & bit) != 0;
        CAT(vstore, BW)(-in, 0, live[yy]);
        any |= in;
    }
    if (hsum(any) == 0) {
        for (int yy = 0; yy < yn; ++yy)
            for (int xx = 0; xx < xn; ++xx)
                labels[(y0 + yy) * width + x0 + xx] = -1;
        return 0;
    }

    int cx0 = (int)(((float)x0 + 0.5f) / cell), cx1 = (int)(((float)(x0 + xn - 1) + 0.5f) / cell);
    int cy0 = (int)(((float)y0 + 0.5f) / cell), cy1 = (int)(((float)(y0 + yn - 1) + 0.5f) / cell);
    cx0 = cx0 < ncx ? cx0 : ncx - 1;
    cx1 = cx1 < ncx ? cx1 : ncx - 1;
    cy0 = cy0 < ncy ? cy0 : ncy - 1;
    cy1 = cy1 < ncy ? cy1 : ncy - 1;

    for (int yy = 0; yy < BH; ++yy) {
        CAT(vstore, BW)((rowf)(INFINITY), 0, best[yy]);
        CAT(vstore, BW)((rowi)(0x7fffffff), 0, best_idx[yy]);
    }

    const rowf pxs = CAT(convert_float, BW)(x0 + load_row(0, LANES)) + 0.5f;

    /* 1. the previous owners of the corners (any valid index is a safe seed) */
    for (int q = 0; q < 4; ++q)
        seeds[q] = -1;
    int tried = 0;
    if (seed) {
        const int corner[4] = {y0 * width + x0, y0 * width + x0 + xn - 1,
                               (y0 + yn - 1) * width + x0, (y0 + yn - 1) * width + x0 + xn - 1};
        for (int q = 0; q < 4; ++q) {
            const int l = labels[corner[q]];
            int fresh = l >= 0 && l < n;
            for (int p = 0; p < q; ++p)
                fresh = fresh && seeds[p] != l;
            if (fresh) {
                seeds[q] = l;
                tried = 1;
                __global const float *rec = records + site_rank[l] * STRIDE;
                TRY_SITE(best, best_idx, pxs, y0, rec, l)
            }
        }
    }
    /* 2. without seeds: every site of the rings of cells around the block, until one
       ring held a site (then every pixel has a finite best) */
    for (int r = 0; !tried; ++r) {
        const int bx0 = cx0 - r, bx1 = cx1 + r, by0 = cy0 - r, by1 = cy1 + r;
        const int inner = bx1 - bx0;
        for (int gy = by0 > 0 ? by0 : 0; gy <= (by1 < ncy - 1 ? by1 : ncy - 1); ++gy) {
            const int step = (r == 0 || gy == by0 || gy == by1) ? 1 : inner;
            for (int gx = bx0; gx <= bx1; gx += step) {
                if (gx < 0 || gx >= ncx)
                    continue;
                const int c = gy * ncx + gx;
                const int s1 = cell_start[c + 1];
                for (int s = cell_start[c]; s < s1; ++s) {
                    __global const float *rec = records + s * STRIDE;
                    const int idx = site_index[s];
                    TRY_SITE(best, best_idx, pxs, y0, rec, idx)
                    tried = 1;
                }
            }
        }
        if (bx0 <= 0 && by0 <= 0 && bx1 >= ncx - 1 && by1 >= ncy - 1)
            break; /* the whole grid */
    }
    return 1;
}

/* One work-item per STRIP blocks side by side in a row of blocks: steps 1 and 2 per
   block, then step 3 for all of them at once, then their labels and sums.

   3. every site that can win or tie at a pixel x of a block lies within reach * d(x) <=
   reach * worst of the block, so within `ext` of the block's box: the cells under the
   strip's box grown by the largest `ext` hold them all.  A row of those cells is one run
   of the sorted sites; each site is tested by its own reach against each block's
   current worst best (which only falls as sites are tried), and tried on the blocks it
   may change.  A site tried twice on a block (a seed, or a ring's in step 2) changes
   nothing the second time. */
__kernel void label_blocks(LABEL_KERNEL_ARGS)
{
    const int y0 = get_global_id(1) * BH;
    const int xs0 = get_global_id(0) * STRIP * BW;
    if (y0 >= height || xs0 >= width)
        return;
    const int yn = y0 + BH < height ? BH : height - y0;
    float best[STRIP][BH][BW];
    int best_idx[STRIP][BH][BW], live[STRIP][BH][BW], seeds[STRIP][4];
    float worst[STRIP], bx0[STRIP], bx1[STRIP];
    int on[STRIP];
    float ext = 0.0f;
    for (int g = 0; g < STRIP; ++g) {
        const int x0 = xs0 + g * BW;
        on[g] = x0 < width && start_block(width, height, ncx, ncy, cell, cell_start, records,
                                          site_index, (__global const ushort *)mask, use_mask, labels, site_rank, n,
                                          seed, x0, y0, best[g], best_idx[g], live[g], seeds[g]);
        if (!on[g])
            continue;
        const int xn = x0 + BW < width ? BW : width - x0;
        bx0[g] = (float)x0 + 0.5f; /* the box of the block's pixel centres in x */
        bx1[g] = (float)(x0 + xn - 1) + 0.5f;
        worst[g] = worst_of(best[g], live[g]);
        const float e = reach * worst[g] + 2.0f * slack;
        ext = e > ext ? e : ext;
    }
    const float box_x0 = (float)xs0 + 0.5f, box_y0 = (float)y0 + 0.5f;
    const float box_x1 = (float)(xs0 + STRIP * BW - 1) + 0.5f, box_y1 = (float)(y0 + yn - 1) + 0.5f;
    int gx0 = (int)floor((box_x0 - ext) / cell), gx1 = (int)floor((box_x1 + ext) / cell);
    int gy0 = (int)floor((box_y0 - ext) / cell), gy1 = (int)floor((box_y1 + ext) / cell);
    gx0 = gx0 > 0 ? gx0 : 0;
    gy0 = gy0 > 0 ? gy0 : 0;
    gx1 = gx1 < ncx - 1 ? gx1 : ncx - 1;
    gy1 = gy1 < ncy - 1 ? gy1 : ncy - 1;
    for (int gy = gy0; gy <= gy1; ++gy) {
        const int s1 = cell_start[gy * ncx + gx1 + 1];
        for (int s = cell_start[gy * ncx + gx0]; s < s1; ++s) {
            const float4 p = site_pos[s]; /* x, y, reach of the site */
            const float gy_s = p.y < box_y0 ? box_y0 - p.y : (p.y > box_y1 ? p.y - box_y1 : 0.0f);
            int idx = -1;
            for (int g = 0; g < STRIP; ++g) {
                const float gx_s = p.x < bx0[g] ? bx0[g] - p.x : (p.x > bx1[g] ? p.x - bx1[g] : 0.0f);
                const float lim = p.z * worst[g] + slack;
                if (!on[g] || gx_s * gx_s + gy_s * gy_s > lim * lim)
                    continue;
                idx = idx < 0 ? site_index[s] : idx;
                if (idx == seeds[g][0] || idx == seeds[g][1] || idx == seeds[g][2] || idx == seeds[g][3])
                    continue; /* tried in step 1 */
                const rowf pxs = CAT(convert_float, BW)(xs0 + g * BW + load_row(0, LANES)) + 0.5f;
                TRY_SITE(best[g], best_idx[g], pxs, y0, records + s * STRIDE, idx)
                worst[g] = worst_of(best[g], live[g]);
            }
        }
    }
    sums_table table;
    table.used = 0;
    for (int g = 0; g < STRIP; ++g) {
        if (!on[g])
            continue;
        const int x0 = xs0 + g * BW;
        const int xn = x0 + BW < width ? BW : width - x0;
        rowi row_above = 0;
        for (int yy = 0; yy < yn; ++yy) {
            const rowi row = load_row(0, live[g][yy]) != 0 ? load_row(0, best_idx[g][yy]) : (rowi)(-1);
#if BW >= 8
            if (bits_stride > 0 && yy > 0) { /* lanes past the raster: any bits */
                const int bits = hsum((row_above == row) & ((rowi)(1) << load_row(0, LANES)));
                __global uchar *to = below_bits + (size_t)(y0 + yy - 1) * bits_stride + x0 / 8;
#if BW == 16
                *(__global ushort *)to = (ushort)bits;
#else
                *to = (uchar)bits;
#endif
            }
            row_above = row;
#endif
            if (xn == BW)
                CAT(vstore, BW)(row, 0, labels + (y0 + yy) * width + x0);
            else
                for (int xx = 0; xx < xn; ++xx)
                    labels[(y0 + yy) * width + x0 + xx] = live[g][yy][xx] ? best_idx[g][yy][xx] : -1;
        }
        if (sums)
            block_sums(acc, n, &table, best_idx[g], live[g], x0, y0);
    }
    if (sums)
        flush_table(acc, n, &table);
}

/* Per-site integer sums (count, Σj, Σi, Σj², Σi²) of the label raster.  One work-item
   per segment of `seg` pixels of a row: it walks the segment, and adds each run of equal
   labels in closed form with one atomic per sum, so the atomics are per run (a few per
   cell and row), not per pixel. */
__kernel void row_moments(const int width, const int height, const int seg,
                          __global const int *labels, const int n,
                          volatile __global acc_t *acc)
{
    const int s = get_global_id(0);
    const int i = get_global_id(1);
    const int j0 = s * seg;
    if (i >= height || j0 >= width)
        return;
    const int j1 = j0 + seg < width ? j0 + seg : width;
    __global const int *row = labels + (size_t)i * width;
    int cur = row[j0];
    int start = j0;
    for (int j = j0 + 1; j < j1; ++j) {
        const int l = row[j];
        if (l != cur) {
            if (cur >= 0)
                flush_run(acc, n, cur, start, j - 1, i, 1);
            cur = l;
            start = j;
        }
    }
    if (cur >= 0)
        flush_run(acc, n, cur, start, j1 - 1, i, 1);
}

/* ------------------------------------------------------------------ walled cells */

/* A walled step keeps one 4-connected piece of each cell (cvt.mosaic.split_cells).  A
   cell whose row runs include only one "top" run (no pixel of it has its own label
   straight above), or only one "bottom" run, is one piece: from any of its runs, steps to
   a touching run above (below) end at that run.  row_runs lists the runs of the region
   and counts both kinds per cell; suspect_runs keeps the runs of the cells with more
   than one of each, and the pieces_* kernels find their pieces.

   Each row of the raster has `cap` slots for its runs, row i's from slot i * cap on, in
   raster order: a kernel needs no other row's count to know where a row's runs are, and
   slots order runs as the raster does.  Every kernel here but suspect_cells takes a row
   (a work-item each) and walks its runs. */

/* 16 labels of a row from column j (j may be -1); columns off the row read -1 */
inline int16 row16(__global const int *row, const int j, const int width)
{
    if (j >= 0 && j + 16 <= width)
        return vload16(0, row + j);
    int v[16];
    for (int q = 0; q < 16; ++q)
        v[q] = j + q >= 0 && j + q < width ? row[j + q] : -1;
    return vload16(0, v);
}

/* the lanes of a comparison's result (-1 where true) as the bits of an integer */
inline uint lane_bits(const int16 m)
{
    const int16 w = m & (int16)(1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048, 4096, 8192,
                                16384, 32768);
    const int8 a = w.lo | w.hi;
    const int4 b = a.lo | a.hi;
    const int2 c = b.lo | b.hi;
    return (uint)(c.x | c.y);
}

/* the lanes where 64 labels of a row from column j (j may be -1) equal those of `l`, as
   the bits of an integer (columns off the row read -1) */
inline ulong window_bits(__global const int *row, const int j, const int width, const int16 l0,
                         const int16 l1, const int16 l2, const int16 l3)
{
    return (ulong)lane_bits(row16(row, j, width) == l0) |
           (ulong)lane_bits(row16(row, j + 16, width) == l1) << 16 |
           (ulong)lane_bits(row16(row, j + 32, width) == l2) << 32 |
           (ulong)lane_bits(row16(row, j + 48, width) == l3) << 48;
}

/* row_runs' end of run number k of its row (label `cell`, from pixel `first`, `length`
   pixels, `up` (`down`) where a pixel of it has its label straight above (below)): a top
   (bottom) run of its cell where none has, and listed where the row has room */
inline void end_run(volatile __global uint *ends, __global int2 *slots, __global int *slot_label,
                    const uint k, const uint cap, const int cell, const int first, const int length,
                    const uint up, const uint down)
{
    if (!up)
        atomic_inc(ends + 2 * cell);
    if (!down)
        atomic_inc(ends + 2 * cell + 1);
    if (k < cap) {
        slots[k] = (int2)(first, length);
        slot_label[k] = cell;
    }
}

/* Row i's runs of the region, each as (first pixel, length) at runs[i * cap + k] and
   its label at run_label[i * cap + k] (apart: suspect_runs reads the labels first), k
   from 0 in raster order; their number at row_count[i], and the most of any row at
   counts[0] (zeroed by the host: where it exceeds cap, the runs past cap are not listed
   and the host asks again with more room); ends[2 l], ends[2 l + 1] count the top and
   bottom runs of cell l (zeroed by the host).

   The row is read in windows of 64 pixels: where the label changes, and where a pixel
   has its own label straight above and below, as bits; a run's part of a window is a
   range of bits, so the work per window is per run, not per pixel.  The bits above and
   below come from the label kernel where it left them (below_bits, for the rows whose
   neighbour is in the same block of `period` rows), else from the rows' labels. */
__kernel void row_runs(const int width, const int height, __global const int *labels,
                       __global const ulong *below_bits, const int bits_stride, const int period,
                       const uint cap,
                       volatile __global uint *ends, __global int2 *runs,
                       __global int *run_label, __global uint *row_count,
                       volatile __global uint *counts)
{
    const int i = get_global_id(0);
    if (i >= height)
        return;
    /* the label kernel's bits of the row pairs inside its blocks of `period` rows (0:
       none), a 64-bit word per window, bits_stride bytes a row as it wrote them */
    const int words = bits_stride / 8;
    __global const ulong *bits_up = period > 0 && i % period != 0 ? below_bits + (size_t)(i - 1) * words : 0;
    __global const ulong *bits_down =
        period > 0 && i % period != period - 1 ? below_bits + (size_t)i * words : 0;
    __global const int *row = labels + (size_t)i * width;
    __global const int *above = row - width, *below = row + width; /* read only in the raster */
    __global int2 *slots = runs + (size_t)i * cap;
    __global int *slot_label = run_label + (size_t)i * cap;
    uint k = 0;
    int cur = -1, start = 0; /* the open run: its label (-1: none of ours) and first pixel */
    uint up = 0, down = 0;   /* whether a pixel of it has its label above, below */
    for (int j = 0; j < width; j += 64) {
        const int16 l0 = row16(row, j, width), l1 = row16(row, j + 16, width);
        const int16 l2 = row16(row, j + 32, width), l3 = row16(row, j + 48, width);
        /* lanes past the row read -1 */
        ulong change = ~window_bits(row, j - 1, width, l0, l1, l2, l3);
        ulong same_up = 0, same_down = 0;
        if (i > 0)
            same_up = bits_up ? bits_up[j / 64] : window_bits(above, j, width, l0, l1, l2, l3);
        if (i + 1 < height)
            same_down = bits_down ? bits_down[j / 64] : window_bits(below, j, width, l0, l1, l2, l3);
        int lab[64];
        vstore16(l0, 0, lab);
        vstore16(l1, 1, lab);
        vstore16(l2, 2, lab);
        vstore16(l3, 3, lab);
        ulong from = ~(ulong)0; /* the bits of the window from the open run's first lane on */
        while (change) {
            const int t = 63 - clz(change & -change);
            change &= change - 1;
            if (cur >= 0) { /* the open run ends before lane t */
                const ulong part = from & (((ulong)1 << t) - 1);
                end_run(ends, slots, slot_label, k++, cap, cur, i * width + start, j + t - start,
                        up || (same_up & part) != 0, down || (same_down & part) != 0);
            }
            cur = lab[t];
            start = j + t;
            up = down = 0;
            from = ~(((ulong)1 << t) - 1);
        }
        if (cur >= 0) {
            up = up || (same_up & from) != 0;
            down = down || (same_down & from) != 0;
        }
    }
    if (cur >= 0) /* the run reaches the row's end (a width that is a multiple of 64) */
        end_run(ends, slots, slot_label, k++, cap, cur, i * width + start, width - start, up, down);
    row_count[i] = k;
    atomic_max(counts, k);
}

/* Of the runs row_runs listed, those of the cells with more than one top and more than
   one bottom run: suspect_cells flags these cells (a byte each: the runs' lookups stay
   in the first-level cache, where the run counts would not); suspect_runs moves each
   row's to the front of its slots, in raster order, each its own piece (parent[k] = k),
   and leaves their number at row_kept[i].  The labels stay apart from the (first pixel,
   length) pairs: the kernels over runs read whole vectors of them. */
__kernel void suspect_cells(const int n, __global const uint *ends, __global uchar *suspect)
{
    const int l = get_global_id(0);
    if (l < n)
        suspect[l] = (ends[2 * l] > 1) & (ends[2 * l + 1] > 1);
}

__kernel void suspect_runs(const int height, const uint cap, __global const uint *row_count,
                           __global const uchar *suspect, __global int2 *runs,
                           __global int *run_label, __global uint *row_kept,
                           __global int *parent)
{
    const int i = get_global_id(0);
    if (i >= height)
        return;
    const uint first = (uint)i * cap, found = row_count[i] < cap ? row_count[i] : cap;
    uint k = first;
    for (uint r = first; r < first + found; ++r) {
        const int l = run_label[r];
        const int keep = suspect[l]; /* k <= r: a slot is read before it is written */
        runs[k] = runs[r];
        run_label[k] = l;
        parent[k] = (int)k;
        k += keep;
    }
    row_kept[i] = k - first;
}

/* The pieces of the listed cells (the runs suspect_runs kept), and the runs of the
   pieces their cells do not keep.  Runs are joined where they touch (same cell, adjacent
   rows, overlapping columns) by a union-find over their slots whose roots are the
   smallest slot of their piece, linked with atomic_min (Playne and Hawick's concurrent
   union: a link that loses a race is retried from the new roots). */

/* The root of run x's piece, halving the path on the way (each run passed then points
   to its grandparent): links go from a higher slot to a lower one, so a tall cell's runs
   would otherwise form chains as long as the cell is tall.  A halving store replaces a
   link by another to the same piece (pieces only merge) with a lower slot, and a union
   that loses a link to it retries from the old root: the pieces come out the same, each
   rooted at its smallest slot. */
inline int piece_root(volatile __global int *parent, int x)
{
    int p = parent[x];
    while (p != x) {
        const int g = parent[p];
        if (g == p)
            return p;
        parent[x] = g;
        x = g;
        p = parent[x];
    }
    return x;
}

/* The pieces kernels take a row each (the first `height`, with `cap` slots a row) and
   walk its kept runs: k is a kept run's slot. */
#define PIECES_KERNEL_ARGS const int height, const uint cap, __global const uint *row_kept
#define FOR_KEPT_RUNS(k)                                                  \
    const int row_ = get_global_id(0);                                    \
    if (row_ >= height)                                                   \
        return;                                                           \
    const uint first_ = (uint)row_ * cap, end_ = first_ + row_kept[row_]; \
    for (uint k = first_; k < end_; ++k)

/* 1. each row joins each of its runs to the runs of its cell in the row above that touch
   it, walking both rows' runs in order at once */
__kernel void pieces_join(PIECES_KERNEL_ARGS, const int width, __global const int2 *runs,
                          __global const int *run_label, volatile __global int *parent)
{
    const int i = get_global_id(0);
    if (i < 1 || i >= height)
        return;
    int r = (i - 1) * (int)cap; /* the first run above that may touch the current one */
    const int above_end = r + (int)row_kept[i - 1];
    const int end = i * (int)cap + (int)row_kept[i];
    for (int k = i * (int)cap; k < end && r < above_end; ++k) {
        const int2 run = runs[k];
        const int q = run.x - width; /* the pixel above the run's first */
        const int l = run_label[k];
        while (r < above_end && runs[r].x + runs[r].y <= q)
            ++r; /* ends before the run begins: before the next ones too */
        for (int t = r; t < above_end && runs[t].x < q + run.y; ++t) {
            if (run_label[t] != l)
                continue;
            int a = k, b = t;
            for (;;) {
                a = piece_root(parent, a);
                b = piece_root(parent, b);
                if (a == b)
                    break;
                const int hi_ = a > b ? a : b, lo_ = a > b ? b : a;
                const int old = atomic_min(parent + hi_, lo_);
                if (old == hi_)
                    break;
                a = old; /* hi_ was linked meanwhile: join its new root */
                b = lo_;
            }
        }
    }
}

/* 2. per listed cell (a work-item each) the piece that holds its site's pixel
   (site_at[l], from the host), or -1 where the site is not in its cell (on a wall, or
   off the raster): the kept run of the pixel's row that holds it, found by bisection
   (a row's kept runs are in raster order) */
__kernel void pieces_site(const int n, const int width, const uint cap, __global const uint *row_kept,
                          __global const uchar *suspect, __global const int2 *runs,
                          __global const int *run_label, volatile __global int *parent,
                          __global const int *site_at, __global int *site_piece)
{
    const int l = get_global_id(0);
    if (l >= n || !suspect[l])
        return;
    const int s = site_at[l];
    const int row = s / width;
    const uint first = (uint)row * cap;
    uint lo = first, hi = first + row_kept[row];
    while (lo < hi) { /* the first run that begins after the pixel */
        const uint mid = (lo + hi) / 2;
        if (runs[mid].x <= s)
            lo = mid + 1;
        else
            hi = mid;
    }
    int own = -1;
    if (lo > first && s < runs[lo - 1].x + runs[lo - 1].y && run_label[lo - 1] == l)
        own = piece_root(parent, (int)lo - 1);
    site_piece[l] = own;
}

/* the sums of a run (first pixel, length) taken from its cell's */
inline void drop_run(volatile __global acc_t *acc, const int n, const int cell, const int2 run,
                     const int width)
{
    const int i = run.x / width, j = run.x - i * width;
    flush_run(acc, n, cell, j, j + run.y - 1, i, (ulong)0 - 1);
}

/* 3. the runs outside the piece their cell keeps, where that is the site's: their sums
   are taken from their cell's (acc, as the label kernels left it), so the host reads
   the cut cells' sums and nothing else.  The runs of the cells whose site is not in
   them go to a list (`homeless`, their number at counts[1], zeroed by the host), for
   pieces_homeless. */
__kernel void pieces_dropped(PIECES_KERNEL_ARGS, __global const int2 *runs, __global const int *run_label,
                             volatile __global int *parent, __global const int *site_piece,
                             __global int2 *homeless, volatile __global uint *counts,
                             const int width, const int n, volatile __global acc_t *acc)
{
    FOR_KEPT_RUNS(k)
    {
        const int l = run_label[k];
        const int own = site_piece[l];
        if (own < 0) {
            homeless[atomic_inc(counts + 1)] = (int2)((int)k, 0);
            continue;
        }
        if (piece_root(parent, (int)k) == own)
            continue;
        drop_run(acc, n, l, runs[k], width);
    }
}

/* 4. the cells whose site is not in them keep their largest piece, of equal largest the
   one that begins last in raster order (the one with the largest root); the runs of
   the others are dropped as in pieces_dropped.  Such cells are few (a site on a wall,
   or off the raster), so their runs (listed by pieces_dropped, of any rows) go to one
   work-group, whose barriers order the steps: per run its piece, per piece its pixels,
   per cell the largest size, of those the last piece, then the runs dropped. */
__kernel void pieces_homeless(__global const int2 *runs, __global const int *run_label,
                              volatile __global int *parent, __global int2 *homeless,
                              __global const uint *counts, volatile __global int *size,
                              volatile __global int *largest, volatile __global int *last,
                              const int width, const int n, volatile __global acc_t *acc)
{
    const uint m = counts[1], step = get_local_size(0);
    for (uint t = get_local_id(0); t < m; t += step) { /* every root is a listed run */
        const int k = homeless[t].x;
        size[k] = 0;
        largest[run_label[k]] = 0;
        last[run_label[k]] = -1;
    }
    barrier(CLK_GLOBAL_MEM_FENCE);
    for (uint t = get_local_id(0); t < m; t += step) {
        const int k = homeless[t].x, r = piece_root(parent, k);
        homeless[t].y = r;
        atomic_add(size + r, runs[k].y);
    }
    barrier(CLK_GLOBAL_MEM_FENCE);
    for (uint t = get_local_id(0); t < m; t += step) {
        const int2 e = homeless[t];
        if (e.y == e.x)
            atomic_max(largest + run_label[e.x], size[e.x]);
    }
    barrier(CLK_GLOBAL_MEM_FENCE);
    for (uint t = get_local_id(0); t < m; t += step) {
        const int2 e = homeless[t];
        const int l = run_label[e.x];
        if (e.y == e.x && size[e.x] == largest[l])
            atomic_max(last + l, e.x);
    }
    barrier(CLK_GLOBAL_MEM_FENCE);
    for (uint t = get_local_id(0); t < m; t += step) {
        const int2 e = homeless[t];
        const int l = run_label[e.x];
        if (e.y == last[l])
            continue;
        drop_run(acc, n, l, runs[e.x], width);
    }
}
