/* C form of roboisf.scan.toolpath_kernel (the numba kernels that toolpath_kernel.py calls; the
 * counting sort of its grid is knn_kernel's, in knn_kernel.c), loaded with ctypes by
 * roboisf.jit.native: the same arithmetic in the same order, so the same bits
 * (tests/test_native_toolpath.py). Arrays are C-contiguous (the Python side makes them so);
 * the grid's keys, row starts and permutation are int32 below 2^31 feet, else int64: the
 * functions take a flag `wide` (0: int32, 1: int64), specialised by inlining; its columns'
 * first cells and compact row offsets are int32 (cells < 2^31). Built by pip install with the
 * flags of roboisf.jit.native.CFLAGS (no fused multiply-add, no fast-math).
 *
 * numba's semantics reproduced: max(a, b) is (b > a ? b : a), min(a, b) is (b < a ? b : a),
 * 3-argument max is max(max(a, b), c); int(x) and math.floor(x) of a float convert as x86's
 * cvttsd2si does (numba's fptosi there): an out-of-range or NaN value gives INT64_MIN. The
 * sorting network's minima and maxima are selects of values without NaN and ±0, whose sorted
 * bits are unique: any correct sort gives them. */
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

#define INLINE static inline __attribute__((always_inline))

/* float -> int64 as numba's int() on x86-64 (truncation; INT64_MIN out of range or NaN),
 * without C's undefined behaviour out of range. */
INLINE int64_t f2i(double x) {
    return (x >= -9223372036854775808.0 && x < 9223372036854775808.0) ? (int64_t)x : INT64_MIN;
}

INLINE int64_t imax(int64_t a, int64_t b) { return b > a ? b : a; }
INLINE int64_t imin(int64_t a, int64_t b) { return b < a ? b : a; }
INLINE double dmax(double a, double b) { return b > a ? b : a; }

/* Element i of an int32 (wide = 0) or int64 (wide = 1) array. */
INLINE int64_t geti(const void *a, int64_t i, int wide) {
    return wide ? ((const int64_t *)a)[i] : (int64_t)((const int32_t *)a)[i];
}

INLINE void seti(void *a, int64_t i, int64_t v, int wide) {
    if (wide)
        ((int64_t *)a)[i] = v;
    else
        ((int32_t *)a)[i] = (int32_t)v;
}

/* ---- the grid of the feet (toolpath_kernel._grid_columns, _grid_keys) ---------------------- */

/* _grid_columns: the cell (ci, cj, ck) of every foot of F (n, 3) as knn_kernel's cell_keys
 * finds it, its column ci * ny + cj in col and ck in kz (n each), the lowest and the highest
 * ck of each column (nx * ny) lowered into kmin and raised into kmax. 0, or -1 when a foot has
 * no cell (not finite; numba's kernel says so too). */
INLINE int64_t grid_columns_t(const double *F, int64_t n, const double *lo, double h,
                              int64_t nx, int64_t ny, int64_t nz, void *col, void *kz,
                              int32_t *kmin, int32_t *kmax, int wide) {
    for (int64_t i = 0; i < n; i++) {
        const double *p = F + 3 * i;
        int64_t ci = imin(f2i((p[0] - lo[0]) / h), nx - 1);
        int64_t cj = imin(f2i((p[1] - lo[1]) / h), ny - 1);
        int64_t ck = imin(f2i((p[2] - lo[2]) / h), nz - 1);
        if (ci < 0 || cj < 0 || ck < 0) return -1;
        int64_t c = ci * ny + cj;
        seti(col, i, c, wide);
        seti(kz, i, ck, wide);
        if (ck < kmin[c]) kmin[c] = (int32_t)ck;
        if (ck > kmax[c]) kmax[c] = (int32_t)ck;
    }
    return 0;
}

