/* The fit of cvt.placement.fit_centres, one work-item per start and cell (fit_search):
   the second start of a cell's search where the host leaves it to the kernel
   (inscribed_start), then the search.  OpenCLBackend.fit_search builds it once per ball
   kind and facet count.

   Compile-time defines, set by the host:
     METRIC_ELLIPSE   the element's ball is an ellipse; else a polygon
     K                facets of a polygonal ball (1 for an ellipse: unused)

   The search is the host's (cvt.placement._fit_search) step for step: from its start,
   8 compass moves per repeat, a move kept when the element there grows by more than a
   part in 1e9 and the centre stays in a pixel of its cell, up to 3 repeats per step
   while the cell grows, steps 0.3, 0.15, 0.075 and 0.0375 of the size (at least 1 px).
   Sizes are the host's expressions term for term in float64 with contraction off, so
   every decision, centre and size is the host's bit for bit.  A trial stops reading its
   cell's samples as soon as one brings its size down to the size it must beat (the
   minimum is exact in any order), and it reads first the sample that stopped the last
   trial: most trials stop at that one sample. */

#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#ifndef VW
#define VW 4
#endif
#define GROWTH (1.0 + 1e-9)
#define REPEATS 3

__constant double STEPS[4] = {0.3, 0.15, 0.075, 0.0375};
__constant long FIT_LANES[16] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15};
__constant double MOVES[8][2] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}, {1, 1}, {1, -1}, {-1, 1}, {-1, -1}};

typedef struct
{
    __global const float *qx, *qy; /* the cell's samples */
    int count;
    double ax, ay;                  /* the ball's anchor: its site */
#ifdef METRIC_ELLIPSE
    double q0, q1, q2, grout;       /* quadratic form (qxx, qxy, qyy), grout G/2 */
    double gmax;                    /* above |grad(rho)| = |Q v| / rho: sqrt(lambda_max(Q)) */
#else
    double fx[K], fy[K], slack[K];  /* facets f_k = R(θ) n_k / h_k, G/2 |f_k| */
#endif
} cell_t;

/* hypot(x, y) as the host's C library computes it (glibc 2.35 and later, its path
   without fused multiply-add): sqrt(ax^2 + ay^2), corrected by its own rounding error
   (Borges, "An improved algorithm for hypot(a, b)", 2019), so that ellipses with grout
   get the host's sizes bit for bit; the device's own hypot where ax is huge or ay tiny
   (never in a raster's cells). */
#define HOST_HYPOT_DEF(NAME, T)                                                          \
    inline T NAME(const T x, const T y)                                                  \
    {                                                                                    \
        const T fx = fabs(x), fy = fabs(y);                                              \
        const T ax = fx < fy ? fy : fx, ay = fx < fy ? fx : fy;                          \
        const T h = sqrt(ax * ax + ay * ay);                                             \
        const T dy = h - ay, dx = h - ax;                                                \
        const T t1 = h <= 2.0 * ay ? ax * (2.0 * dy - ax) : 2.0 * dx * (ax - 2.0 * ay);  \
        const T t2 = h <= 2.0 * ay ? (dy - 2.0 * (ax - ay)) * dy                         \
                                   : (4.0 * dx - ay) * ay + dx * dx;                     \
        const T out = h - (t1 + t2) / (2.0 * h);                                         \
        const T odd = ax > 0x1p511 || ay < 0x1p-511 ? hypot(x, y) : out;                 \
        return ay <= ax * 0x1p-54 ? ax + ay : odd;                                       \
    }

/* The size at which the element centred at (px, py) reaches the sample (sx, sy) (the
   host's _Gauge.reach); ``shift`` holds the polygon's per-facet terms of that centre.
   One expression for one sample (T = double) and for VW samples (T = a vector type). */
#ifdef METRIC_ELLIPSE
#define REACH(NAME, T, HYPOT)                                                                \
    inline T NAME(const cell_t *c, const T sx, const T sy, const double px, const double py, \
                  const double *shift, const bool only_rho)                             \
    {                                                                                   \
        const T vx = sx - px, vy = sy - py;                                             \
        const T gx = c->q0 * vx + c->q1 * vy; /* Q v = rho grad(rho) */                 \
        const T gy = c->q1 * vx + c->q2 * vy;                                           \
        const T dot = vx * gx + vy * gy;                                                \
        const T rho = sqrt(dot > (T)0.0 ? dot : (T)0.0);                                \
        if (c->grout <= 0.0 || only_rho)                                                \
            return rho;                                                                 \
        const T grad = rho > (T)0.0 ? HYPOT(gx, gy)    / rho : (T)0.0;                \
        return rho - c->grout * grad;                                                   \
    }
