/* C form of the robot batch kernels: roboisf.robot.fk_numba._rows (tip positions of a joint
 * log) and roboisf.robot.vjm_numba._rows (the fused VJM pass: chain walk, tip Jacobian,
 * deflection, compliance, singularity-margin test), with the chain walk, the sincos and the tip
 * Jacobian of roboisf.robot.vjm_chain. Loaded with ctypes by roboisf.jit.native for
 * roboisf.robot.vjm_kernel: the same arithmetic in the same order, so the same bits
 * (tests/test_native_robot.py). Arrays are C-contiguous float64 (the Python side makes them
 * so); F is (7, 4, 4), q (N, 6). Built by pip install with the flags of
 * roboisf.jit.native.CFLAGS (no fused multiply-add, no fast-math). */
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

/* vjm_chain.sincos: fdlibm's __kernel_sin / __kernel_cos polynomials after a three-part
 * Cody-Waite reduction by pi/2; libm beyond |x| < 1e5 (and for NaN, inf). */
#define PIO2_1 1.57079632673412561417e00
#define PIO2_2 6.07710050630396597660e-11
#define PIO2_3 2.02226624879595063154e-21
#define S1 -1.66666666666666324348e-01
#define S2 8.33333333332248946124e-03
#define S3 -1.98412698298579493134e-04
#define S4 2.75573137070700676789e-06
#define S5 -2.50507602534068634195e-08
#define S6 1.58969099521155010221e-10
#define C1 4.16666666666666019037e-02
#define C2 -1.38888888888741095749e-03
#define C3 2.48015872894767294178e-05
#define C4 -2.75573143513906633035e-07
#define C5 2.08757232129817482790e-09
#define C6 -1.13596475577881948265e-11

INLINE void sincos_rb(double x, double *so, double *co) {
    if (!(fabs(x) < 1e5)) {
        *so = sin(x);
        *co = cos(x);
        return;
    }
    /* round(x / (pi/2)): numba's round of a float is llvm.rint (half to even), then to int64 */
    int64_t n = (int64_t)rint(x * 0.636619772367581343);
    double dn = (double)n;
    double r = ((x - dn * PIO2_1) - dn * PIO2_2) - dn * PIO2_3;
    double z = r * r;
    double s = r + r * z * (S1 + z * (S2 + z * (S3 + z * (S4 + z * (S5 + z * S6)))));
    double hz = 0.5 * z;
    double w = 1.0 - hz;
    double c =
        w + (((1.0 - w) - hz) + z * z * (C1 + z * (C2 + z * (C3 + z * (C4 + z * (C5 + z * C6))))));
    switch (n & 3) { /* two's complement: Python's int & 3 of a negative n */
    case 0:
        *so = s;
        *co = c;
        return;
    case 1:
        *so = c;
        *co = -s;
        return;
    case 2:
        *so = -s;
        *co = -c;
        return;
    default:
        *so = -c;
        *co = s;
        return;
    }
}

#define FX(j, r, c) F[(j) * 16 + (r) * 4 + (c)]

/* vjm_chain.chain_walk of one pose q (6): the tip position into p (3); with oz (6 x 6, row
 * per joint: z axis, origin) not NULL, the joint axes recorded for tip_jacobian. R_base_6 is
 * not returned (no caller here reads it). */