__attribute__((target_clones("avx2", "default"))) int64_t
grid_columns(const double *F, int64_t n, const double *lo, double h, int64_t nx, int64_t ny,
             int64_t nz, void *col, void *kz, int64_t wide, int32_t *kmin, int32_t *kmax) {
    if (wide) return grid_columns_t(F, n, lo, h, nx, ny, nz, col, kz, kmin, kmax, 1);
    return grid_columns_t(F, n, lo, h, nx, ny, nz, col, kz, kmin, kmax, 0);
}

/* _grid_keys: key (n, a column on entry) := the compact cell cbase[col] + kz - kmin[col]; the
 * feet per cell added to counts. */
INLINE void grid_keys_t(void *key, const void *kz, int64_t n, const int32_t *kmin,
                        const int32_t *cbase, void *counts, int wide) {
    for (int64_t i = 0; i < n; i++) {
        int64_t c = geti(key, i, wide);
        int64_t cell = (int64_t)cbase[c] + geti(kz, i, wide) - (int64_t)kmin[c];
        seti(key, i, cell, wide);
        seti(counts, cell, geti(counts, cell, wide) + 1, wide);
    }
}

void grid_keys(void *key, const void *kz, int64_t n, int64_t wide, const int32_t *kmin,
               const int32_t *cbase, void *counts) {
    if (wide)
        grid_keys_t(key, kz, n, kmin, cbase, counts, 1);
    else
        grid_keys_t(key, kz, n, kmin, cbase, counts, 0);
}

/* ---- the contacts' statistics (toolpath_kernel._contacts and its helpers) ---------------- */

/* _select: reorder d[:m] (v alongside) so that its k smallest come first (Hoare quickselect,
 * median-of-three pivot). */
INLINE void select_k(double *d, double *v, int64_t m, int64_t k) {
    int64_t lo = 0, hi = m - 1;
    while (hi > lo) {
        int64_t mid = (lo + hi) / 2; /* both >= 0: // is / */
        double a = d[lo], b = d[mid], c = d[hi];
        double mn_ab = b < a ? b : a;
        double mx_ab = b > a ? b : a;
        double mn2 = c < mx_ab ? c : mx_ab;
        double piv = mn2 > mn_ab ? mn2 : mn_ab;
        int64_t i = lo, j = hi;
        while (i <= j) {
            while (d[i] < piv) i++;
            while (d[j] > piv) j--;
            if (i <= j) {
                double t = d[i];
                d[i] = d[j];
                d[j] = t;
                t = v[i];
                v[i] = v[j];
                v[j] = t;
                i++;
                j--;
            }
        }
        if (k - 1 <= j)
            hi = j;
        else if (k - 1 >= i)
            lo = i;
        else
            return;
    }
}

/* _kth_smallest: the k-th smallest of d[:n] (1 <= k <= n, no NaN) — a quickselect on the values
 * alone, median-of-three pivot, each pass a branch-free three-way split of src into a (below
 * the pivot) and b (above it); a or b is split in place when it is the source (the write index
 * never passes the read index). a, b: room for n. */
INLINE double kth_smallest(const double *d, int64_t n, int64_t k, double *a, double *b) {
    const double *src = d;
    int64_t kk = k - 1;
    for (;;) {
        double x = src[0], y = src[n / 2], z = src[n - 1]; /* n >= 1: // is / */
        double mn_xy = y < x ? y : x;
        double mx_xy = y > x ? y : x;
        double mn2 = z < mx_xy ? z : mx_xy;
        double piv = mn2 > mn_xy ? mn2 : mn_xy;
        int64_t nl = 0, nr = 0;
        for (int64_t t = 0; t < n; t++) {
            double v = src[t];
            a[nl] = v;
            b[nr] = v;
            nl += v < piv;
            nr += v > piv;
        }
        if (kk < nl) {
            src = a;
            n = nl;
        } else if (kk < n - nr) {
            return piv; /* the pivot, one of the values: n falls every pass */
        } else {
            kk -= n - nr;
            src = b;
            n = nr;
        }
    }
}

