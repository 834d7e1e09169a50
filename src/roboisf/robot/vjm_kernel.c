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

/* ---- the IK of roboisf.robot.ik_numba ------------------------------------------------ */

#define PI_RB 3.141592653589793116       /* np.pi */
#define TWO_PI_RB 6.283185307179586232   /* 2.0 * np.pi (exact) */

/* Python's (and numba's) float modulo x % w: fmod, then the sign of the divisor (numba's
 * real_divmod: a zero remainder becomes +0 times the divisor's sign; NaN stays NaN). */
INLINE double py_mod(double x, double w) {
    double m = fmod(x, w);
    if (m != 0.0) {
        if ((w < 0.0) != (m < 0.0)) m += w;
    } else {
        m = m * m;
        if (w < 0.0) m = -m;
    }
    return m;
}

/* ik_numba._atan_pos / atan2: fdlibm's atan (reduction with the atanhi/atanlo table, an
 * 11-term odd polynomial); libm's atan2 for zeros, infinities and NaN. */
#define ATANHI0 4.63647609000806093515e-01
#define ATANHI1 7.85398163397448278999e-01
#define ATANHI2 9.82793723247329054082e-01
#define ATANLO0 2.26987774529616870924e-17
#define ATANLO1 3.06161699786838301793e-17
#define ATANLO2 1.39033110312309984516e-17
#define HALF_PI_HI 1.57079632679489655800e00
#define HALF_PI_LO 6.12323399573676603587e-17
#define PI_LO 1.2246467991473531772e-16
#define AT0 3.33333333333329318027e-01
#define AT1 -1.99999999998764832476e-01
#define AT2 1.42857142725034663711e-01
#define AT3 -1.11111104054623557880e-01
#define AT4 9.09088713343650656196e-02
#define AT5 -7.69187620504482999495e-02
#define AT6 6.66107313738753120669e-02
#define AT7 -5.83357013379057348645e-02
#define AT8 4.97687799461593236017e-02
#define AT9 -3.65315727442169155270e-02
#define AT10 1.62858201153657823623e-02

INLINE double atan_pos(double x) {
    int ident;
    if (x >= 7.3786976294838206464e19) return HALF_PI_HI + HALF_PI_LO; /* 2**66 */
    if (x < 0.4375) {
        if (x < 7.450580596923828e-09) return x; /* 2**-27 */
        ident = -1;
    } else if (x < 1.1875) {
        if (x < 0.6875) {
            ident = 0;
            x = (2.0 * x - 1.0) / (2.0 + x);
        } else {
            ident = 1;
            x = (x - 1.0) / (x + 1.0);
        }
    } else if (x < 2.4375) {
        ident = 2;
        x = (x - 1.5) / (1.0 + 1.5 * x);
    } else {
        ident = 3;
        x = -1.0 / x;
    }
    double z = x * x;
    double w = z * z;
    double s1 = z * (AT0 + w * (AT2 + w * (AT4 + w * (AT6 + w * (AT8 + w * AT10)))));
    double s2 = w * (AT1 + w * (AT3 + w * (AT5 + w * (AT7 + w * AT9))));
    if (ident < 0) return x - x * (s1 + s2);
    double hi, lo;
    if (ident == 0) {
        hi = ATANHI0, lo = ATANLO0;
    } else if (ident == 1) {
        hi = ATANHI1, lo = ATANLO1;
    } else if (ident == 2) {
        hi = ATANHI2, lo = ATANLO2;
    } else {
        hi = HALF_PI_HI, lo = HALF_PI_LO;
    }
    return hi - ((x * (s1 + s2) - lo) - x);
}

INLINE double atan2_rb(double y, double x) {
    if (x == 0.0 || y == 0.0 || !(fabs(x) < INFINITY && fabs(y) < INFINITY)) return atan2(y, x);
    double r = fabs(y / x);
    if (r > 1.152921504606847e18) /* |y/x| > 2**60 */
        return y > 0.0 ? HALF_PI_HI + 0.5 * PI_LO : -(HALF_PI_HI + 0.5 * PI_LO);
    double z = (x < 0.0 && r < 8.673617379884035e-19) ? 0.0 : atan_pos(r); /* 2**-60 */
    if (x > 0.0) return y > 0.0 ? z : -z;
    if (y > 0.0) return PI_RB - (z - PI_LO);
    return (z - PI_LO) - PI_RB;
}

