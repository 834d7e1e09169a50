/* C form of roboisf.parts.mesh_kernel (the numba kernels of mesh_kernel.py), loaded with ctypes
 * by roboisf.jit.native: the same arithmetic in the same order, so the same bits
 * (tests/test_native_mesh.py). Arrays come as a pointer to element [0, 0] and, where a caller
 * may pass another layout, strides in elements; the mesh's own arrays (triangles, grid, BVH)
 * are C-contiguous. An index read from an array wraps when negative, as numba's indexing does.
 * Built by pip install with the flags of roboisf.jit.native.CFLAGS (no fused multiply-add, no
 * fast-math). */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#ifndef ROBOISF_SOURCE_SHA256
#define ROBOISF_SOURCE_SHA256 ""
#endif
/* The SHA-256 of this file as built: roboisf.jit.native loads no library of another source. */
const char *roboisf_source_sha256 = ROBOISF_SOURCE_SHA256;

/* Return codes of the functions that divide: Python raises ZeroDivisionError on ERR_ZERODIV,
 * as numba's kernels do (error model "python"). */
#define OK 0
#define ERR_ZERODIV 1

/* numba's a[i] for a negative i: counted from the end. */
static inline int64_t wrap(int64_t i, int64_t n) { return i < 0 ? i + n : i; }

/* numba's math.floor(x) (an int64): the truncation of floor(x); out of range or NaN the
 * "integer indefinite" of cvttsd2si, INT64_MIN (the conversion numba's LLVM emits). */
static inline int64_t floor_i64(double x) {
    double f = floor(x);
    if (f >= -9223372036854775808.0 && f < 9223372036854775808.0) return (int64_t)f;
    return INT64_MIN;
}

/* Python's min(max(i, 0), n - 1) of integers. */
static inline int64_t clamp_i(int64_t i, int64_t n) {
    int64_t m = i < 0 ? 0 : i;
    return m > n - 1 ? n - 1 : m;
}

/* ---- bounds ---------------------------------------------------------------------------- */

/* Per-axis minimum and maximum of X[rows] (nrows > 0) or of all of X (nx rows, strides rs, cs;
 * nx >= 1) into lo, hi (3,): mesh_kernel._bounds_nb. */
void bounds(const double *X, int64_t nx, int64_t rs, int64_t cs, const int64_t *rows,
            int64_t nrows, double *lo, double *hi) {
    int64_t n = nrows ? nrows : nx;
    int64_t r0 = nrows ? wrap(rows[0], nx) : 0;
    for (int a = 0; a < 3; a++) lo[a] = hi[a] = X[r0 * rs + a * cs];
    double l0 = lo[0], l1 = lo[1], l2 = lo[2], h0 = hi[0], h1 = hi[1], h2 = hi[2];
#define BOUNDS_STEP(r)                                                                          \
    do {                                                                                        \
        const double *p = X + (r) * rs;                                                         \
        double v = p[0];                                                                        \
        if (v < l0) l0 = v;                                                                     \
        else if (v > h0) h0 = v;                                                                \
        v = p[cs];                                                                              \
        if (v < l1) l1 = v;                                                                     \
        else if (v > h1) h1 = v;                                                                \
        v = p[2 * cs];                                                                          \
        if (v < l2) l2 = v;                                                                     \
        else if (v > h2) h2 = v;                                                                \
    } while (0)
    if (nrows) {
        for (int64_t i = 1; i < n; i++) BOUNDS_STEP(wrap(rows[i], nx));
    } else {
        for (int64_t i = 1; i < n; i++) BOUNDS_STEP(i);
    }
#undef BOUNDS_STEP
    lo[0] = l0, lo[1] = l1, lo[2] = l2;
    hi[0] = h0, hi[1] = h1, hi[2] = h2;
}

/* ---- gather, scatter ------------------------------------------------------------------- */

/* out[i] = P[rows[order[i]]] (P[order[i]] when nrows == 0), i < n; P: np rows, strides ps0, ps1;
 * order: stride os; out (n, 3) C order: mesh_kernel._gather_rows_into. */