/* _bitonic: src[:n] sorted ascending into dst[:n] by a bitonic sorting network on x (room for
 * np2, the power of two >= n; padded with +inf), each stage's compare-exchanges a branch-free
 * loop over contiguous rows (vectorised). For values without NaN and without ±0 — the sorted
 * bits are then unique, those of every sort (the insertion sort's too). */
INLINE void bitonic(const double *src, double *dst, double *x, int64_t n, int64_t np2) {
    for (int64_t t = 0; t < n; t++) x[t] = src[t];
    for (int64_t t = n; t < np2; t++) x[t] = INFINITY;
    for (int64_t p = 1; p < np2; p *= 2) {
        /* blocks of 2p: each half sorted; row t against row 2p - 1 - t (the second reversed) */
        for (int64_t b = 0; b < np2; b += 2 * p) {
            double *restrict lo = x + b, *restrict hi = x + b + p;
            for (int64_t t = 0; t < p; t++) {
                double u = lo[t], w = hi[p - 1 - t];
                double mn = u < w ? u : w, mx = u < w ? w : u;
                lo[t] = mn;
                hi[p - 1 - t] = mx;
            }
        }
        /* then half-cleaners: row t against row t + q within blocks of 2q, q = p / 2 ... 2 */
        for (int64_t q = p / 2; q > 1; q /= 2)
            for (int64_t b = 0; b < np2; b += 2 * q) {
                double *restrict lo = x + b, *restrict hi = x + b + q;
                for (int64_t t = 0; t < q; t++) {
                    double u = lo[t], w = hi[t];
                    double mn = u < w ? u : w, mx = u < w ? w : u;
                    lo[t] = mn;
                    hi[t] = mx;
                }
            }
        if (p > 1) /* and q = 1: neighbours */
            for (int64_t t = 0; t < np2; t += 2) {
                double u = x[t], w = x[t + 1];
                double mn = u < w ? u : w, mx = u < w ? w : u;
                x[t] = mn;
                x[t + 1] = mx;
            }
    }
    for (int64_t t = 0; t < n; t++) dst[t] = x[t];
}

typedef struct {
    int64_t i0, i1, j0, j1, k0, k1;
    double rs;
} Box;

/* _box: the cells of the ball of radius rad about p, widened by a hair, and that radius. */
INLINE Box box_of(double px, double py, double pz, double rad, const double *lo, double h,
                  int64_t nx, int64_t ny, int64_t nz) {
    Box b;
    double rs = rad + 1e-9 * (rad + fabs(px) + fabs(py) + fabs(pz));
    b.i0 = imax(f2i(floor((px - rs - lo[0]) / h)), 0);
    b.i1 = imin(f2i(floor((px + rs - lo[0]) / h)), nx - 1);
    b.j0 = imax(f2i(floor((py - rs - lo[1]) / h)), 0);
    b.j1 = imin(f2i(floor((py + rs - lo[1]) / h)), ny - 1);
    b.k0 = imax(f2i(floor((pz - rs - lo[2]) / h)), 0);
    b.k1 = imin(f2i(floor((pz + rs - lo[2]) / h)), nz - 1);
    b.rs = rs;
    return b;
}

/* _run: the rows start[r0] .. start[r1] of the box's cells in column col — r0 > r1 when the
 * column holds none of them (its cells kmin[col] ... in the compact rows cbase[col] ...). */
INLINE void run_of(const int32_t *kmin, const int32_t *cbase, int64_t col, const Box *b,
                   int64_t *r0, int64_t *r1) {
    int64_t c0 = cbase[col], kl = kmin[col];
    int64_t kh = kl + ((int64_t)cbase[col + 1] - c0) - 1;
    *r0 = c0 + imax(b->k0, kl) - kl;
    *r1 = c0 + imin(b->k1, kh) - kl + 1;
}

/* _need: feet in the box's cells. */
INLINE int64_t need_of(const void *start, const int32_t *kmin, const int32_t *cbase, int64_t ny,
                       const Box *b, int wide) {
    int64_t need = 0;
    for (int64_t ii = b->i0; ii <= b->i1; ii++)
        for (int64_t jj = b->j0; jj <= b->j1; jj++) {
            int64_t r0, r1;
            run_of(kmin, cbase, ii * ny + jj, b, &r0, &r1);
            if (r0 < r1) need += geti(start, r1, wide) - geti(start, r0, wide);
        }
    return need;
}

