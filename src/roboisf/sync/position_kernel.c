/* C form of roboisf.sync.position_kernel (the numba kernels of position_kernel.py), loaded
 * with ctypes by roboisf.jit.native: the same arithmetic in the same order, so the same bits
 * (tests/test_native_position.py). Arrays come as a pointer to element [0] / [0, 0] and strides
 * in elements (the toolpath's tip may be any layout: Toolpath.with_tip keeps the caller's).
 * Built by pip install with the flags of roboisf.jit.native.CFLAGS (no fused multiply-add, no
 * fast-math). */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#ifndef ROBOISF_SOURCE_SHA256
#define ROBOISF_SOURCE_SHA256 ""
#endif
/* The SHA-256 of this file as built: roboisf.jit.native loads no library of another source. */
const char *roboisf_source_sha256 = ROBOISF_SOURCE_SHA256;

/* The toolpath's segments: starts A (rows, 3 columns), directions D, squared lengths L2, the
 * arc length at each start S0 and the lengths seglen, each with its strides in elements. */
typedef struct {
    const double *A, *D, *L2, *S0, *seglen;
    int64_t ars, acs, drs, dcs, l2s, s0s, sls;
} Segs;

#define ALWAYS_INLINE static inline __attribute__((always_inline))

/* _nearest: the nearest point of segments j0:j1 to sample (p0, p1, p2): its progress into *s
 * and its distance into *d. Python's max(u, 0.0) is u unless 0.0 > u, min(x, 1.0) is x unless
 * 1.0 < x (a NaN u stays NaN); the first minimum wins (d2 < best); no segment nearer than inf
 * (all NaN) leaves segment j0 at u = 0. */
ALWAYS_INLINE void nearest(double p0, double p1, double p2, const Segs *g, int64_t j0,
                           int64_t j1, double *s, double *d) {
    const int64_t ars = g->ars, acs = g->acs, drs = g->drs, dcs = g->dcs, l2s = g->l2s;
    double best = INFINITY;
    int64_t bj = j0;
    double bu = 0.0;
    for (int64_t w = j0; w < j1; w++) {
        const double *a = g->A + w * ars;
        const double *dd = g->D + w * drs;
        double r0 = p0 - a[0];
        double r1 = p1 - a[acs];
        double r2 = p2 - a[2 * acs];
        double l2 = g->L2[w * l2s];
        double den = l2 > 0 ? l2 : 1.0;
        double D0 = dd[0], D1 = dd[dcs], D2 = dd[2 * dcs];
        double u = (r0 * D0 + r1 * D1 + r2 * D2) / den;
        u = 0.0 > u ? 0.0 : u; /* max(u, 0.0) */
        u = 1.0 < u ? 1.0 : u; /* min(., 1.0) */
        double e0 = r0 - u * D0;
        double e1 = r1 - u * D1;
        double e2 = r2 - u * D2;
        double d2 = e0 * e0 + e1 * e1 + e2 * e2;
        if (d2 < best) {
            best = d2;
            bj = w;
            bu = u;
        }
    }
    *s = g->S0[bj * g->s0s] + bu * g->seglen[bj * g->sls];
    *d = sqrt(best);
}

/* np.searchsorted(a, key, side="right") as numba runs it: the first index whose element is
 * not <= key (a NaN key is past every element: n). */