#define GATHER(NAME, T)                                                                         \
    static void NAME(const double *P, int64_t np_, int64_t ps0, int64_t ps1, const int64_t *rows, \
                     int64_t nrows, const T *order, int64_t os, int64_t n, double *out) {       \
        for (int64_t i = 0; i < n; i++) {                                                       \
            int64_t o = (int64_t)order[i * os];                                                 \
            int64_t r = nrows ? wrap(rows[wrap(o, nrows)], np_) : wrap(o, np_);                 \
            const double *p = P + r * ps0;                                                      \
            out[3 * i] = p[0];                                                                  \
            out[3 * i + 1] = p[ps1];                                                            \
            out[3 * i + 2] = p[2 * ps1];                                                        \
        }                                                                                       \
    }
GATHER(gather_i32, int32_t)
GATHER(gather_i64, int64_t)

/* order's element size osz: 4 (int32) or 8 (int64). */
void gather_rows(const double *P, int64_t np_, int64_t ps0, int64_t ps1, const int64_t *rows,
                 int64_t nrows, const void *order, int64_t osz, int64_t os, int64_t n,
                 double *out) {
    if (osz == 4)
        gather_i32(P, np_, ps0, ps1, rows, nrows, (const int32_t *)order, os, n, out);
    else
        gather_i64(P, np_, ps0, ps1, rows, nrows, (const int64_t *)order, os, n, out);
}

/* out[order[i]] = Xs[i], i < n (Xs strides xs0, xs1; out: nout rows, C order):
 * mesh_kernel._scatter_rows_into. */
#define SCATTER(NAME, T)                                                                        \
    static void NAME(const double *Xs, int64_t xs0, int64_t xs1, const T *order, int64_t os,    \
                     int64_t n, double *out, int64_t nout) {                                    \
        for (int64_t i = 0; i < n; i++) {                                                       \
            int64_t r = wrap((int64_t)order[i * os], nout);                                     \
            const double *x = Xs + i * xs0;                                                     \
            out[3 * r] = x[0];                                                                  \
            out[3 * r + 1] = x[xs1];                                                            \
            out[3 * r + 2] = x[2 * xs1];                                                        \
        }                                                                                       \
    }
SCATTER(scatter_i32, int32_t)
SCATTER(scatter_i64, int64_t)

void scatter_rows(const double *Xs, int64_t xs0, int64_t xs1, const void *order, int64_t osz,
                  int64_t os, int64_t n, double *out, int64_t nout) {
    if (osz == 4)
        scatter_i32(Xs, xs0, xs1, (const int32_t *)order, os, n, out, nout);
    else
        scatter_i64(Xs, xs0, xs1, (const int64_t *)order, os, n, out, nout);
}

/* ---- Morton order ---------------------------------------------------------------------- */

/* numba's np.uint64(x) of a double outside (-1, 2^64) (NaN included): what its LLVM emits on
 * this CPU — vcvttsd2usi where AVX-512F is there (all ones), else the two signed conversions
 * t1 | (t2 & (t1 >> 63)) (cvttsd2si: INT64_MIN out of range). Only NaN coordinates get here. */
static int have_avx512f = -1;

static inline int64_t cvt_s(double x) {
    return (x >= -9223372036854775808.0 && x < 9223372036854775808.0) ? (int64_t)x : INT64_MIN;
}

static uint64_t to_u64_slow(double x) {
    if (have_avx512f < 0) {
        __builtin_cpu_init();
        have_avx512f = __builtin_cpu_supports("avx512f") ? 1 : 0;
    }
    if (have_avx512f) return UINT64_MAX;
    int64_t t1 = cvt_s(x), t2 = cvt_s(x - 9223372036854775808.0);
    return (uint64_t)t1 | ((uint64_t)t2 & (uint64_t)(t1 >> 63));
}

static inline uint64_t to_u64(double x) {
    if (x > -1.0 && x < 18446744073709551616.0) return (uint64_t)x;
    return to_u64_slow(x);
}

