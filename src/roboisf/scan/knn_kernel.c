/* C form of roboisf.scan.knn_kernel (the numba kernels of knn_kernel.py), loaded with ctypes by
 * roboisf.jit.native: the same arithmetic in the same order, so the same bits
 * (tests/test_native_knn.py). Built by pip install with the flags of roboisf.jit.native.CFLAGS
 * (no fused multiply-add, no fast-math).
 *
 * Conventions: points X come as a pointer to element [0, 0] and strides in elements (rs, cs);
 * an output vector `out` with its stride `os` in elements. The grid's row starts, the cell keys
 * and the permutation are int32 (below 2^31 points) or int64 (`wide` != 0), all of one type in
 * a call. Python's max(a, b) of floats is `b > a ? b : a`, min(a, b) is `b < a ? b : a` (as
 * numba compiles them: a NaN never wins as b); int(x) truncates toward zero. */
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

#define INLINE static inline __attribute__((always_inline))
/* four doubles (GCC/Clang vector extensions: AVX2 in the avx2 clone, two SSE2 halves in the
 * default one); a comparison of two is a mask of __auto_type, whatever integer the compiler
 * makes its lanes */
typedef double v4d __attribute__((vector_size(32)));

INLINE double pmax(double a, double b) { return b > a ? b : a; }
INLINE double pmin(double a, double b) { return b < a ? b : a; }
INLINE int64_t imax(int64_t a, int64_t b) { return b > a ? b : a; }
INLINE int64_t imin(int64_t a, int64_t b) { return b < a ? b : a; }

/* float -> int64 as numba's int() on x86-64 (truncation; INT64_MIN for NaN or out of range),
 * without C's undefined behaviour out of range. */
INLINE int64_t f2i(double x) {
    return (x >= -9223372036854775808.0 && x < 9223372036854775808.0) ? (int64_t)x : INT64_MIN;
}
INLINE int64_t iabs(int64_t a) { return a < 0 ? -a : a; }

/* Element i of an int32 (wide == 0) or int64 array; the callers pass wide as a constant, so each
 * function below is compiled twice, once per type. */
INLINE int64_t geti(const void *p, int wide, int64_t i) {
    return wide ? ((const int64_t *)p)[i] : (int64_t)((const int32_t *)p)[i];
}
INLINE void seti(void *p, int wide, int64_t i, int64_t v) {
    if (wide)
        ((int64_t *)p)[i] = v;
    else
        ((int32_t *)p)[i] = (int32_t)v;
}

/* _offer: rows j0 .. j1-1 of X offered to best, the k1 smallest squared distances to p so far
 * (ascending), merged from the top by best[t] = min(best[t], max(best[t-1], d2)). */
INLINE void offer(const double *X, int64_t rs, int64_t cs, int64_t j0, int64_t j1, double px,
                  double py, double pz, double *best, int64_t k1) {
    for (int64_t j = j0; j < j1; j++) {
        const double *r = X + j * rs;
        double dx = r[0] - px;
        double dy = r[cs] - py;
        double dz = r[2 * cs] - pz;
        double d2 = dx * dx + dy * dy + dz * dz;
        if (d2 < best[k1 - 1]) {
            for (int64_t t = k1 - 1; t > 0; t--) best[t] = pmin(best[t], pmax(best[t - 1], d2));
            best[0] = pmin(best[0], d2);
        }
    }
}

/* _unseen_xy: the distance from p to the faces inside the grid of the square of columns 0 .. r
 * around column (ci, cj) (x and y faces only); inf when there is no such face. */
INLINE double unseen_xy(double px, double py, int64_t ci, int64_t cj, int64_t r, const double *lo,
                        double h, int64_t nx, int64_t ny) {
    double bound = INFINITY;
    if (ci - r > 0) bound = pmin(bound, px - (lo[0] + (double)(ci - r) * h));
    if (ci + r < nx - 1) bound = pmin(bound, lo[0] + (double)(ci + r + 1) * h - px);
    if (cj - r > 0) bound = pmin(bound, py - (lo[1] + (double)(cj - r) * h));
    if (cj + r < ny - 1) bound = pmin(bound, lo[1] + (double)(cj + r + 1) * h - py);
    return bound;
}