/* ik_numba._wrap: np.mod(x + pi, 2 pi) - pi, the exact shortcuts of the numba form. */
INLINE double wrap_pi(double x) {
    double y = x + PI_RB;
    if (0.0 < y && y < TWO_PI_RB) return y - PI_RB;
    if (TWO_PI_RB <= y && y < 2.0 * TWO_PI_RB) return (y - TWO_PI_RB) - PI_RB;
    if (-TWO_PI_RB < y && y < 0.0) return (y + TWO_PI_RB) - PI_RB;
    return py_mod(y, TWO_PI_RB) - PI_RB;
}

/* ik_numba._opw: one flange pose (R row-major r.., p) -> qn (6, controller angles wrapped) of
 * the branch flags = (front, sgn, flip); returns reachability (the row NaN when 0). geo: a1,
 * a2, b, c1, c2, c3, c4, kappa^2, kappa, phi. */
INLINE int opw(double r00, double r01, double r02, double r10, double r11, double r12,
               double r20, double r21, double r22, double px, double py, double pz,
               const double *geo, const double *flags, const double *sign,
               const double *offset, double cpl, double *qn) {
    const double a1 = geo[0], a2 = geo[1], b = geo[2], c1 = geo[3], c2 = geo[4], c3g = geo[5],
                 c4 = geo[6];
    const double kappa2 = geo[7], kappa = geo[8], phi = geo[9];
    const int front = flags[0] > 0.0;
    const double sgn = flags[1];
    const int flip = flags[2] > 0.0;
    double cx = px - c4 * r02;
    double cy = py - c4 * r12;
    double cz = pz - c4 * r22;
    double rho2 = cx * cx + cy * cy - b * b;
    int ok = rho2 >= 0;
    double r = ok ? sqrt(rho2) : 0.0;
    double xr = front ? r : -r;
    double u = cx * xr + cy * b;
    double v = cy * xr - cx * b;
    double th1 = atan2_rb(v, u);
    double h2 = u * u + v * v;
    double cc1, s1;
    if (h2 > 0.0) {
        double h = 1.0 / sqrt(h2);
        cc1 = u * h, s1 = v * h;
    } else {
        sincos_rb(th1, &s1, &cc1);
    }
    double x = xr - a1;
    double z = cz - c1;
    double D = (x * x + z * z - c2 * c2 - kappa2) / (2.0 * c2 * kappa);
    ok = ok && fabs(D) <= 1.0 + 1e-12;
    double mx = (-1.0 > D) ? -1.0 : D; /* max(D, -1.0) */
    double mn = (1.0 < mx) ? 1.0 : mx; /* min(., 1.0) */
    double acos_d = acos(mn);
    double th3 = sgn * acos_d - phi;
    double s3, cc3;
    sincos_rb(th3, &s3, &cc3);
    double wx = a2 * cc3 + c3g * s3;
    double wz = c2 - a2 * s3 + c3g * cc3;
    double th2 = atan2_rb(x * wz - z * wx, z * wz + x * wx);
    double s23, c23;
    sincos_rb(th2 + th3, &s23, &c23);
    double e00 = cc1 * c23, e01 = s1 * c23, e02 = -s23;
    double e20 = cc1 * s23, e21 = s1 * s23, e22 = c23;
    double w02 = e00 * r02 + e01 * r12 + e02 * r22;
    double w12 = -s1 * r02 + cc1 * r12;
    double w20 = e20 * r00 + e21 * r10 + e22 * r20;
    double w21 = e20 * r01 + e21 * r11 + e22 * r21;
    double w22 = e20 * r02 + e21 * r12 + e22 * r22;
    double th5 = atan2_rb(sqrt(w02 * w02 + w12 * w12), w22);
    double th4 = atan2_rb(w12, w02);
    double th6 = atan2_rb(w21, -w20);
    if (flip) {
        th4 = th4 + PI_RB;
        th5 = -th5;
        th6 = th6 + PI_RB;
    }
    if (!ok) {
        for (int j = 0; j < 6; j++) qn[j] = NAN;
        return 0;
    }
    qn[0] = wrap_pi((th1 - offset[0]) * sign[0]);
    qn[1] = wrap_pi((th2 - offset[1]) * sign[1]);
    qn[2] = wrap_pi((th3 - offset[2]) * sign[2] - cpl * ((th2 - offset[1]) * sign[1]));
    qn[3] = wrap_pi((th4 - offset[3]) * sign[3]);
    qn[4] = wrap_pi((th5 - offset[4]) * sign[4]);
    qn[5] = wrap_pi((th6 - offset[5]) * sign[5]);
    return 1;
}