/* mesh_kernel.part1by2 of a scalar: the low 21 bits of v spread to every third bit. */
static inline uint64_t spread3(uint64_t v) {
    v &= 0x1FFFFFull;
    v = (v | (v << 32)) & 0x1F00000000FFFFull;
    v = (v | (v << 16)) & 0x1F0000FF0000FFull;
    v = (v | (v << 8)) & 0x100F00F00F00F00Full;
    v = (v | (v << 4)) & 0x10C30C30C30C30C3ull;
    return (v | (v << 2)) & 0x1249249249249249ull;
}

#define RADIX_BITS 8

/* mesh_kernel._morton_order: codes of X (n rows, strides rs, cs) into code, then the LSD radix
 * sort carrying order (0..n-1 on entry) with scratch tmp_o, tmp_c (all C order, n long; 3 bits
 * <= 64). Returns 0 when the result is in order, 1 when in tmp_o. */
#define MORTON(NAME, T)                                                                         \
    static int NAME(const double *X, int64_t n, int64_t rs, int64_t cs, const double *lo,       \
                    double scale, int64_t bits, T *order, T *tmp_o, uint64_t *code,             \
                    uint64_t *tmp_c) {                                                          \
        const double l0 = lo[0], l1 = lo[1], l2 = lo[2];                                        \
        for (int64_t i = 0; i < n; i++) {                                                       \
            const double *p = X + i * rs;                                                       \
            uint64_t q0 = to_u64((p[0] - l0) * scale);                                          \
            uint64_t q1 = to_u64((p[cs] - l1) * scale);                                         \
            uint64_t q2 = to_u64((p[2 * cs] - l2) * scale);                                     \
            code[i] = spread3(q0) | (spread3(q1) << 1) | (spread3(q2) << 2);                    \
        }                                                                                       \
        const int64_t nbits = 3 * bits;                                                         \
        const uint64_t mask = (1u << RADIX_BITS) - 1;                                           \
        const int nb = 1 << RADIX_BITS;                                                         \
        int64_t count[(1 << RADIX_BITS) + 1];                                                   \
        int swapped = 0;                                                                        \
        for (int64_t shift = 0; shift < nbits; shift += RADIX_BITS) {                           \
            const unsigned s = (unsigned)shift;                                                 \
            memset(count, 0, sizeof count);                                                     \
            for (int64_t i = 0; i < n; i++) count[((code[i] >> s) & mask) + 1] += 1;           \
            int64_t mx = count[0];                                                              \
            for (int e = 1; e <= nb; e++)                                                       \
                if (count[e] > mx) mx = count[e];                                               \
            if (mx < n) {                                                                       \
                for (int e = 1; e <= nb; e++) count[e] += count[e - 1];                         \
                for (int64_t i = 0; i < n; i++) {                                               \
                    uint64_t d = (code[i] >> s) & mask;                                         \
                    int64_t j = count[d];                                                       \
                    count[d] = j + 1;                                                           \
                    tmp_c[j] = code[i];                                                         \
                    tmp_o[j] = order[i];                                                        \
                }                                                                               \
                uint64_t *tc = code;                                                            \
                code = tmp_c;                                                                   \
                tmp_c = tc;                                                                     \
                T *to = order;                                                                  \
                order = tmp_o;                                                                  \
                tmp_o = to;                                                                     \
                swapped ^= 1;                                                                   \
            }                                                                                   \
        }                                                                                       \
        return swapped;                                                                         \
    }
MORTON(morton_i32, int32_t)
MORTON(morton_i64, int64_t)

/* order, tmp_o: element size osz, 4 (int32) or 8 (int64). */
int64_t morton_order(const double *X, int64_t n, int64_t rs, int64_t cs, const double *lo,
                     double scale, int64_t bits, void *order, void *tmp_o, int64_t osz,
                     uint64_t *code, uint64_t *tmp_c) {
    if (osz == 4)
        return morton_i32(X, n, rs, cs, lo, scale, bits, (int32_t *)order, (int32_t *)tmp_o, code,
                          tmp_c);
    return morton_i64(X, n, rs, cs, lo, scale, bits, (int64_t *)order, (int64_t *)tmp_o, code,
                      tmp_c);
}

/* ---- the grid --------------------------------------------------------------------------- */