/* _unseen: the distance from p to the faces inside the grid of the cube of rings 0 .. r around
 * cell (ci, cj, ck); inf when there is no such face (the square's x and y faces, then z's). */
INLINE double unseen(double px, double py, double pz, int64_t ci, int64_t cj, int64_t ck,
                     int64_t r, const double *lo, double h, int64_t nx, int64_t ny, int64_t nz) {
    double bound = unseen_xy(px, py, ci, cj, r, lo, h, nx, ny);
    if (ck - r > 0) bound = pmin(bound, pz - (lo[2] + (double)(ck - r) * h));
    if (ck + r < nz - 1) bound = pmin(bound, lo[2] + (double)(ck + r + 1) * h - pz);
    return bound;
}

/* _resolved: when the k1-th distance is within bound, out[i] = the mean of the roots of
 * best[1:] and 1; else 0. (max(bound, 0.0) ** 2 is numba's m * m.) */
INLINE int resolved(const double *best, int64_t k1, double bound, double *out, int64_t os,
                    int64_t i) {
    double m = pmax(bound, 0.0);
    if (bound == INFINITY || best[k1 - 1] <= m * m) {
        double s = 0.0;
        for (int64_t t = 1; t < k1; t++) s += sqrt(best[t]);
        out[i * os] = s / (double)(k1 - 1);
        return 1;
    }
    return 0;
}

/* centre-out offset of step q: 0, -1, 1, -2, 2, ... as (q + 1) // 2 * (1 if q % 2 == 0 else -1)
 * (q >= 0: C's / and % are Python's here) */
INLINE int64_t centre_out(int64_t q) { return (q + 1) / 2 * (q % 2 == 0 ? 1 : -1); }

/* p's cell (ci, cj, ck), clamped into the grid: min(max(int((x - lo) / h), 0), n - 1). */
INLINE void cell_of(double px, double py, double pz, const double *lo, double h, int64_t nx,
                    int64_t ny, int64_t nz, int64_t *ci, int64_t *cj, int64_t *ck) {
    *ci = imin(imax((int64_t)((px - lo[0]) / h), 0), nx - 1);
    *cj = imin(imax((int64_t)((py - lo[1]) / h), 0), ny - 1);
    *ck = imin(imax((int64_t)((pz - lo[2]) / h), 0), nz - 1);
}