/* _gather: the squared distances to p below keep2 of the feet in the box's cells, in cd
 * (their dn in cv), in the cells' order; how many. Columns farther than prune2 skipped. */
INLINE int64_t gather(const double *F, const double *dn, const void *order, const void *start,
                      const int32_t *kmin, const int32_t *cbase, const double *lo, double h,
                      int64_t ny, double px, double py, double pz, const Box *b, double keep2,
                      double prune2, double *cd, double *cv, int wide) {
    int64_t m = 0;
    for (int64_t ii = b->i0; ii <= b->i1; ii++) {
        double ex = dmax(dmax(lo[0] + (double)ii * h - px, 0.0),
                         px - (lo[0] + (double)(ii + 1) * h));
        for (int64_t jj = b->j0; jj <= b->j1; jj++) {
            double ey = dmax(dmax(lo[1] + (double)jj * h - py, 0.0),
                             py - (lo[1] + (double)(jj + 1) * h));
            if (ex * ex + ey * ey > prune2) continue;
            int64_t r0, r1;
            run_of(kmin, cbase, ii * ny + jj, b, &r0, &r1);
            if (r0 >= r1) continue;
            int64_t t0 = geti(start, r0, wide), t1 = geti(start, r1, wide);
            for (int64_t t = t0; t < t1; t++) {
                int64_t r = geti(order, t, wide);
                double dx = F[3 * r] - px;
                double dy = F[3 * r + 1] - py;
                double dz = F[3 * r + 2] - pz;
                double d2 = dx * dx + dy * dy + dz * dz;
                cd[m] = d2;
                cv[m] = dn[r];
                m += d2 < keep2;
            }
        }
    }
    return m;
}

/* Scratch buffers of the candidates (cd, cv), grown as _ball grows them. */
typedef struct {
    double *cd, *cv;
    int64_t cap;
} Buf;

/* Grows buffers a and b (room for *cap) to room for need; 0, or -1 when out of memory. */
static int grow2(double **a, double **b, int64_t *cap, int64_t need) {
    if (need <= *cap) return 0;
    double *na = malloc((size_t)need * sizeof(double));
    double *nb = malloc((size_t)need * sizeof(double));
    if (na == NULL || nb == NULL) {
        free(na);
        free(nb);
        return -1;
    }
    free(*a);
    free(*b);
    *a = na;
    *b = nb;
    *cap = need;
    return 0;
}

/* _ball: the feet closer to p than rad, in buf (grown when the cells hold more); -1 when
 * there is no memory for them. */
INLINE int64_t ball(const double *F, const double *dn, const void *order, const void *start,
                    const int32_t *kmin, const int32_t *cbase, const double *lo, double h,
                    int64_t nx, int64_t ny, int64_t nz, double px, double py, double pz,
                    double rad, Buf *buf, int wide) {
    Box b = box_of(px, py, pz, rad, lo, h, nx, ny, nz);
    if (b.k0 > b.k1) return 0;
    int64_t need = need_of(start, kmin, cbase, ny, &b, wide);
    if (grow2(&buf->cd, &buf->cv, &buf->cap, need) < 0) return -1;
    double rs = b.rs;
    return gather(F, dn, order, start, kmin, cbase, lo, h, ny, px, py, pz, &b, rad * rad,
                  rs * rs, buf->cd, buf->cv, wide);
}

/* _kth: the largest of cd[:k]. */
INLINE double kth(const double *cd, int64_t k) {
    double vk = cd[0];
    for (int64_t t = 1; t < k; t++) vk = dmax(vk, cd[t]);
    return vk;
}

/* _contacts over contacts a .. b - 1 of P (M, 3). Returns 0, 1 when out of memory, 2 when
 * trim would read beyond the k values (numba's kernel reads outside its array there: trim
 * outside [0, 1)), 3 when k < 1. */