/* ik_numba._flange_rows: poses s..e-1 of T (N, 4, 4) -> q (N, 6), ok (N, bytes 0/1). */
void
flange_rows(const double *T, const double *geo, const double *flags, const double *sign,
            const double *offset, double c23, double *q, uint8_t *ok, int64_t s, int64_t e) {
    for (int64_t n = s; n < e; n++) {
        const double *t = T + 16 * n;
        ok[n] = (uint8_t)opw(t[0], t[1], t[2], t[4], t[5], t[6], t[8], t[9], t[10], t[3], t[7],
                             t[11], geo, flags, sign, offset, c23, q + 6 * n);
    }
}

/* ik_numba._tip_rows: poses s..e-1: T_base_tip = A [vertical_tool(gamma), tip], T_base_flange =
 * T_base_tip B (A = T_base_work, B = T_flange_tip^-1, both (4, 4)), then the OPW branch;
 * T_tip (N, 4, 4) written when not NULL. gam: ngam = 1 angle for the path, or N. */
void
tip_rows(const double *A, const double *B, const double *tip, const double *gam, int64_t ngam,
         const double *geo, const double *flags, const double *sign, const double *offset,
         double c23, double *q, uint8_t *ok, double *T_tip, int64_t s, int64_t e) {
    const int one_g = ngam == 1;
    double sg = 0.0, cg = 1.0;
    if (ngam > 0) sincos_rb(gam[0], &sg, &cg); /* one angle for the path: once */
#define AX(r, c) A[4 * (r) + (c)]
#define BX(r, c) B[4 * (r) + (c)]
    for (int64_t n = s; n < e; n++) {
        if (!one_g) sincos_rb(gam[n], &sg, &cg);
        double t0 = tip[3 * n], t1 = tip[3 * n + 1], t2 = tip[3 * n + 2];
        double m00 = AX(0, 0) * cg - AX(0, 1) * sg;
        double m01 = -AX(0, 0) * sg - AX(0, 1) * cg;
        double m02 = -AX(0, 2);
        double m10 = AX(1, 0) * cg - AX(1, 1) * sg;
        double m11 = -AX(1, 0) * sg - AX(1, 1) * cg;
        double m12 = -AX(1, 2);
        double m20 = AX(2, 0) * cg - AX(2, 1) * sg;
        double m21 = -AX(2, 0) * sg - AX(2, 1) * cg;
        double m22 = -AX(2, 2);
        double p0 = AX(0, 0) * t0 + AX(0, 1) * t1 + AX(0, 2) * t2 + AX(0, 3);
        double p1 = AX(1, 0) * t0 + AX(1, 1) * t1 + AX(1, 2) * t2 + AX(1, 3);
        double p2 = AX(2, 0) * t0 + AX(2, 1) * t1 + AX(2, 2) * t2 + AX(2, 3);
        if (T_tip != NULL) {
            double *o = T_tip + 16 * n;
            o[0] = m00, o[1] = m01, o[2] = m02, o[3] = p0;
            o[4] = m10, o[5] = m11, o[6] = m12, o[7] = p1;
            o[8] = m20, o[9] = m21, o[10] = m22, o[11] = p2;
            o[12] = 0.0, o[13] = 0.0, o[14] = 0.0, o[15] = 1.0;
        }
        ok[n] = (uint8_t)opw(m00 * BX(0, 0) + m01 * BX(1, 0) + m02 * BX(2, 0),
                             m00 * BX(0, 1) + m01 * BX(1, 1) + m02 * BX(2, 1),
                             m00 * BX(0, 2) + m01 * BX(1, 2) + m02 * BX(2, 2),
                             m10 * BX(0, 0) + m11 * BX(1, 0) + m12 * BX(2, 0),
                             m10 * BX(0, 1) + m11 * BX(1, 1) + m12 * BX(2, 1),
                             m10 * BX(0, 2) + m11 * BX(1, 2) + m12 * BX(2, 2),
                             m20 * BX(0, 0) + m21 * BX(1, 0) + m22 * BX(2, 0),
                             m20 * BX(0, 1) + m21 * BX(1, 1) + m22 * BX(2, 1),
                             m20 * BX(0, 2) + m21 * BX(1, 2) + m22 * BX(2, 2),
                             m00 * BX(0, 3) + m01 * BX(1, 3) + m02 * BX(2, 3) + p0,
                             m10 * BX(0, 3) + m11 * BX(1, 3) + m12 * BX(2, 3) + p1,
                             m20 * BX(0, 3) + m21 * BX(1, 3) + m22 * BX(2, 3) + p2, geo, flags,
                             sign, offset, c23, q + 6 * n);
    }
#undef AX
#undef BX
}

