/* C form of roboisf.logs.forcelog_kernel (the numba kernels of forcelog_kernel.py), loaded
 * with ctypes by roboisf.jit.native: the same arithmetic in the same order, so the same bits
 * (tests/test_native_forcelog.py). Arrays come as a pointer to element [0, 0] and strides in
 * elements (a log read backwards has a negative row stride). Built by pip install with the
 * flags of roboisf.jit.native.CFLAGS (no fused multiply-add, no fast-math). */
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

/* |X[i, j:j+3] - c| for every row i (X: n rows, strides rs, cs in elements). */
void row_norms(const double *X, int64_t n, int64_t rs, int64_t cs, int64_t j, const double *c,
               double *out) {
    const double c0 = c[0], c1 = c[1], c2 = c[2];
    for (int64_t i = 0; i < n; i++) {
        const double *r = X + i * rs + j * cs;
        double d0 = r[0] - c0;
        double d1 = r[cs] - c1;
        double d2 = r[2 * cs] - c2;
        out[i] = sqrt(d0 * d0 + d1 * d1 + d2 * d2);
    }
}

/* (span, onset) of forcelog_kernel.onset: the largest |F - c| (the root of the largest
 * square) into *span, and the first row whose |F - c| exceeds max(5 noise, 0.01 span), -1 for
 * none, returned. Python's max(a, b) is a when not b > a. */
int64_t onset(const double *X, int64_t n, int64_t rs, int64_t cs, const double *c, double noise,
              double *span) {
    const double c0 = c[0], c1 = c[1], c2 = c[2];
    double m2 = 0.0;
    for (int64_t i = 0; i < n; i++) {
        const double *r = X + i * rs;
        double d0 = r[0] - c0;
        double d1 = r[cs] - c1;
        double d2 = r[2 * cs] - c2;
        double s = d0 * d0 + d1 * d1 + d2 * d2;
        if (s > m2) m2 = s; /* max(m2, s) as numba and Python take it: a NaN never wins */
    }
    double sp = sqrt(m2);
    *span = sp;
    double a = 5.0 * noise, b = 0.01 * sp;
    double thr = b > a ? b : a;
    for (int64_t i = 0; i < n; i++) {
        const double *r = X + i * rs;
        double d0 = r[0] - c0;
        double d1 = r[cs] - c1;
        double d2 = r[2 * cs] - c2;
        if (sqrt(d0 * d0 + d1 * d1 + d2 * d2) > thr) return i;
    }
    return -1;
}

/* Rows ks (sorted, unique; m of them) of the running trapezoid integral of y (n, K; strides
 * ys0, ys1) over t (stride ts), into out (m, K, C order); 0 when acc cannot be allocated. */
int running_at(const double *t, int64_t ts, const double *y, int64_t K, int64_t ys0,
               int64_t ys1, const int64_t *ks, int64_t m, double *out) {
    double *acc = calloc((size_t)(K > 0 ? K : 1), sizeof(double));
    if (acc == NULL) return 0;
    int64_t r = 0;
    while (r < m && ks[r] == 0) {
        for (int64_t c = 0; c < K; c++) out[r * K + c] = 0.0;
        r++;
    }
    int64_t i = 1;
    while (r < m) {
        double h = 0.5 * (t[i * ts] - t[(i - 1) * ts]);
        for (int64_t c = 0; c < K; c++)
            acc[c] += (y[i * ys0 + c * ys1] + y[(i - 1) * ys0 + c * ys1]) * h;
        while (r < m && ks[r] == i) {
            for (int64_t c = 0; c < K; c++) out[r * K + c] = acc[c];
            r++;
        }
        i++;
    }
    free(acc);
    return 1;
}

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_forcelog_kernel_c",
    "C kernels of roboisf.logs.forcelog_kernel, called through ctypes (roboisf.jit.native).",
    -1, NULL};

PyMODINIT_FUNC PyInit__forcelog_kernel_c(void) { return PyModule_Create(&module); }