INLINE int contacts_t(const double *F, const double *dn, const void *order, const void *start,
                      const int32_t *kmin, const int32_t *cbase, const double *lo, double h,
                      int64_t nx, int64_t ny, int64_t nz, const double *P, double radius,
                      int64_t k, double trim, double widen, int64_t a, int64_t b, int64_t *cnt,
                      double *med, double *trimmed, double *mad, int wide) {
    if (k < 1) return 3;
    int64_t np2 = 1;
    while (np2 < k) np2 *= 2;
    Buf buf = {NULL, NULL, 0};
    double *sa = NULL, *sb = NULL; /* _kth_smallest's */
    int64_t scap = 0;
    double *vv = calloc((size_t)k, sizeof(double));
    double *xs = malloc((size_t)np2 * sizeof(double)); /* _bitonic's (c <= k) */
    int status = 0;
    if (vv == NULL || xs == NULL || grow2(&buf.cd, &buf.cv, &buf.cap, 256) < 0) {
        status = 1;
        goto done;
    }
    double est = 0.0;
    for (int64_t i = a; i < b; i++) {
        double px = P[3 * i], py = P[3 * i + 1], pz = P[3 * i + 2];
        if (!(isfinite(px) && isfinite(py) && isfinite(pz))) {
            cnt[i] = 0;
            med[i] = 0.0;
            trimmed[i] = 0.0;
            mad[i] = 0.0;
            est = 0.0;
            continue;
        }
        int64_t m = -1;
        double kd = 0.0; /* the k-th squared distance */
        if (0.0 < est && est < radius) {
            m = ball(F, dn, order, start, kmin, cbase, lo, h, nx, ny, nz, px, py, pz, est, &buf,
                     wide);
            if (m < 0) {
                status = 1;
                goto done;
            }
            /* k feet or more within est: the k nearest are the feet at <= the k-th squared
             * distance kd (the set alone counts here, not its order) — k of them unless one
             * ties with the k-th; a tie, a dn of ±0 or NaN: the whole ball below */
            if (m < k) {
                m = -1;
            } else {
                if (grow2(&sa, &sb, &scap, m) < 0) {
                    status = 1;
                    goto done;
                }
                kd = kth_smallest(buf.cd, m, k, sa, sb);
                int64_t j = 0;
                for (int64_t t = 0; t < m; t++) {
                    buf.cv[j] = buf.cv[t];
                    j += buf.cd[t] <= kd;
                }
                if (j != k) m = -1; /* a tie with the k-th distance */
                for (int64_t t = 0; t < k && m >= 0; t++) {
                    double x = buf.cv[t];
                    if (x == 0.0 || x != x) m = -1;
                }
            }
        }
        int whole = m < 0;
        if (whole) {
            m = ball(F, dn, order, start, kmin, cbase, lo, h, nx, ny, nz, px, py, pz, radius,
                     &buf, wide);
            if (m < 0) {
                status = 1;
                goto done;
            }
            if (m > k) select_k(buf.cd, buf.cv, m, k);
            if (m >= k) kd = kth(buf.cd, k);
        }
        const double *cv = buf.cv;
        int64_t c = imin(m, k);
        est = 0.0;
        if (c == k) est = sqrt(kd) * widen;
        /* the values sorted, zero-padded to k: by the network when none is NaN or ±0 (the
         * small ball's are not: checked above), else by the insertion sort */
        int plain = 1;
        if (whole)
            for (int64_t t = 0; t < c; t++) plain &= (cv[t] == cv[t]) & (cv[t] != 0.0);
        if (plain) {
            int64_t n2 = 1;
            while (n2 < c) n2 *= 2;
            bitonic(cv, vv, xs, c, n2);
        } else {
            for (int64_t t = 0; t < c; t++) {
                double x = cv[t];
                int64_t u = t;
                while (u > 0 && vv[u - 1] > x) {
                    vv[u] = vv[u - 1];
                    u--;
                }
                vv[u] = x;
            }
        }
        for (int64_t t = c; t < k; t++) vv[t] = 0.0;
        int64_t cc = imax(c, 1);
        int64_t lo_mid = (cc - 1) / 2; /* cc >= 1: // is / */
        int64_t hi_mid = cc / 2;
        double md = 0.5 * (vv[lo_mid] + vv[hi_mid]);
        int64_t cut = f2i(floor((double)cc * trim));
        /* wrapping as numba's int64 arithmetic (no C overflow) */
        int64_t lo_t = cut, hi_t = (int64_t)((uint64_t)cc - (uint64_t)cut);
        int64_t top = imax(lo_t, hi_t);
        if (top > k) {
            status = 2;
            goto done;
        }
        double s = 0.0, cs_lo = 0.0, cs_hi = 0.0;
        for (int64_t t = 0; t < top; t++) {
            s = t == 0 ? vv[t] : s + vv[t];
            if (t + 1 == lo_t) cs_lo = s;
            if (t + 1 == hi_t) cs_hi = s;
        }
        trimmed[i] = (cs_hi - cs_lo) / (double)imax((int64_t)((uint64_t)hi_t - (uint64_t)lo_t), 1);
        if (c > 0) {
            int64_t left = hi_mid;
            while (left > 0 && vv[left - 1] >= md) left--;
            int64_t right = left;
            int64_t lft = right - 1;
            double a_lo = 0.0, a_hi = 0.0;
            for (int64_t t = 0; t < hi_mid + 1; t++) {
                double e;
                if (lft < 0 || (right < c && vv[right] - md <= md - vv[lft])) {
                    e = fabs(vv[right] - md);
                    right++;
                } else {
                    e = fabs(vv[lft] - md);
                    lft--;
                }
                if (t == lo_mid) a_lo = e;
                if (t == hi_mid) a_hi = e;
            }
            mad[i] = 0.5 * (a_lo + a_hi);
        } else {
            mad[i] = 0.0;
        }
        med[i] = md;
        cnt[i] = c;
    }
done:
    free(buf.cd);
    free(buf.cv);
    free(sa);
    free(sb);
    free(vv);
    free(xs);
    return status;
}