/* ik_numba._round_half_even */
INLINE double round_half_even(double x) {
    double r = floor(x + 0.5) * 1.0;
    if (r - x == 0.5 && py_mod(r, 2.0) != 0.0) r -= 1.0;
    return r;
}

/* ik_numba._continuous: in place on q (n, 6): np.unwrap along the path, the whole-turn shift
 * into the limits; returns 1 when every angle is within them (+- 1e-9 rad). n = 0: 1 (no
 * angle; the numba form reads a row that is not there). */
int64_t
continuous(double *q, int64_t n, const double *q_min, const double *q_max) {
    if (n <= 0) return 1;
    int64_t all_in = 1;
    for (int j = 0; j < 6; j++) {
        double acc = 0.0;
        double prev = q[j];
        double tot = prev, lo_q = prev, hi_q = prev;
        for (int64_t i = 1; i < n; i++) {
            double cur = q[6 * i + j];
            double dd = cur - prev;
            prev = cur;
            if (!(fabs(dd) < PI_RB)) {
                double ddmod = py_mod(dd + PI_RB, TWO_PI_RB) - PI_RB;
                if (ddmod == -PI_RB && dd > 0) ddmod = PI_RB;
                acc += ddmod - dd;
            }
            double v = cur + acc;
            q[6 * i + j] = v;
            tot += v;
            if (v < lo_q) lo_q = v;
            if (v > hi_q) hi_q = v;
        }
        double mean = tot / (double)n;
        double mid = 0.5 * (q_min[j] + q_max[j]);
        double k = round_half_even((mid - mean) / TWO_PI_RB);
        double lo = q_min[j] - 1e-9;
        double hi = q_max[j] + 1e-9;
        double sh = k * TWO_PI_RB;
        double lo_s = lo_q + sh, hi_s = hi_q + sh;
        double dk = 0.0;
        for (int t = 0; t < 3; t++) {
            double dt = t == 0 ? 0.0 : (t == 1 ? 1.0 : -1.0);
            double a = lo_s + dt * TWO_PI_RB;
            double b = hi_s + dt * TWO_PI_RB;
            if (a >= lo && a <= hi && b >= lo && b <= hi) {
                dk = dt;
                break;
            }
        }
        double ds = dk * TWO_PI_RB;
        for (int64_t i = 0; i < n; i++) {
            q[6 * i + j] = q[6 * i + j] + sh;
            if (dk != 0.0) q[6 * i + j] = q[6 * i + j] + ds;
        }
        if (lo_s + ds < lo || hi_s + ds > hi) all_in = 0;
    }
    return all_in;
}

/* ik_numba._row6 */
INLINE double row6(const double *C, int i, double a0, double a1, double a2, double a3,
                   double a4, double a5) {
    const double *c = C + 6 * i;
    return a0 * c[0] + a1 * c[1] + a2 * c[2] + a3 * c[3] + a4 * c[4] + a5 * c[5];
}

/* ik_numba._vjm_rows: poses s..e-1 of a solved path (q (N, 6)): the wrench (W_work (N or 1, 6)
 * work axes) into base axes (W_base (N, 6), scratch), the VJM pass of vjm_rows (d (N, 6), the
 * margin test into ok), delta into work axes (A = R_base_work (3, 3)), the tool's deflection
 * (C_tool (6, 6) tool axes, NULL: none), the ball centre rb above the tip, |delta|, the
 * normal component (nrm (N, 3), NULL: none) and the joint steps. */
