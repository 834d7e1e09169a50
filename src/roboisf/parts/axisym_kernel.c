/* C form of roboisf.parts.axisym_kernel (the numba kernel of axisym_kernel.py), loaded with
 * ctypes by roboisf.jit.native: the same arithmetic in the same order, so the same bits
 * (tests/test_native_axisym.py). The points come as a pointer to element [0, 0] and strides in
 * elements; the packed generatrix and the outputs are C-contiguous. Built by pip install with
 * the flags of roboisf.jit.native.CFLAGS (no fused multiply-add, no fast-math). */
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

/* axisym_kernel._closest: the closest point of each of X (n rows, strides rs, cs) on the packed
 * generatrix of np primitives (kind, par (np, 8), s0, code), visited in order[0..no) — foot,
 * normal (n, 3), dist, alpha, s, region (n,). Returns 1 where numba raises ZeroDivisionError
 * (a segment of zero length; the points before it are filled), else 0. Python's
 * min(max(u, 0.0), 1.0) is spelled out: max(a, b) is b when b > a, else a. Two clones chosen
 * at load by the CPU (AVX2 where there is one: 58 against 68 ms on 1.7 M points of the paper
 * cone, numba 54); the same arithmetic, no contraction in either. */
__attribute__((target_clones("avx2", "default"))) int
closest(const double *X, int64_t n, int64_t rs, int64_t cs, const int64_t *kind, const double *par,
        const double *s0, const int64_t *code, int64_t np_, const int64_t *order, int64_t no,
        double *foot, double *normal, double *dist, double *alpha, double *s, int64_t *region) {
    for (int64_t k = 0; k < n; k++) {
        const double *p = X + k * rs;
        const double x = p[0], y = p[cs], z = p[2 * cs];
        const double r = sqrt(x * x + y * y);
        double c, sn;
        if (r > 0.0) {
            c = x / r, sn = y / r;
        } else {
            c = 1.0, sn = 0.0;
        }
        double best = INFINITY;
        double rp = 0.0, zp = 0.0, al = 0.0, ss = 0.0, nr = 0.0;
        double nz = 1.0;
        int64_t idx = 0;
        for (int64_t j = 0; j < no; j++) {
            int64_t i = order[j];
            if (i < 0) i += np_;
            const double *q = par + 8 * i;
            if (kind[i] == 0) {
                const double r0 = q[0], z0 = q[1], r1 = q[2], z1 = q[3];
                const double dr = r1 - r0, dz = z1 - z0;
                const double den = dr * dr + dz * dz;
                if (den == 0.0) return 1;
                double u = ((r - r0) * dr + (z - z0) * dz) / den;
                u = 0.0 > u ? 0.0 : u;
                u = 1.0 < u ? 1.0 : u;
                const double cr = r0 + u * dr, cz = z0 + u * dz;
                const double er = cr - r, ez = cz - z;
                const double d = sqrt(er * er + ez * ez);
                if (d < best - 1e-12) {
                    best = d, rp = cr, zp = cz, ss = u * q[4] + s0[i], idx = i;
                    al = q[5], nr = q[6], nz = q[7];
                }
            } else {
                const double rc = q[0], zc = q[1], rho = q[2], b0 = q[3], b1 = q[4];
                const double ur = r - rc, uz = z - zc;
                double beta = (ur != 0.0 || uz != 0.0) ? atan2(-ur, uz) : b0;
                beta = b0 > beta ? b0 : beta;
                beta = b1 < beta ? b1 : beta;
                const double sb = sin(beta), cb = cos(beta);
                const double cr = rc - rho * sb, cz = zc + rho * cb;
                const double er = cr - r, ez = cz - z;
                const double d = sqrt(er * er + ez * ez);
                if (d < best - 1e-12) {
                    best = d, rp = cr, zp = cz, ss = (beta - b0) * rho + s0[i], idx = i;
                    al = beta, nr = -sb, nz = cb;
                }
            }
        }
        foot[3 * k] = rp * c, foot[3 * k + 1] = rp * sn, foot[3 * k + 2] = zp;
        normal[3 * k] = nr * c, normal[3 * k + 1] = nr * sn, normal[3 * k + 2] = nz;
        const double fr = r - rp, fz = z - zp;
        const double dd = sqrt(fr * fr + fz * fz);
        dist[k] = fr * nr + fz * nz < 0.0 ? -dd : dd;
        alpha[k] = al, s[k] = ss, region[k] = code[idx];
    }
    return 0;
}

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_axisym_kernel_c",
    "C kernel of roboisf.parts.axisym_kernel, called through ctypes (roboisf.jit.native).", -1,
    NULL};

PyMODINIT_FUNC PyInit__axisym_kernel_c(void) { return PyModule_Create(&module); }