static int64_t search_right(const double *a, int64_t st, int64_t n, double key) {
    if (isnan(key)) return n;
    int64_t lo = 0, hi = n;
    while (lo < hi) {
        int64_t mid = lo + ((hi - lo) >> 1);
        if (a[mid * st] <= key)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/* The body of project_segments for given strides (inlined twice: the usual C-contiguous
 * arrays with constant strides, and any layout). */
ALWAYS_INLINE void project_body(const double *P, int64_t M, int64_t prs, int64_t pcs,
                                const Segs *g, int64_t W, double *s, double *d) {
    for (int64_t b = 0; b < M; b++) {
        const double *p = P + b * prs;
        nearest(p[0], p[pcs], p[2 * pcs], g, 0, W, s + b, d + b);
    }
}

/* project_segments: the nearest point of the W segments to each of the M samples P: progress
 * into s, distance into d (both (M,), contiguous). W >= 1 (the caller checks). */
void project_segments(const double *P, int64_t M, int64_t prs, int64_t pcs, const double *A,
                      int64_t ars, int64_t acs, const double *D, int64_t drs, int64_t dcs,
                      const double *L2, int64_t l2s, const double *S0, int64_t s0s,
                      const double *seglen, int64_t sls, int64_t W, double *s, double *d) {
    Segs g = {A, D, L2, S0, seglen, ars, acs, drs, dcs, l2s, s0s, sls};
    if (prs == 3 && pcs == 1 && ars == 3 && acs == 1 && drs == 3 && dcs == 1 && l2s == 1 &&
        s0s == 1 && sls == 1) {
        Segs c = {A, D, L2, S0, seglen, 3, 1, 3, 1, 1, 1, 1};
        project_body(P, M, 3, 1, &c, W, s, d);
    } else {
        project_body(P, M, prs, pcs, &g, W, s, d);
    }
}

/* The body of track_blocks (_track_py) for given strides; sb, db: scratch of nb >= every
 * block's samples. Returns k; *s_prev, *last_on updated. */
ALWAYS_INLINE int64_t track_body(const double *P, int64_t M, int64_t prs, int64_t pcs,
                                 const double *travel, int64_t ts, int64_t nt, const Segs *g,
                                 int64_t nseg, double tol, double block, double margin,
                                 int64_t max_block, double *s, int64_t ss, int64_t k,
                                 double *s_prev_io, int64_t *last_on_io, double *sb,
                                 double *db) {
    double s_prev = *s_prev_io;
    int64_t last_on = *last_on_io;
    while (k < M) {
        if (!isfinite(s_prev)) break;
        int64_t k2 = search_right(travel, ts, nt, travel[k * ts] + block);
        /* max(k + 1, min(k2, k + max_block, M)) */
        int64_t m = k + max_block < k2 ? k + max_block : k2;
        m = M < m ? M : m;
        k2 = m > k + 1 ? m : k + 1;
        double ahead = travel[(k2 - 1) * ts] - travel[last_on * ts] + margin;
        int64_t j0 = search_right(g->S0, g->s0s, nseg, s_prev - margin) - 1;
        j0 = j0 > 0 ? j0 : 0;
        int64_t j1 = search_right(g->S0, g->s0s, nseg, s_prev + ahead);
        j1 = nseg < j1 ? nseg : j1;
        j1 = j0 + 1 > j1 ? j0 + 1 : j1;
        int hit = 0;
        for (int64_t b = k; b < k2; b++) {
            const double *p = P + b * prs;
            nearest(p[0], p[pcs], p[2 * pcs], g, j0, j1, sb + (b - k), db + (b - k));
            if (db[b - k] <= tol) hit = 1;
        }
        if (!hit) break;
        for (int64_t b = k; b < k2; b++) {
            if (db[b - k] <= tol) {
                double v = sb[b - k];
                s_prev = v > s_prev ? v : s_prev; /* max(s_prev, v) */
                s[b * ss] = s_prev;
                last_on = b;
            }
        }
        k = k2;
    }
    *s_prev_io = s_prev;
    *last_on_io = last_on;
    return k;
}

/* track_blocks (_track_py): track samples from k on while the tool stays in the search window,
 * writing the monotone progress into s; returns the k to resume at (M: done), *s_prev and
 * *last_on in/out; -1 when the block scratch cannot be allocated. The caller checks the
 * shapes: travel (nt >= M), s (>= M), the segments (nseg rows, nseg >= 1 when s_prev is
 * finite), 0 <= last_on < nt, max_block >= 1. */
int64_t track_blocks(const double *P, int64_t M, int64_t prs, int64_t pcs, const double *travel,
                     int64_t ts, int64_t nt, const double *A, int64_t ars, int64_t acs,
                     const double *D, int64_t drs, int64_t dcs, const double *L2, int64_t l2s,
                     const double *S0, int64_t s0s, const double *seglen, int64_t sls,
                     int64_t nseg, double tol, double block, double margin, int64_t max_block,
                     double *s, int64_t ss, int64_t k, double *s_prev, int64_t *last_on) {
    if (k >= M) return k;
    int64_t nb = M - k < max_block ? M - k : max_block; /* the most samples of a block */
    double *sb = malloc(2 * (size_t)nb * sizeof(double));
    if (sb == NULL) return -1;
    double *db = sb + nb;
    Segs g = {A, D, L2, S0, seglen, ars, acs, drs, dcs, l2s, s0s, sls};
    if (prs == 3 && pcs == 1 && ts == 1 && ars == 3 && acs == 1 && drs == 3 && dcs == 1 &&
        l2s == 1 && s0s == 1 && sls == 1 && ss == 1) {
        Segs c = {A, D, L2, S0, seglen, 3, 1, 3, 1, 1, 1, 1};
        k = track_body(P, M, 3, 1, travel, 1, nt, &c, nseg, tol, block, margin, max_block, s, 1,
                       k, s_prev, last_on, sb, db);
    } else {
        k = track_body(P, M, prs, pcs, travel, ts, nt, &g, nseg, tol, block, margin, max_block,
                       s, ss, k, s_prev, last_on, sb, db);
    }
    free(sb);
    return k;
}

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_position_kernel_c",
    "C kernels of roboisf.sync.position_kernel, called through ctypes (roboisf.jit.native).",
    -1, NULL};

PyMODINIT_FUNC PyInit__position_kernel_c(void) { return PyModule_Create(&module); }