/* _kth_smallest and _bitonic as Python calls them (tests: a wrong k-th would only cost time —
 * the tie check sends the contact to the whole ball — so it is checked on its own). */
double kth_value(const double *d, int64_t n, int64_t k, double *a, double *b) {
    return kth_smallest(d, n, k, a, b);
}

void sort_values(const double *src, double *dst, double *x, int64_t n, int64_t n2) {
    bitonic(src, dst, x, n, n2);
}

/* Two clones chosen at load by the CPU (AVX2 where there is one: floor inline, the network's
 * compare-exchanges 4 wide), the same arithmetic, no contraction in either. */
__attribute__((target_clones("avx2", "default"))) int
contacts(const double *F, const double *dn, const void *order, const void *start, int64_t wide,
         const int32_t *kmin, const int32_t *cbase, const double *lo, double h, int64_t nx,
         int64_t ny, int64_t nz, const double *P, double radius, int64_t k, double trim,
         double widen, int64_t a, int64_t b, int64_t *cnt, double *med, double *trimmed,
         double *mad) {
    if (wide)
        return contacts_t(F, dn, order, start, kmin, cbase, lo, h, nx, ny, nz, P, radius, k,
                          trim, widen, a, b, cnt, med, trimmed, mad, 1);
    return contacts_t(F, dn, order, start, kmin, cbase, lo, h, nx, ny, nz, P, radius, k, trim,
                      widen, a, b, cnt, med, trimmed, mad, 0);
}

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_toolpath_kernel_c",
    "C kernels of roboisf.scan.toolpath_kernel, called through ctypes (roboisf.jit.native).",
    -1, NULL};

PyMODINIT_FUNC PyInit__toolpath_kernel_c(void) { return PyModule_Create(&module); }