/* First half of mesh_kernel._fill_grid: every triangle's clamped cell range into rng (n_tri, 6)
 * and the cells' counts into start (ncells + 1, zeroed, C order), left as the exclusive sums
 * start[c + 1] = the first row of cell c (for fill_grid_items). Returns the number of items. */
int64_t fill_grid_count(const double *lo, const double *hi, int64_t n_tri, const double *origin,
                        double h, const int64_t *dims, int64_t *rng, int64_t *start) {
    const int64_t ny = dims[1], nz = dims[2];
    const int64_t ncells = dims[0] * ny * nz;
    for (int64_t t = 0; t < n_tri; t++) {
        int64_t *g = rng + 6 * t;
        for (int ax = 0; ax < 3; ax++) {
            int64_t n = dims[ax];
            int64_t i0 = floor_i64((lo[3 * t + ax] - origin[ax]) / h);
            int64_t i1 = floor_i64((hi[3 * t + ax] - origin[ax]) / h);
            g[2 * ax] = clamp_i(i0, n);
            g[2 * ax + 1] = clamp_i(i1, n);
        }
        for (int64_t i = g[0]; i <= g[1]; i++)
            for (int64_t j = g[2]; j <= g[3]; j++)
                for (int64_t k = g[4]; k <= g[5]; k++) start[(i * ny + j) * nz + k + 1] += 1;
    }
    int64_t s = 0;
    for (int64_t c = 0; c < ncells; c++) {
        int64_t cnt = start[c + 1];
        start[c + 1] = s;
        s += cnt;
    }
    return s;
}

/* Second half: the triangles into items, in triangle order within each cell; start then holds
 * the cells' row starts (numpy's cumsum of the counts, start[0] = 0). */
void fill_grid_items(const int64_t *rng, int64_t n_tri, const int64_t *dims, int64_t *start,
                     int32_t *items) {
    const int64_t ny = dims[1], nz = dims[2];
    for (int64_t t = 0; t < n_tri; t++) {
        const int64_t *g = rng + 6 * t;
        for (int64_t i = g[0]; i <= g[1]; i++)
            for (int64_t j = g[2]; j <= g[3]; j++)
                for (int64_t k = g[4]; k <= g[5]; k++) {
                    int64_t c = (i * ny + j) * nz + k;
                    items[start[c + 1]++] = (int32_t)t;
                }
    }
}

/* ---- the closest triangle ---------------------------------------------------------------- */

typedef struct {
    const double *a, *ab, *ac, *abab, *abac, *acac, *bnd;
} Mesh;

/* mesh_kernel._tri_d2: (d², v, w) of point p and triangle t; ERR_ZERODIV where numba raises. */
static inline int tri_d2(double px, double py, double pz, int64_t t, const Mesh *M, double *d2o,
                         double *vo, double *wo) {
    const double *A = M->a + 3 * t, *AB = M->ab + 3 * t, *AC = M->ac + 3 * t;
    double apx = px - A[0], apy = py - A[1], apz = pz - A[2];
    double d1 = AB[0] * apx + AB[1] * apy + AB[2] * apz;
    double d2 = AC[0] * apx + AC[1] * apy + AC[2] * apz;
    double s_abab = M->abab[t], s_abac = M->abac[t], s_acac = M->acac[t];
    double d3 = d1 - s_abab;
    double d4 = d2 - s_abac;
    double d5 = d1 - s_abac;
    double d6 = d2 - s_acac;
    double va = d3 * d6 - d5 * d4;
    double vb = d5 * d2 - d1 * d6;
    double vc = d1 * d4 - d3 * d2;
    double v, w;
    /* an edge's region only for an edge of non-zero length, the face only for a non-zero
     * area (mesh_kernel._tri_d2): a triangle with two equal vertices divided 0 by 0 */
    if (d1 <= 0 && d2 <= 0) {
        v = 0.0, w = 0.0;
    } else if (d3 >= 0 && d4 <= d3) {
        v = 1.0, w = 0.0;
    } else if (vc <= 0 && d1 >= 0 && d3 <= 0 && d1 - d3 > 0) {
        v = d1 / (d1 - d3), w = 0.0;
    } else if (d6 >= 0 && d5 <= d6) {
        v = 0.0, w = 1.0;
    } else if (vb <= 0 && d2 >= 0 && d6 <= 0 && d2 - d6 > 0) {
        v = 0.0, w = d2 / (d2 - d6);
    } else if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0 && (d4 - d3) + (d5 - d6) > 0) {
        double t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        v = 1.0 - t_bc, w = t_bc;
    } else if (va + vb + vc != 0) {
        double den = va + vb + vc;
        v = vb / den, w = vc / den;
    } else { /* no area and no edge region (rounding): vertex a, an upper bound */
        v = 0.0, w = 0.0;
    }
    double r = (apx * apx + apy * apy + apz * apz) - 2.0 * (v * d1 + w * d2) + v * v * s_abab +
               2.0 * v * w * s_abac + w * w * s_acac;
    *d2o = 0.0 > r ? 0.0 : r;
    *vo = v;
    *wo = w;
    return OK;
}