void
path_vjm_rows(const double *F, const double *sign, const double *offset, double c23,
              const double *kinv, const double *q, const double *W_work, int64_t nw,
              const double *A, const double *C_tool, const double *gam, int64_t ngam,
              const double *mg, double rb, double *W_base, double *d, uint8_t *margin_ok,
              double *d_robot, double *d_total, double *abs_total, double *steps,
              const double *nrm, double *abs_robot, double *abs_normal, int64_t s, int64_t e) {
    const int one_w = nw == 1;
    const int one_g = ngam == 1;
#define AX(r, c) A[3 * (r) + (c)]
    for (int64_t n = s; n < e; n++) {
        const double *w = W_work + (one_w ? 0 : 6 * n);
        for (int i = 0; i < 3; i++) {
            W_base[6 * n + i] = AX(i, 0) * w[0] + AX(i, 1) * w[1] + AX(i, 2) * w[2];
            W_base[6 * n + 3 + i] = AX(i, 0) * w[3] + AX(i, 1) * w[4] + AX(i, 2) * w[5];
        }
    }
    double sg = 0.0, cg = 1.0;
    if (ngam > 0) sincos_rb(gam[0], &sg, &cg); /* one angle for the path: once */
    /* vjm_numba._rows with W_base of N rows (one row when N = 1: the same row) */
    vjm_rows(F, sign, offset, c23, kinv, q, W_base, 0, s, e, d, NULL, NULL, mg, margin_ok);
    for (int64_t n = s; n < e; n++) {
        const double *dn = d + 6 * n;
        double x0 = dn[0] * AX(0, 0) + dn[1] * AX(1, 0) + dn[2] * AX(2, 0);
        double x1 = dn[0] * AX(0, 1) + dn[1] * AX(1, 1) + dn[2] * AX(2, 1);
        double x2 = dn[0] * AX(0, 2) + dn[1] * AX(1, 2) + dn[2] * AX(2, 2);
        if (rb != 0.0) {
            double h0 = dn[3] * AX(0, 0) + dn[4] * AX(1, 0) + dn[5] * AX(2, 0);
            double h1 = dn[3] * AX(0, 1) + dn[4] * AX(1, 1) + dn[5] * AX(2, 1);
            x0 = x0 + h1 * rb;
            x1 = x1 - h0 * rb;
        }
        d_robot[3 * n] = x0, d_robot[3 * n + 1] = x1, d_robot[3 * n + 2] = x2;
        abs_robot[n] = sqrt(x0 * x0 + x1 * x1 + x2 * x2);
        if (C_tool != NULL) {
            if (!one_g) sincos_rb(gam[n], &sg, &cg);
            const double *w = W_work + (one_w ? 0 : 6 * n);
            double f0 = w[0], f1 = w[1], m0 = w[3], m1 = w[4];
            double wt0 = cg * f0 - sg * f1;
            double wt1 = sg * f0 + cg * f1;
            double wt3 = cg * m0 - sg * m1;
            double wt4 = sg * m0 + cg * m1;
            double f2 = w[2], m2 = w[5];
            double t0 = row6(C_tool, 0, wt0, wt1, f2, wt3, wt4, m2);
            double t1 = row6(C_tool, 1, wt0, wt1, f2, wt3, wt4, m2);
            double t2 = row6(C_tool, 2, wt0, wt1, f2, wt3, wt4, m2);
            double y0 = cg * t0 + sg * t1;
            double y1 = -sg * t0 + cg * t1;
            if (rb != 0.0) {
                double t3 = row6(C_tool, 3, wt0, wt1, f2, wt3, wt4, m2);
                double t4 = row6(C_tool, 4, wt0, wt1, f2, wt3, wt4, m2);
                y0 = y0 + (-sg * t3 + cg * t4) * rb;
                y1 = y1 - (cg * t3 + sg * t4) * rb;
            }
            x0 += y0;
            x1 += y1;
            x2 += t2;
        }
        d_total[3 * n] = x0, d_total[3 * n + 1] = x1, d_total[3 * n + 2] = x2;
        abs_total[n] = sqrt(x0 * x0 + x1 * x1 + x2 * x2);
        if (nrm != NULL)
            abs_normal[n] = fabs((x0 * nrm[3 * n] + x2 * nrm[3 * n + 2]) + x1 * nrm[3 * n + 1]);
        double st = 0.0;
        if (n > 0) {
            for (int j = 0; j < 6; j++) {
                double v = fabs(q[6 * n + j] - q[6 * (n - 1) + j]);
                st = (v > st) ? v : st; /* max(st, v) */
            }
        }
        steps[n] = st;
    }
#undef AX
}

/* ik_numba._atan2_many / _wrap_many (for the tests): atan2 and _wrap of n values into out. */
void
atan2_many(const double *y, const double *x, double *out, int64_t n) {
    for (int64_t i = 0; i < n; i++) out[i] = atan2_rb(y[i], x[i]);
}

void
wrap_many(const double *x, double *out, int64_t n) {
    for (int64_t i = 0; i < n; i++) out[i] = wrap_pi(x[i]);
}

/* vjm_numba._margin_rows: the margin test of Js (N, 6, 6) poses s..e-1 into ok (bytes 0/1). */
void
margin_rows(const double *Js, double lin_scale, double c, uint8_t *ok, int64_t s, int64_t e) {
    double M[72];
    for (int64_t n = s; n < e; n++) ok[n] = (uint8_t)margin_pivots_ok(Js + 36 * n, lin_scale, c, M);
}

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_vjm_kernel_c",
    "C kernels of roboisf.robot.vjm_kernel, called through ctypes (roboisf.jit.native).", -1,
    NULL};

PyMODINIT_FUNC PyInit__vjm_kernel_c(void) { return PyModule_Create(&module); }