/* The ring search of _knn_mean for point i (best: k1 doubles of scratch). */
INLINE void ring_point(const double *X, int64_t rs, int64_t cs, const void *start, int wide,
                       const double *lo, double h, int64_t nx, int64_t ny, int64_t nz,
                       int64_t k1, int64_t max_rings, int64_t i, double *out, int64_t os,
                       double *best) {
    const double *p = X + i * rs;
    double px = p[0], py = p[cs], pz = p[2 * cs];
    int64_t ci, cj, ck;
    cell_of(px, py, pz, lo, h, nx, ny, nz, &ci, &cj, &ck);
    for (int64_t t = 0; t < k1; t++) best[t] = INFINITY;
    int64_t r = 0;
    for (;;) {
        if (r > max_rings) { /* far from the others: left to the caller's k-d tree */
            out[i * os] = NAN;
            break;
        }
        for (int64_t qi = 0; qi < 2 * r + 1; qi++) {
            int64_t di = centre_out(qi);
            int64_t ii = ci + di;
            if (ii < 0 || ii >= nx) continue;
            double ex = pmax(pmax(lo[0] + (double)ii * h - px, 0.0),
                             px - (lo[0] + (double)(ii + 1) * h));
            if (ex * ex > best[k1 - 1]) continue;
            for (int64_t qj = 0; qj < 2 * r + 1; qj++) {
                int64_t dj = centre_out(qj);
                int64_t jj = cj + dj;
                if (jj < 0 || jj >= ny) continue;
                double ey = pmax(pmax(lo[1] + (double)jj * h - py, 0.0),
                                 py - (lo[1] + (double)(jj + 1) * h));
                double exy = ex * ex + ey * ey;
                if (exy > best[k1 - 1]) continue;
                /* a column inside the ring: only its two end cells are new */
                int inner = r > 0 && iabs(di) < r && iabs(dj) < r;
                int64_t nk = inner ? 2 : 2 * r + 1;
                for (int64_t qk = 0; qk < nk; qk++) {
                    int64_t dk = inner ? (qk ? r : -r) : centre_out(qk);
                    int64_t kk = ck + dk;
                    if (kk < 0 || kk >= nz) continue;
                    double ez = pmax(pmax(lo[2] + (double)kk * h - pz, 0.0),
                                     pz - (lo[2] + (double)(kk + 1) * h));
                    if (exy + ez * ez > best[k1 - 1]) continue;
                    int64_t c = (ii * ny + jj) * nz + kk;
                    offer(X, rs, cs, geti(start, wide, c), geti(start, wide, c + 1), px, py, pz,
                          best, k1);
                }
            }
        }
        if (resolved(best, k1, unseen(px, py, pz, ci, cj, ck, r, lo, h, nx, ny, nz), out, os,
                     i))
            break;
        r++;
    }
}

INLINE void ring_range(const double *X, int64_t rs, int64_t cs, const void *start, int wide,
                       const double *lo, double h, int64_t nx, int64_t ny, int64_t nz,
                       int64_t k1, int64_t max_rings, const int64_t *rows, int64_t a, int64_t b,
                       double *out, int64_t os, double *best) {
    for (int64_t q = a; q < b; q++)
        ring_point(X, rs, cs, start, wide, lo, h, nx, ny, nz, k1, max_rings, rows ? rows[q] : q,
                   out, os, best);
}

/* _knn_mean: the ring search of points a .. b-1 (k1 >= 2). 0 when the scratch cannot be had. */
int knn_mean(const double *X, int64_t rs, int64_t cs, const void *start, int64_t wide,
             const double *lo, double h, int64_t nx, int64_t ny, int64_t nz, int64_t k1,
             int64_t max_rings, int64_t a, int64_t b, double *out, int64_t os) {
    double *best = malloc((size_t)(k1 > 0 ? k1 : 1) * sizeof(double));
    if (best == NULL) return 0;
    if (wide)
        ring_range(X, rs, cs, start, 1, lo, h, nx, ny, nz, k1, max_rings, NULL, a, b, out, os,
                   best);
    else
        ring_range(X, rs, cs, start, 0, lo, h, nx, ny, nz, k1, max_rings, NULL, a, b, out, os,
                   best);
    free(best);
    return 1;
}

/* _box_gap: the distance from coordinate x to the cell [lo + i h, lo + (i + 1) h] of an axis. */
INLINE double box_gap(double x, double lo, int64_t i, double h) {
    return pmax(pmax(lo + (double)i * h - x, 0.0), x - (lo + (double)(i + 1) * h));
}

/* A hint (no arithmetic): the row starts of the columns of square ring r around column (ci, cj)
 * at height ck, wanted next (~10 % of knn_mean_rows on the paper cone's scan: a column's row
 * starts are one of its two cache misses). */
INLINE void prefetch_ring(const void *start, int wide, int64_t ci, int64_t cj, int64_t ck,
                          int64_t r, int64_t nx, int64_t ny, int64_t nz) {
    for (int64_t ii = imax(ci - r, 0); ii <= imin(ci + r, nx - 1); ii++) {
        int64_t step = (ii == ci - r || ii == ci + r) ? 1 : 2 * r; /* a row, or its two ends */
        for (int64_t jj = cj - r; jj <= cj + r; jj += step) {
            if (jj < 0 || jj >= ny) continue;
            int64_t c = (ii * ny + jj) * nz + ck;
            __builtin_prefetch(wide ? (const void *)((const int64_t *)start + c)
                                    : (const void *)((const int32_t *)start + c));
        }
    }
}