/* The best so far of one point. */
typedef struct {
    double d2, v, w;
    int64_t f;
} Best;

/* mesh_kernel._scan: update b with triangles ids[s:e] (a -1 ends the list). */
static inline int scan(const int32_t *ids, int64_t s, int64_t e, double px, double py, double pz,
                       const Mesh *M, double tol2, Best *b) {
    const double *bnd = M->bnd;
    double best2 = b->d2;
    double sb = sqrt(best2 * (1.0 + 1e-12) + tol2) * (1.0 + 1e-9);
    for (int64_t q = s; q < e; q++) {
        int64_t t = ids[q];
        if (t < 0) break;
        const double *B = bnd + 8 * t;
        double dx = px - B[0];
        double dy = py - B[1];
        double dz = pz - B[2];
        double r2 = dx * dx + dy * dy + dz * dz;
        double sr = sb + B[3];
        if (r2 > sr * sr) continue;
        double hn = dx * B[4] + dy * B[5] + dz * B[6];
        double h2 = hn * hn;
        double lim = best2 + 1e-12 * (best2 + r2 + B[7]) + tol2;
        if (h2 > lim) continue;
        double m = r2 - h2;
        double g = sqrt(0.0 > m ? 0.0 : m) - B[3];
        if (g > 0.0 && h2 + g * g > lim) continue;
        double d2, v, w;
        if (tri_d2(px, py, pz, t, M, &d2, &v, &w)) return ERR_ZERODIV;
        if (d2 < best2 || (d2 == best2 && t < b->f)) {
            best2 = d2;
            b->d2 = d2, b->f = t, b->v = v, b->w = w;
            sb = sqrt(best2 * (1.0 + 1e-12) + tol2) * (1.0 + 1e-9);
        }
    }
    return OK;
}

/* mesh_kernel._box_d2: squared distance from p to the box [lo, hi]. */
static inline double box_d2(const double *p, const double *lo, const double *hi) {
    double s = 0.0;
    for (int ax = 0; ax < 3; ax++) {
        if (p[ax] < lo[ax]) {
            double d = lo[ax] - p[ax];
            s += d * d;
        } else if (p[ax] > hi[ax]) {
            double d = p[ax] - hi[ax];
            s += d * d;
        }
    }
    return s;
}

/* mesh_kernel._node_d2: squared distance from p to the box of BVH node i. */
static inline double node_d2(const double *p, const double *lo, const double *hi, int64_t i) {
    return box_d2(p, lo + 3 * i, hi + 3 * i);
}

/* mesh_kernel._closest_grid: the exact closest triangle of each of X (n rows, strides xs0, xs1)
 * into face (stride fs), dist2 (stride ds), closest (strides cs0, cs1). Mesh arrays C order:
 * a, ab, ac (F, 3); abab, abac, acac (F,); bnd (F, 8); start, items: the grid; nlo, nhi
 * (2P - 1, 3), leaf_tri (P leaf,): the BVH (P = n_leaves); max_rings: mesh_kernel.MAX_RINGS.
 * ERR_ZERODIV where numba raises (rows before the point are filled). */