#else
#define REACH(NAME, T, HYPOT)                                                                \
    inline T NAME(const cell_t *c, const T sx, const T sy, const double px, const double py, \
                  const double *shift, const bool only_rho)                             \
    {                                                                                   \
        const T ux = sx - c->ax, uy = sy - c->ay;                                       \
        T out = (c->fx[0] * ux + c->fy[0] * uy) - shift[0];                             \
        for (int k = 1; k < K; ++k)                                                     \
        {                                                                               \
            const T e = (c->fx[k] * ux + c->fy[k] * uy) - shift[k];                     \
            out = e > out ? e : out;                                                    \
        }                                                                               \
        return out;                                                                     \
    }
#endif
#define FIT_CAT(a, b) a##b
#define FIT_VEC(T, n) FIT_CAT(T, n)
typedef FIT_VEC(double, VW) doublev;
typedef FIT_VEC(long, VW) longv;
#ifdef METRIC_ELLIPSE
HOST_HYPOT_DEF(host_hypot_s, double)
HOST_HYPOT_DEF(host_hypot_v, doublev)
#endif
REACH(reach, double, host_hypot_s)
REACH(reach_v, doublev, host_hypot_v)

/* The element's size at (px, py): the least reach over the cell's samples, or any value
   <= ``beat`` once VW samples show it cannot exceed ``beat``; ``hint`` is the sample
   read first, and becomes the nearest sample read. */
inline double least(const cell_t *c, const double px, const double py, const double beat, int *hint)
{
    double shift[K];
#ifndef METRIC_ELLIPSE
    for (int k = 0; k < K; ++k)
        shift[k] = (c->fx[k] * (px - c->ax) + c->fy[k] * (py - c->ay)) + c->slack[k];
#endif
    const double m = reach(c, (double)c->qx[*hint], (double)c->qy[*hint], px, py, shift, false);
    if (m <= beat)
        return m;
    doublev mv = (doublev)(m);
    longv at = (longv)(*hint);
    const longv lane = FIT_VEC(vload, VW)(0, FIT_LANES);
    for (int j = 0; j < c->count; j += VW)
    {
        doublev sx, sy;
        if (j + VW <= c->count)
        {
            sx = FIT_VEC(convert_double, VW)(FIT_VEC(vload, VW)(0, c->qx + j));
            sy = FIT_VEC(convert_double, VW)(FIT_VEC(vload, VW)(0, c->qy + j));
        }
        else /* the last, short vector: its last sample repeated (no minimum changes) */
        {
            float tx[VW], ty[VW];
            for (int l = 0; l < VW; ++l)
            {
                const int at = j + l < c->count ? j + l : c->count - 1;
                tx[l] = c->qx[at];
                ty[l] = c->qy[at];
            }
            sx = FIT_VEC(convert_double, VW)(FIT_VEC(vload, VW)(0, tx));
            sy = FIT_VEC(convert_double, VW)(FIT_VEC(vload, VW)(0, ty));
        }
#ifdef METRIC_ELLIPSE
        if (c->grout > 0.0)
        {
            /* the grout term is >= 0 and at most G/2 |grad(rho)| <= G/2 sqrt(lambda_max(Q)):
               rho alone may end the reading, or show that no sample of VW lowers the least */
            const doublev rho = reach_v(c, sx, sy, px, py, shift, true);
            if (any(rho <= beat))
            {
                mv = rho <= beat ? rho : mv;
                at = rho <= beat ? lane + j : at;
                break;
            }
            if (!any(rho - c->grout * c->gmax < mv))
                continue;
        }
#endif
        const doublev r = reach_v(c, sx, sy, px, py, shift, false);
        const longv lower = r < mv;
        mv = lower ? r : mv;
        at = lower ? lane + j : at;
        if (any(r <= beat))
            break;
    }
    double best = mv.s0;
    long where = at.s0;
    for (int l = 1; l < VW; ++l)
    {
        const double v = ((double *)&mv)[l];
        if (v < best)
        {
            best = v;
            where = ((long *)&at)[l];
        }
    }
    *hint = (int)where;
    return best;
}