/* The column search of _knn_mean_rows for point i (best: k1 doubles of scratch): the k1
 * smallest squared distances to the points of the cube of rings 0 .. max_rings around p's cell,
 * then the ring search's stop test after ring max_rings. */
INLINE void column_point(const double *X, int64_t rs, int64_t cs, const void *start, int wide,
                         const double *lo, double h, int64_t nx, int64_t ny, int64_t nz,
                         int64_t k1, int64_t max_rings, int64_t i, double *out, int64_t os,
                         double *best) {
    const double *p = X + i * rs;
    double px = p[0], py = p[cs], pz = p[2 * cs];
    int64_t ci, cj, ck;
    cell_of(px, py, pz, lo, h, nx, ny, nz, &ci, &cj, &ck);
    int64_t zmin = imax(ck - max_rings, 0), zmax = imin(ck + max_rings, nz - 1);
    double ih = 1.0 / h, zp = (pz - lo[2]) * ih; /* z in cells (the run's first guess) */
    for (int64_t t = 0; t < k1; t++) best[t] = INFINITY;
    for (int64_t r = 0; r <= max_rings; r++) {
        if (r < max_rings) /* ring r + 1's row starts, fetched from memory meanwhile */
            prefetch_ring(start, wide, ci, cj, ck, r + 1, nx, ny, nz);
        /* the columns of square ring r, centre out */
        for (int64_t qi = 0; qi < 2 * r + 1; qi++) {
            int64_t di = centre_out(qi);
            int64_t ii = ci + di;
            if (ii < 0 || ii >= nx) continue;
            double ex = box_gap(px, lo[0], ii, h);
            if (ex * ex > best[k1 - 1]) continue;
            int edge = iabs(di) == r; /* a whole row of the ring, else its two ends */
            int64_t nq = edge ? 2 * r + 1 : 2;
            for (int64_t qj = 0; qj < nq; qj++) {
                int64_t dj = edge ? centre_out(qj) : (qj ? r : -r);
                int64_t jj = cj + dj;
                if (jj < 0 || jj >= ny) continue;
                double ey = box_gap(py, lo[1], jj, h);
                double exy = ex * ex + ey * ey;
                double b = best[k1 - 1];
                if (exy > b) continue;
                /* the column's cells within the cube and not farther than the best: one run of
                 * points (cells are sorted z fastest) */
                int64_t k0 = zmin, k9 = zmax;
                if (b < INFINITY) {
                    double s = sqrt(b - exy);
                    double t0 = zp - s * ih, t9 = zp + s * ih;
                    if (t0 > (double)zmin) k0 = t0 < (double)zmax ? (int64_t)t0 : zmax;
                    if (t9 < (double)zmax) k9 = t9 > (double)zmin ? (int64_t)t9 : zmin;
                    while (k0 > zmin) { /* one cell more where rounding cut it */
                        double ez = box_gap(pz, lo[2], k0 - 1, h);
                        if (exy + ez * ez > b) break;
                        k0--;
                    }
                    while (k9 < zmax) {
                        double ez = box_gap(pz, lo[2], k9 + 1, h);
                        if (exy + ez * ez > b) break;
                        k9++;
                    }
                }
                int64_t c = (ii * ny + jj) * nz;
                offer(X, rs, cs, geti(start, wide, c + k0), geti(start, wide, c + k9 + 1), px, py,
                      pz, best, k1);
            }
        }
        if (r == max_rings) break;
        /* every point of the cube not seen is outside the square of columns 0 .. r */
        double bxy = pmax(unseen_xy(px, py, ci, cj, r, lo, h, nx, ny), 0.0);
        if (bxy == INFINITY || best[k1 - 1] <= bxy * bxy) break;
    }
    if (!resolved(best, k1, unseen(px, py, pz, ci, cj, ck, max_rings, lo, h, nx, ny, nz), out,
                  os, i))
        out[i * os] = NAN; /* far from the others: left to the caller's k-d tree */
}

