/* C form of roboisf.scan.toolpath_kernel (the numba kernels that toolpath_kernel.py calls,
 * its grid's passes are knn_kernel's, in knn_kernel.c), loaded with ctypes by
 * roboisf.jit.native: the same arithmetic in the same order, so the same bits
 * (tests/test_native_toolpath.py). Arrays are C-contiguous (the Python side makes them so);
 * the grid's cell keys, row starts and permutation are int32 below 2^31 feet, else int64:
 * the functions take a flag `wide` (0: int32, 1: int64), specialised by inlining. Built by
 * pip install with the flags of roboisf.jit.native.CFLAGS (no fused multiply-add, no
 * fast-math).
 *
 * numba's semantics reproduced: max(a, b) is (b > a ? b : a), min(a, b) is (b < a ? b : a),
 * 3-argument max is max(max(a, b), c); int(x) and math.floor(x) of a float convert as x86's
 * cvttsd2si does (numba's fptosi there): an out-of-range or NaN value gives INT64_MIN. */
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

/* ---- the contacts' statistics (toolpath_kernel._contacts and its helpers) ---------------- */

/* _select: reorder d[:m] (v alongside) so that its k smallest come first (Hoare quickselect,
 * median-of-three pivot). */
static void select_k(double *d, double *v, int64_t m, int64_t k) {
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

/* _need: feet in the box's cells. */
INLINE int64_t need_of(const void *start, int64_t ny, int64_t nz, const Box *b, int wide) {
    int64_t need = 0;
    if (b->k0 <= b->k1) {
        for (int64_t ii = b->i0; ii <= b->i1; ii++)
            for (int64_t jj = b->j0; jj <= b->j1; jj++) {
                int64_t base = (ii * ny + jj) * nz;
                need += geti(start, base + b->k1 + 1, wide) - geti(start, base + b->k0, wide);
            }
    }
    return need;
}

/* _gather: the squared distances to p below keep2 of the feet in the box's cells, in cd
 * (their dn in cv), in the cells' order; how many. Columns farther than prune2 skipped. */
INLINE int64_t gather(const double *F, const double *dn, const void *order, const void *start,
                      const double *lo, double h, int64_t ny, int64_t nz, double px, double py,
                      double pz, const Box *b, double keep2, double prune2, double *cd,
                      double *cv, int wide) {
    int64_t m = 0;
    if (b->k0 > b->k1) return 0;
    for (int64_t ii = b->i0; ii <= b->i1; ii++) {
        double ex = dmax(dmax(lo[0] + (double)ii * h - px, 0.0),
                         px - (lo[0] + (double)(ii + 1) * h));
        for (int64_t jj = b->j0; jj <= b->j1; jj++) {
            double ey = dmax(dmax(lo[1] + (double)jj * h - py, 0.0),
                             py - (lo[1] + (double)(jj + 1) * h));
            if (ex * ex + ey * ey > prune2) continue;
            int64_t base = (ii * ny + jj) * nz;
            int64_t t0 = geti(start, base + b->k0, wide), t1 = geti(start, base + b->k1 + 1, wide);
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

/* _ball: the feet closer to p than rad, in buf (grown when the cells hold more); -1 when
 * there is no memory for them. */
INLINE int64_t ball(const double *F, const double *dn, const void *order, const void *start,
                    const double *lo, double h, int64_t nx, int64_t ny, int64_t nz, double px,
                    double py, double pz, double rad, Buf *buf, int wide) {
    Box b = box_of(px, py, pz, rad, lo, h, nx, ny, nz);
    int64_t need = need_of(start, ny, nz, &b, wide);
    if (need > buf->cap) {
        double *cd = malloc((size_t)need * sizeof(double));
        double *cv = malloc((size_t)need * sizeof(double));
        if (cd == NULL || cv == NULL) {
            free(cd);
            free(cv);
            return -1;
        }
        free(buf->cd);
        free(buf->cv);
        buf->cd = cd;
        buf->cv = cv;
        buf->cap = need;
    }
    double rs = b.rs;
    return gather(F, dn, order, start, lo, h, ny, nz, px, py, pz, &b, rad * rad, rs * rs,
                  buf->cd, buf->cv, wide);
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
                      const double *lo, double h, int64_t nx, int64_t ny, int64_t nz,
                      const double *P, double radius, int64_t k, double trim, double widen,
                      int64_t a, int64_t b, int64_t *cnt, double *med, double *trimmed,
                      double *mad, int wide) {
    if (k < 1) return 3;
    Buf buf;
    buf.cap = 256;
    buf.cd = malloc(256 * sizeof(double));
    buf.cv = malloc(256 * sizeof(double));
    double *vv = calloc((size_t)k, sizeof(double));
    int status = 0;
    if (buf.cd == NULL || buf.cv == NULL || vv == NULL) {
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
        if (0.0 < est && est < radius) {
            m = ball(F, dn, order, start, lo, h, nx, ny, nz, px, py, pz, est, &buf, wide);
            if (m < 0) {
                status = 1;
                goto done;
            }
            if (m < k) {
                m = -1;
            } else {
                if (m > k) select_k(buf.cd, buf.cv, m, k);
                double vk = kth(buf.cd, k);
                for (int64_t t = k; t < m; t++)
                    if (buf.cd[t] == vk) {
                        m = -1;
                        break;
                    }
                for (int64_t t = 0; t < k; t++) {
                    double x = buf.cv[t];
                    if (x == 0.0 || x != x) {
                        m = -1;
                        break;
                    }
                }
            }
        }
        if (m < 0) {
            m = ball(F, dn, order, start, lo, h, nx, ny, nz, px, py, pz, radius, &buf, wide);
            if (m < 0) {
                status = 1;
                goto done;
            }
            if (m > k) select_k(buf.cd, buf.cv, m, k);
        }
        const double *cd = buf.cd, *cv = buf.cv;
        int64_t c = imin(m, k);
        est = 0.0;
        if (c == k) est = sqrt(kth(cd, k)) * widen;
        for (int64_t t = 0; t < c; t++) {
            double x = cv[t];
            int64_t u = t;
            while (u > 0 && vv[u - 1] > x) {
                vv[u] = vv[u - 1];
                u--;
            }
            vv[u] = x;
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
    free(vv);
    return status;
}

int contacts(const double *F, const double *dn, const void *order, const void *start,
             int64_t wide, const double *lo, double h, int64_t nx, int64_t ny, int64_t nz,
             const double *P, double radius, int64_t k, double trim, double widen, int64_t a,
             int64_t b, int64_t *cnt, double *med, double *trimmed, double *mad) {
    if (wide)
        return contacts_t(F, dn, order, start, lo, h, nx, ny, nz, P, radius, k, trim, widen, a,
                          b, cnt, med, trimmed, mad, 1);
    return contacts_t(F, dn, order, start, lo, h, nx, ny, nz, P, radius, k, trim, widen, a, b,
                      cnt, med, trimmed, mad, 0);
}

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_toolpath_kernel_c",
    "C kernels of roboisf.scan.toolpath_kernel, called through ctypes (roboisf.jit.native).",
    -1, NULL};

PyMODINIT_FUNC PyInit__toolpath_kernel_c(void) { return PyModule_Create(&module); }