/* Whether (x, y) lies in a pixel labelled ``id`` (the host's own()). */
inline bool own(__global const int *labels, const int w, const int h, const double x, const double y, const int id)
{
    if (!(x >= 0.0 && x < (double)w && y >= 0.0 && y < (double)h))
        return false;
    return labels[(long)(int)y * w + (int)x] == id;
}

/* The pixel of cell ``id`` on the near side of contour sample (sx, sy): the edge's
   midpoint lies between two pixels, exactly one of them the cell's. */
inline int2 sample_pixel(__global const int *labels, const int w, const int id, const float sx, const float sy)
{
    const int x = (int)floor(sx), y = (int)floor(sy);
    if (sx == (float)x) /* a vertical edge x = c, between pixels c - 1 and c of row y */
        return (int2)(x > 0 && labels[(long)y * w + x - 1] == id ? x - 1 : x, y);
    return (int2)(x, y > 0 && labels[(long)(y - 1) * w + x] == id ? y - 1 : y);
}

/* How far pixel p lies from pixel z: max(|dx|, |dy|) (chessboard), else the squared
   Euclidean distance with rows ``sy`` and columns ``sx`` apart, as the host's transform
   forms it ((dy sy)^2 + (dx sx)^2). */
inline double depth_to(const int2 p, const int2 z, const int chess, const double sy, const double sx)
{
    const int dx = abs(p.x - z.x), dy = abs(p.y - z.y);
    if (chess)
        return (double)(dx > dy ? dx : dy);
    const double a = (double)dy * sy, b = (double)dx * sx;
    return a * a + b * b;
}

/* The depth of pixel p (its distance to the nearest of the cell's ``count`` sample
   pixels ``z``, as depth_to measures it), or any value < ``beat`` (<= ``beat`` when
   ``tie``) once one sample pixel shows that p cannot reach ``beat``.  The reading starts
   at ``hint`` and goes round from there (neighbours in the list are neighbours on the
   contour); ``hint`` becomes the nearest read. */
inline double depth_of(const int2 p, __global const int2 *z, const int count, const int chess,
                       const double sy, const double sx, const double beat, const bool tie, int *hint)
{
    const int from = *hint;
    double d = depth_to(p, z[from], chess, sy, sx);
    for (int t = 1; t < count && (d > beat || (tie && d == beat)); ++t)
    {
        const int j = from + t < count ? from + t : from + t - count;
        const double e = depth_to(p, z[j], chess, sy, sx);
        if (e < d)
        {
            d = e;
            *hint = j;
        }
    }
    return d;
}

/* The second start of a cell's search: the centre of the first pixel,
   in raster order, of those of the cell farthest from any pixel that is not inside it
   (a pixel whose 4 neighbours are all the cell's and in the raster): the host's
   _inscribed_centres.  The nearest such pixel of a pixel of the cell is always one of
   the cell's own pixels beside its contour, one per contour sample: a path from a
   foreign pixel towards the cell's pixel enters the cell through one, no farther along
   either axis, so the least over them is the transform's value bit for bit.  The depth
   of the site's pixel (when it is the cell's) is a first bound; then each pixel of the
   cell's box, in raster order, reads first the sample that decided the last one and
   stops as soon as it cannot beat the bound (or tie it, before the bound's pixel). */