/* _knn_mean_rows: the ring search's result (knn_mean) for the points rows[0 .. m-1] (k1 >= 2),
 * found by columns. 0 when the scratch cannot be had. */
int knn_mean_rows(const double *X, int64_t rs, int64_t cs, const void *start, int64_t wide,
                  const double *lo, double h, int64_t nx, int64_t ny, int64_t nz, int64_t k1,
                  int64_t max_rings, const int64_t *rows, int64_t m, double *out, int64_t os) {
    double *best = malloc((size_t)(k1 > 0 ? k1 : 1) * sizeof(double));
    if (best == NULL) return 0;
    for (int64_t q = 0; q < m; q++) {
        if (k1 == 9 && !wide) /* the default k, compiled for its k1 and int32 row starts */
            column_point(X, rs, cs, start, 0, lo, h, nx, ny, nz, 9, max_rings, rows[q], out, os,
                         best);
        else if (wide)
            column_point(X, rs, cs, start, 1, lo, h, nx, ny, nz, k1, max_rings, rows[q], out, os,
                         best);
        else
            column_point(X, rs, cs, start, 0, lo, h, nx, ny, nz, k1, max_rings, rows[q], out, os,
                         best);
    }
    free(best);
    return 1;
}

/* The buffers of the block search: three coordinate columns. */
typedef struct {
    double *bx, *by, *bz;
    int64_t cap;
} Buffer;

static void buffer_free(Buffer *B) {
    free(B->bx);
    free(B->by);
    free(B->bz);
}

/* Room for `need` points, the first n kept (the numba kernel's growth: cap = 2 * need). */
static int buffer_grow(Buffer *B, int64_t need) {
    int64_t cap = 2 * need;
    double *p;
    if ((p = realloc(B->bx, (size_t)cap * sizeof(double))) == NULL) return 0;
    B->bx = p;
    if ((p = realloc(B->by, (size_t)cap * sizeof(double))) == NULL) return 0;
    B->by = p;
    if ((p = realloc(B->bz, (size_t)cap * sizeof(double))) == NULL) return 0;
    B->bz = p;
    B->cap = cap;
    return 1;
}

/* _knn_mean_block9 for cells ca .. cb-1 (k1 = 9): each query cell's 3 x 3 x 3 block (offsets
 * `block`, (27, 3) int64 C order) copied into the buffer, each of its points' squared distances
 * to the whole buffer (four at a time), the nine smallest in nine registers; the points the
 * block does not settle are left NaN for knn_mean_rows. 0 when the buffer cannot be had. */