int closest_grid(const double *X, int64_t n_pts, int64_t xs0, int64_t xs1, const double *origin,
                 double h, const int64_t *dims, const int64_t *start, const int32_t *items,
                 const double *a, const double *ab, const double *ac, const double *abab,
                 const double *abac, const double *acac, const double *bnd, int64_t n_tri,
                 const double *nlo, const double *nhi, const int32_t *leaf_tri, int64_t n_leaves,
                 int64_t leaf, int64_t max_rings, double tol2, int64_t seed, int64_t *face,
                 int64_t fs, double *dist2, int64_t ds, double *closest, int64_t cs0,
                 int64_t cs1) {
    const Mesh M = {a, ab, ac, abab, abac, acac, bnd};
    const int64_t nx = dims[0], ny = dims[1], nz = dims[2];
    double g_hi[3];
    for (int ax = 0; ax < 3; ax++) g_hi[ax] = origin[ax] + (double)dims[ax] * h;
    int64_t stack[256];
    double sd[256];
    double blo[3], bhi[3], p[3];
    int64_t lo_i[3], hi_i[3], cell[3];
    for (int64_t n = 0; n < n_pts; n++) {
        const double *x = X + n * xs0;
        const double px = x[0], py = x[xs1], pz = x[2 * xs1];
        p[0] = px, p[1] = py, p[2] = pz;
        Best b = {INFINITY, 0.0, 0.0, -1};
        int done = 0;
        if (seed && n > 0) {
            b.f = face[(n - 1) * fs];
            if (tri_d2(px, py, pz, wrap(b.f, n_tri), &M, &b.d2, &b.v, &b.w)) return ERR_ZERODIV;
            double r = sqrt(b.d2 + tol2) * (1.0 + 1e-9);
            if (r <= 2.0 * h) {
                if (h == 0.0) return ERR_ZERODIV;
                for (int ax = 0; ax < 3; ax++) {
                    int64_t i0 = floor_i64((p[ax] - r - origin[ax]) / h);
                    int64_t i1 = floor_i64((p[ax] + r - origin[ax]) / h);
                    lo_i[ax] = clamp_i(i0, dims[ax]);
                    hi_i[ax] = clamp_i(i1, dims[ax]);
                }
                for (int64_t i = lo_i[0]; i <= hi_i[0]; i++)
                    for (int64_t j = lo_i[1]; j <= hi_i[1]; j++)
                        for (int64_t k = lo_i[2]; k <= hi_i[2]; k++) {
                            int64_t c = (i * ny + j) * nz + k;
                            int64_t s = start[c], e = start[c + 1];
                            if (s == e) continue;
                            blo[0] = origin[0] + (double)i * h;
                            blo[1] = origin[1] + (double)j * h;
                            blo[2] = origin[2] + (double)k * h;
                            bhi[0] = blo[0] + h, bhi[1] = blo[1] + h, bhi[2] = blo[2] + h;
                            if (box_d2(p, blo, bhi) > b.d2 * (1.0 + 1e-12) + tol2) continue;
                            if (scan(items, s, e, px, py, pz, &M, tol2, &b)) return ERR_ZERODIV;
                        }
                done = 1;
            }
        }
        if (!done) {
            for (int ax = 0; ax < 3; ax++) {
                int64_t ci = 0;
                if (isfinite(p[ax])) {
                    if (h == 0.0) return ERR_ZERODIV;
                    ci = floor_i64((p[ax] - origin[ax]) / h);
                }
                cell[ax] = clamp_i(ci, dims[ax]);
            }
            const int64_t cx = cell[0], cy = cell[1], cz = cell[2];
            int64_t R = 0;
            for (;;) {
                int64_t i0 = cx - R < 0 ? 0 : cx - R, i1 = cx + R > nx - 1 ? nx - 1 : cx + R;
                int64_t j0 = cy - R < 0 ? 0 : cy - R, j1 = cy + R > ny - 1 ? ny - 1 : cy + R;
                int64_t k0 = cz - R < 0 ? 0 : cz - R, k1 = cz + R > nz - 1 ? nz - 1 : cz + R;
                for (int64_t i = i0; i <= i1; i++)
                    for (int64_t j = j0; j <= j1; j++) {
                        int64_t ka, kb, ks;
                        if (llabs(i - cx) == R || llabs(j - cy) == R) { /* a side of the shell */
                            ka = k0, kb = k1 + 1, ks = 1;
                        } else { /* inside the shell's x-y extent: only its two z faces */
                            ka = cz - R, kb = cz + R + 1, ks = 2 * R;
                        }
                        for (int64_t k = ka; k < kb; k += ks) {
                            if (k < 0 || k >= nz) continue;
                            int64_t c = (i * ny + j) * nz + k;
                            int64_t s = start[c], e = start[c + 1];
                            if (s == e) continue;
                            blo[0] = origin[0] + (double)i * h;
                            blo[1] = origin[1] + (double)j * h;
                            blo[2] = origin[2] + (double)k * h;
                            bhi[0] = blo[0] + h, bhi[1] = blo[1] + h, bhi[2] = blo[2] + h;
                            if (box_d2(p, blo, bhi) > b.d2 * (1.0 + 1e-12) + tol2) continue;
                            if (scan(items, s, e, px, py, pz, &M, tol2, &b)) return ERR_ZERODIV;
                        }
                    }
                /* lower bound for every triangle outside the cube of rings 0..R */
                double lb2 = INFINITY;
                const int64_t lo_c[3] = {cx - R, cy - R, cz - R};
                const int64_t hi_c[3] = {cx + R, cy + R, cz + R};
                for (int ax = 0; ax < 3; ax++)
                    for (int side = 0; side < 2; side++) {
                        if (side == 0 && lo_c[ax] <= 0) continue;
                        if (side == 1 && hi_c[ax] >= dims[ax] - 1) continue;
                        for (int bx = 0; bx < 3; bx++) blo[bx] = origin[bx], bhi[bx] = g_hi[bx];
                        if (side == 0)
                            bhi[ax] = origin[ax] + (double)lo_c[ax] * h;
                        else
                            blo[ax] = origin[ax] + (double)(hi_c[ax] + 1) * h;
                        double q = box_d2(p, blo, bhi);
                        if (q < lb2) lb2 = q;
                    }
                if (lb2 == INFINITY || b.d2 * (1.0 + 1e-12) + tol2 < lb2) break;
                R += 1;
                if (R > max_rings) { /* far from the surface: finish with the BVH */
                    stack[0] = 0;
                    sd[0] = node_d2(p, nlo, nhi, 0);
                    int top = 1;
                    while (top > 0) {
                        top -= 1;
                        int64_t node = stack[top];
                        double lim = b.d2 * (1.0 + 1e-12) + tol2;
                        if (sd[top] > lim) continue;
                        if (node >= n_leaves - 1) { /* a leaf */
                            int64_t s = (node - (n_leaves - 1)) * leaf;
                            if (scan(leaf_tri, s, s + leaf, px, py, pz, &M, tol2, &b))
                                return ERR_ZERODIV;
                            continue;
                        }
                        int64_t left = 2 * node + 1;
                        double dl = node_d2(p, nlo, nhi, left);
                        double dr = node_d2(p, nlo, nhi, left + 1);
                        int64_t near = left, far = left + 1;
                        double dn = dl, df = dr;
                        if (dr < dl) near = left + 1, far = left, dn = dr, df = dl;
                        if (df <= lim && top < 256) stack[top] = far, sd[top] = df, top++;
                        if (dn <= lim && top < 256) stack[top] = near, sd[top] = dn, top++;
                    }
                    break;
                }
            }
        }
        face[n * fs] = b.f;
        dist2[n * ds] = b.d2;
        const int64_t f = wrap(b.f, n_tri);
        double *cp = closest + n * cs0;
        for (int ax = 0; ax < 3; ax++)
            cp[ax * cs1] = a[3 * f + ax] + b.v * ab[3 * f + ax] + b.w * ac[3 * f + ax];
    }
    return OK;
}

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_mesh_kernel_c",
    "C kernels of roboisf.parts.mesh_kernel, called through ctypes (roboisf.jit.native).", -1,
    NULL};

PyMODINIT_FUNC PyInit__mesh_kernel_c(void) { return PyModule_Create(&module); }