INLINE void chain_walk(const double *F, const double *sign, const double *offset, double c23,
                       const double *q, double *oz, double *p) {
    double r00 = FX(0, 0, 0), r01 = FX(0, 0, 1), r02 = FX(0, 0, 2);
    double r10 = FX(0, 1, 0), r11 = FX(0, 1, 1), r12 = FX(0, 1, 2);
    double r20 = FX(0, 2, 0), r21 = FX(0, 2, 1), r22 = FX(0, 2, 2);
    double px = FX(0, 0, 3), py = FX(0, 1, 3), pz = FX(0, 2, 3);
    for (int j = 0; j < 6; j++) {
        if (j > 0) {
            double t0 = FX(j, 0, 3), t1 = FX(j, 1, 3), t2 = FX(j, 2, 3);
            px += r00 * t0 + r01 * t1 + r02 * t2;
            py += r10 * t0 + r11 * t1 + r12 * t2;
            pz += r20 * t0 + r21 * t1 + r22 * t2;
            double f00 = FX(j, 0, 0), f01 = FX(j, 0, 1), f02 = FX(j, 0, 2);
            double f10 = FX(j, 1, 0), f11 = FX(j, 1, 1), f12 = FX(j, 1, 2);
            double f20 = FX(j, 2, 0), f21 = FX(j, 2, 1), f22 = FX(j, 2, 2);
            double a0, a1, a2;
            a0 = r00 * f00 + r01 * f10 + r02 * f20;
            a1 = r00 * f01 + r01 * f11 + r02 * f21;
            a2 = r00 * f02 + r01 * f12 + r02 * f22;
            r00 = a0, r01 = a1, r02 = a2;
            a0 = r10 * f00 + r11 * f10 + r12 * f20;
            a1 = r10 * f01 + r11 * f11 + r12 * f21;
            a2 = r10 * f02 + r11 * f12 + r12 * f22;
            r10 = a0, r11 = a1, r12 = a2;
            a0 = r20 * f00 + r21 * f10 + r22 * f20;
            a1 = r20 * f01 + r21 * f11 + r22 * f21;
            a2 = r20 * f02 + r21 * f12 + r22 * f22;
            r20 = a0, r21 = a1, r22 = a2;
        }
        if (oz != NULL) {
            double *o = oz + 6 * j;
            o[0] = r02;
            o[1] = r12;
            o[2] = r22;
            o[3] = px;
            o[4] = py;
            o[5] = pz;
        }
        double th = sign[j] * q[j] + offset[j];
        if (j == 2 && c23 != 0.0) th += sign[2] * c23 * q[1]; /* FANUC J2/J3 coupling */
        double sn, c;
        sincos_rb(th, &sn, &c);
        double b0, b1;
        b0 = c * r00 + sn * r01;
        b1 = c * r01 - sn * r00;
        r00 = b0, r01 = b1;
        b0 = c * r10 + sn * r11;
        b1 = c * r11 - sn * r10;
        r10 = b0, r11 = b1;
        b0 = c * r20 + sn * r21;
        b1 = c * r21 - sn * r20;
        r20 = b0, r21 = b1;
    }
    double t0 = FX(6, 0, 3), t1 = FX(6, 1, 3), t2 = FX(6, 2, 3);
    px += r00 * t0 + r01 * t1 + r02 * t2;
    py += r10 * t0 + r11 * t1 + r12 * t2;
    pz += r20 * t0 + r21 * t1 + r22 * t2;
    p[0] = px;
    p[1] = py;
    p[2] = pz;
}

/* vjm_chain.tip_jacobian: Jl (6 x 6, row-major) from oz and the tip position p. */
INLINE void tip_jacobian(const double *sign, double c23, const double *oz, const double *p,
                         double *Jl) {
    const double px = p[0], py = p[1], pz = p[2];
    for (int j = 0; j < 6; j++) {
        const double *o = oz + 6 * j;
        double zx = o[0], zy = o[1], zz = o[2];
        double rx = px - o[3], ry = py - o[4], rz = pz - o[5];
        double sj = sign[j];
        Jl[0 * 6 + j] = sj * (zy * rz - zz * ry);
        Jl[1 * 6 + j] = sj * (zz * rx - zx * rz);
        Jl[2 * 6 + j] = sj * (zx * ry - zy * rx);
        Jl[3 * 6 + j] = sj * zx;
        Jl[4 * 6 + j] = sj * zy;
        Jl[5 * 6 + j] = sj * zz;
    }
    if (c23 != 0.0) { /* d/dq2 also turns joint 3: column 2 += c23 x column 3 */
        for (int i = 0; i < 6; i++) Jl[i * 6 + 1] += c23 * Jl[i * 6 + 2];
    }
}

/* vjm_numba.margin_pivots_ok: sigma_min(J_s) > sqrt(c), J_s = J with rows 0-2 times lin_scale,
 * by the LDL^T pivots of J_s^T J_s - c I (M: 12 x 6 scratch). */