INLINE int block9(const double *X, int64_t rs, int64_t cs, const void *start, int wide,
                  const double *lo, double h, int64_t nx, int64_t ny, int64_t nz,
                  const int64_t *block, int64_t ca, int64_t cb, double *out, int64_t os,
                  Buffer *B) {
    const int64_t k1 = 9;
    double best[9];
    for (int64_t c = ca; c < cb; c++) {
        int64_t a0 = geti(start, wide, c), a1 = geti(start, wide, c + 1);
        if (a0 == a1) continue;
        int64_t ci = c / (ny * nz);
        int64_t cj = (c / nz) % ny;
        int64_t ck = c % nz;
        int64_t n = 0;
        for (int q = 0; q < 27; q++) {
            int64_t ii = ci + block[3 * q], jj = cj + block[3 * q + 1], kk = ck + block[3 * q + 2];
            if (ii < 0 || ii >= nx || jj < 0 || jj >= ny || kk < 0 || kk >= nz) continue;
            int64_t e = (ii * ny + jj) * nz + kk;
            int64_t s0 = geti(start, wide, e), s1 = geti(start, wide, e + 1);
            if (s0 == s1) continue;
            if (n + (s1 - s0) > B->cap && !buffer_grow(B, n + (s1 - s0))) return 0;
            double *restrict bx = B->bx, *restrict by = B->by, *restrict bz = B->bz;
            for (int64_t j = s0; j < s1; j++) {
                const double *r = X + j * rs;
                bx[n] = r[0];
                by[n] = r[cs];
                bz[n] = r[2 * cs];
                n++;
            }
        }
        const double *restrict bx = B->bx, *restrict by = B->by, *restrict bz = B->bz;
        for (int64_t i = a0; i < a1; i++) {
            const double *p = X + i * rs;
            double px = p[0], py = p[cs], pz = p[2 * cs];
            double b0 = INFINITY, b1 = INFINITY, b2 = INFINITY, b3 = INFINITY, b4 = INFINITY;
            double b5 = INFINITY, b6 = INFINITY, b7 = INFINITY, b8 = INFINITY;
#define INSERT9(d)                            \
    if ((d) < b8) {                           \
        b8 = pmin(b8, pmax(b7, (d)));         \
        b7 = pmin(b7, pmax(b6, (d)));         \
        b6 = pmin(b6, pmax(b5, (d)));         \
        b5 = pmin(b5, pmax(b4, (d)));         \
        b4 = pmin(b4, pmax(b3, (d)));         \
        b3 = pmin(b3, pmax(b2, (d)));         \
        b2 = pmin(b2, pmax(b1, (d)));         \
        b1 = pmin(b1, pmax(b0, (d)));         \
        b0 = pmin(b0, (d));                   \
    }
            /* four candidates at a time: their squared distances (dx² + dy² + dz², in that
             * order, as one at a time), skipped together when none is below the ninth so far
             * (b8 only falls: a skipped one would not have been taken) — the same nine as one
             * at a time, with a quarter of the loop's unpredictable branches and no pass
             * through memory for the distances */
            const v4d vx = {px, px, px, px}, vy = {py, py, py, py}, vz = {pz, pz, pz, pz};
            int64_t j = 0;
            for (; j + 4 <= n; j += 4) {
                v4d ex, ey, ez;
                memcpy(&ex, bx + j, sizeof ex);
                memcpy(&ey, by + j, sizeof ey);
                memcpy(&ez, bz + j, sizeof ez);
                ex -= vx, ey -= vy, ez -= vz;
                const v4d e = ex * ex + ey * ey + ez * ez;
                const __auto_type below = e < (v4d){b8, b8, b8, b8};
                if (!(below[0] | below[1] | below[2] | below[3])) continue;
                INSERT9(e[0])
                INSERT9(e[1])
                INSERT9(e[2])
                INSERT9(e[3])
            }
            for (; j < n; j++) {
                const double dx = bx[j] - px, dy = by[j] - py, dz = bz[j] - pz;
                const double e = dx * dx + dy * dy + dz * dz;
                INSERT9(e)
            }
#undef INSERT9
            best[0] = b0, best[1] = b1, best[2] = b2, best[3] = b3, best[4] = b4;
            best[5] = b5, best[6] = b6, best[7] = b7, best[8] = b8;
            if (!resolved(best, k1, unseen(px, py, pz, ci, cj, ck, 1, lo, h, nx, ny, nz), out, os,
                          i))
                out[i * os] = NAN; /* for the ring search (knn_mean_rows), after every cell */
        }
    }
    return 1;
}