inline double2 inscribed_start(const int w, const int h, __global const int *labels,
                               __global const float *cx, __global const float *cy, const int count,
                               const int id, const int chess, const double sy, const double sx,
                               const double ax, const double ay,
                               __global int2 *z) /* (count,): scratch */
{
    for (int j = 0; j < count; ++j)
        z[j] = sample_pixel(labels, w, id, cx[j], cy[j]);
    float x0 = cx[0], x1 = cx[0], y0 = cy[0], y1 = cy[0];
    for (int j = 1; j < count; ++j)
    {
        x0 = cx[j] < x0 ? cx[j] : x0;
        x1 = cx[j] > x1 ? cx[j] : x1;
        y0 = cy[j] < y0 ? cy[j] : y0;
        y1 = cy[j] > y1 ? cy[j] : y1;
    }
    const int c0 = max((int)floor(x0) - 1, 0), c1 = min((int)ceil(x1) + 1, w);
    const int r0 = max((int)floor(y0) - 1, 0), r1 = min((int)ceil(y1) + 1, h);
    int hint = 0;
    double best = -1.0; /* the depth to beat; tied too until a pixel holds it */
    bool held = false;
    int2 at = (int2)(c0, r0);
    if (own(labels, w, h, ax, ay, id))
    {
        const int2 p = (int2)((int)ax, (int)ay);
        best = depth_of(p, z, count, chess, sy, sx, -INFINITY, false, &hint);
    }
    for (int r = r0; r < r1; ++r)
        for (int c = c0; c < c1; ++c)
        {
            if (labels[(long)r * w + c] != id)
                continue;
            const int2 p = (int2)(c, r);
            const double d = depth_of(p, z, count, chess, sy, sx, best, !held, &hint);
            if (d > best || (!held && d == best))
            {
                best = d;
                held = true;
                at = p;
            }
        }
    return (double2)(at.x + 0.5, at.y + 0.5);
}

__kernel void fit_search(const int w, const int h, __global const int *labels,
                         __global const float *qx, __global const float *qy,
                         __global const long *first, __global const int *counts,
                         __global const int *ids, const int m,
                         __global const double *anchor, /* (M, 2) */
                         __global const double *coef,   /* (M, 2K) fx then fy; ellipse (M, 3) */
                         __global const double *slack,  /* (K,) */
                         const double grout,
                         __global const double *starts, /* (2, M, 2): the second unless ``depth`` */
                         const int depth,               /* 1 chessboard, 2 Euclidean: find the second */
                         const double sy, const double sx,
                         __global int2 *pixels,         /* (S,): scratch of inscribed_start */
                         __global double *centres,      /* (2, M, 2) */
                         __global double *sizes)        /* (2, M) */
{
    const int g = get_global_id(0);
    if (g >= 2 * m)
        return;
    const int i = g % m;
    const int id = ids[i];
    cell_t c;
    c.qx = qx + first[i];
    c.qy = qy + first[i];
    c.count = counts[i];
    c.ax = anchor[2 * i];
    c.ay = anchor[2 * i + 1];
#ifdef METRIC_ELLIPSE
    c.q0 = coef[3 * i];
    c.q1 = coef[3 * i + 1];
    c.q2 = coef[3 * i + 2];
    c.grout = grout;
    {
        const double mid = 0.5 * (c.q0 + c.q2), dev = 0.5 * (c.q0 - c.q2);
        c.gmax = sqrt(mid + sqrt(dev * dev + c.q1 * c.q1)) * (1.0 + 1e-6); /* rounding kept above */
    }
#else
    for (int k = 0; k < K; ++k)
    {
        c.fx[k] = coef[2 * K * i + k];
        c.fy[k] = coef[2 * K * i + K + k];
        c.slack[k] = slack[k];
    }
#endif
    double cx = starts[2 * g], cy = starts[2 * g + 1];
    if (g >= m && depth)
    {
        const double2 p = inscribed_start(w, h, labels, c.qx, c.qy, c.count, id, depth == 1, sy, sx,
                                          c.ax, c.ay, pixels + first[i]);
        cx = p.x;
        cy = p.y;
    }
    int hint = 0;
    double b = 0.0;
    if (own(labels, w, h, cx, cy, id))
    {
        const double s = least(&c, cx, cy, -INFINITY, &hint);
        b = s > 0.0 ? s : 0.0;
    }
    for (int f = 0; f < 4; ++f)
    {
        for (int r = 0; r < REPEATS; ++r)
        {
            const double step = STEPS[f] * (b > 1.0 ? b : 1.0);
            bool grew = false;
            for (int mv = 0; mv < 8; ++mv)
            {
                const double tx = cx + step * MOVES[mv][0], ty = cy + step * MOVES[mv][1];
                if (!own(labels, w, h, tx, ty, id))
                    continue;
                const double beat = b * GROWTH;
                const double s = least(&c, tx, ty, beat, &hint);
                if (s > beat)
                {
                    cx = tx;
                    cy = ty;
                    b = s;
                    grew = true;
                }
            }
            if (!grew)
                break;
        }
    }
    centres[2 * g] = cx;
    centres[2 * g + 1] = cy;
    sizes[g] = b;
}