INLINE int margin_pivots_ok(const double *J, double lin_scale, double c, double *M) {
    for (int i = 0; i < 6; i++) {
        for (int r = 0; r < 3; r++) M[(6 + i) * 6 + r] = J[r * 6 + i] * lin_scale;
        for (int r = 3; r < 6; r++) M[(6 + i) * 6 + r] = J[r * 6 + i];
    }
    for (int i = 0; i < 6; i++) {
        for (int j = i; j < 6; j++) {
            double acc = 0.0;
            for (int r = 0; r < 6; r++) acc += M[(6 + i) * 6 + r] * M[(6 + j) * 6 + r];
            M[i * 6 + j] = acc;
        }
        M[i * 6 + i] -= c;
    }
    for (int p = 0; p < 6; p++) {
        double piv = M[p * 6 + p];
        if (!(piv > 0.0)) return 0;
        double inv = 1.0 / piv;
        for (int i = p + 1; i < 6; i++) {
            double lk = M[p * 6 + i] * inv;
            for (int j = i; j < 6; j++) M[i * 6 + j] -= lk * M[p * 6 + j];
        }
    }
    return 1;
}

/* fk_numba._rows: poses s..e-1 of q (N, 6), tip position T[:3] @ [p; 1] into out (N, 3). */
void
fk_rows(const double *F, const double *sign, const double *offset, double c23, const double *T,
        const double *q, double *out, int64_t s, int64_t e) {
    for (int64_t n = s; n < e; n++) {
        double p[3];
        chain_walk(F, sign, offset, c23, q + 6 * n, NULL, p);
        for (int i = 0; i < 3; i++)
            out[3 * n + i] = T[4 * i + 0] * p[0] + T[4 * i + 1] * p[1] + T[4 * i + 2] * p[2] +
                             T[4 * i + 3];
    }
}

/* vjm_numba._rows: poses s..e-1 of q (N, 6): the deflection into d (N, 6); the compliance into
 * k (N, 6, 6), the Jacobian into J (N, 6, 6) and the margin test into ok (N, bytes 0/1) when
 * those are not NULL. W: (N, 6), or one wrench (1, 6) for every pose when one_w; kinv (6,);
 * margin = (1 / length scale, threshold^2). */
void
vjm_rows(const double *F, const double *sign, const double *offset, double c23, const double *kinv,
         const double *q, const double *W, int64_t one_w, int64_t s, int64_t e, double *d,
         double *k, double *J, const double *margin, uint8_t *ok) {
    double oz[36], Jl[36], M[72], a[6], p[3];
    for (int64_t n = s; n < e; n++) {
        chain_walk(F, sign, offset, c23, q + 6 * n, oz, p);
        tip_jacobian(sign, c23, oz, p, Jl);
        const double *w = W + (one_w ? 0 : 6 * n);
        for (int j = 0; j < 6; j++) {
            double tau = 0.0;
            for (int i = 0; i < 6; i++) tau += Jl[i * 6 + j] * w[i];
            a[j] = tau * kinv[j];
        }
        for (int i = 0; i < 6; i++) {
            double acc = 0.0;
            for (int j = 0; j < 6; j++) acc += Jl[i * 6 + j] * a[j];
            d[6 * n + i] = acc;
        }
        if (k != NULL) {
            double *kn = k + 36 * n;
            for (int i = 0; i < 6; i++) {
                for (int m = i; m < 6; m++) {
                    double acc = 0.0;
                    for (int j = 0; j < 6; j++) acc += Jl[i * 6 + j] * kinv[j] * Jl[m * 6 + j];
                    kn[i * 6 + m] = acc;
                    kn[m * 6 + i] = acc;
                }
            }
        }
        if (J != NULL) {
            double *Jn = J + 36 * n;
            for (int i = 0; i < 36; i++) Jn[i] = Jl[i];
        }
        if (ok != NULL) ok[n] = (uint8_t)margin_pivots_ok(Jl, margin[0], margin[1], M);
    }
}

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_vjm_kernel_c",
    "C kernels of roboisf.robot.vjm_kernel, called through ctypes (roboisf.jit.native).", -1,
    NULL};

PyMODINIT_FUNC PyInit__vjm_kernel_c(void) { return PyModule_Create(&module); }