__attribute__((target_clones("avx2", "default"))) int knn_mean_block9(
    const double *X, int64_t rs, int64_t cs, const void *start, int64_t wide, const double *lo,
    double h, int64_t nx, int64_t ny, int64_t nz, const int64_t *block, int64_t ca, int64_t cb,
    double *out, int64_t os) {
    Buffer B = {NULL, NULL, NULL, 0};
    int ok = buffer_grow(&B, 2048); /* cap 4096, as the numba kernel's first buffer */
    if (ok) {
        if (wide)
            ok = block9(X, rs, cs, start, 1, lo, h, nx, ny, nz, block, ca, cb, out, os, &B);
        else
            ok = block9(X, rs, cs, start, 0, lo, h, nx, ny, nz, block, ca, cb, out, os, &B);
    }
    buffer_free(&B);
    return ok;
}

INLINE void counting_sort(const void *key, int64_t n, void *start, int64_t m, void *order,
                          int wide) {
    for (int64_t i = 0; i < n; i++) {
        int64_t c = geti(key, wide, i);
        int64_t s = geti(start, wide, c);
        seti(order, wide, s, i);
        seti(start, wide, c, s + 1);
    }
    /* start[c] is now the end of cell c, the start of cell c + 1: shifted back by one cell */
    for (int64_t c = m - 2; c > 0; c--) seti(start, wide, c, geti(start, wide, c - 1));
    seti(start, wide, 0, 0);
}

/* _counting_sort_into: the stable permutation sorting key (n) by cell into order (n), start (m
 * >= 1 row starts) holding each cell's next row during the pass and restored after it. */
void counting_sort_into(const void *key, int64_t n, void *start, int64_t m, void *order,
                        int64_t wide) {
    if (wide)
        counting_sort(key, n, start, m, order, 1);
    else
        counting_sort(key, n, start, m, order, 0);
}

INLINE int64_t cell_keys_t(const double *P, int64_t rs, int64_t cs, int64_t np,
                           const int64_t *rows, int64_t nrows, const double *lo, double h,
                           int64_t nx, int64_t ny, int64_t nz, void *key, int64_t n,
                           void *counts, int wide) {
    int64_t occupied = 0;
    for (int64_t i = 0; i < n; i++) {
        int64_t r = nrows ? rows[i] : i;
        if (r < 0) r += np; /* numba's index of a negative row: from the end */
        const double *p = P + r * rs;
        int64_t ci = imin(f2i((p[0] - lo[0]) / h), nx - 1);
        int64_t cj = imin(f2i((p[cs] - lo[1]) / h), ny - 1);
        int64_t ck = imin(f2i((p[2 * cs] - lo[2]) / h), nz - 1);
        if (ci < 0 || cj < 0 || ck < 0) return -1; /* below lo, or not finite: no cell */
        int64_t c = (ci * ny + cj) * nz + ck;
        seti(key, wide, i, c);
        int64_t cnt = geti(counts, wide, c);
        if (cnt == 0) occupied++;
        seti(counts, wide, c, cnt + 1);
    }
    return occupied;
}

/* _cell_keys: the cell of every point P[rows] (all of P, np rows, when nrows == 0) in key (n),
 * points per cell added to counts; the number of cells that were empty before, or -1 when a
 * point has no cell (below lo or not finite: numba's kernel would write outside its arrays). */
int64_t cell_keys(const double *P, int64_t rs, int64_t cs, int64_t np, const int64_t *rows,
                  int64_t nrows, const double *lo, double h, int64_t nx, int64_t ny, int64_t nz,
                  void *key, int64_t n, void *counts, int64_t wide) {
    if (wide) return cell_keys_t(P, rs, cs, np, rows, nrows, lo, h, nx, ny, nz, key, n, counts, 1);
    return cell_keys_t(P, rs, cs, np, rows, nrows, lo, h, nx, ny, nz, key, n, counts, 0);
}

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_knn_kernel_c",
    "C kernels of roboisf.scan.knn_kernel, called through ctypes (roboisf.jit.native).", -1,
    NULL};

PyMODINIT_FUNC PyInit__knn_kernel_c(void) { return PyModule_Create(&module); }
