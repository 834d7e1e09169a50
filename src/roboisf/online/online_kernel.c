/* C form of roboisf.online.kernel (its numba kernels fk_deflection, sample_kernel and
 * cycle_kernel, with the chain walk, sincos and tip Jacobian of roboisf.robot.vjm_chain, copied
 * from roboisf/robot/vjm_kernel.c), loaded with ctypes by roboisf.jit.native: the same arithmetic
 * in the same order, so the same bits (tests/test_native_online.py). Named online_kernel.c, not
 * kernel.c: setup.py and roboisf.jit.native build every "*_kernel.c" (kernel.py asks for the
 * library under the name "roboisf.online.online_kernel").
 *
 * Arrays are C-contiguous float64 of the shapes the numba kernels index (the Python side checks
 * them): F (7, 4, 4), X_ts / k_tip (6, 6), R_tip_sensor / R_base_work (3, 3), scr (20, 6), the
 * rest vectors. sample_kernel and cycle_kernel take their arrays as one block of pointers (built
 * once per set of arrays by kernel.py: a call converts three or four scalars, not seventeen
 * arguments). No restrict anywhere: the kernels are called with aliased arguments (the
 * deflection of the weight's pass reads and writes scratch row 19; R is rows 14-16 of scr).
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

#define INLINE static inline __attribute__((always_inline))

/* math.pi */
#define PI 3.141592653589793

/* the state vector and the status bits of kernel.py */
#define S_HAVE 0
#define S_LAST_SAMPLE 1
#define S_LAST_CYCLE 2
#define S_STATUS 3
#define S_CYCLES 4
#define S_LAST_BAD 5
#define S_BAD 6
#define S_STOP 7

#define STATUS_DEADBAND 1
#define STATUS_LIMITED 2
#define STATUS_HOLD 4
#define STATUS_RAMP 8
#define STATUS_NO_SAMPLE 16
#define STATUS_BAD_INPUT 32
#define STATUS_IMPLAUSIBLE 64
#define STATUS_STOP 128

/* Python's min(a, b): a unless b < a (a NaN b never wins) */
INLINE double py_min(double a, double b) { return (b < a) ? b : a; }

/* vjm_chain.sincos: fdlibm's __kernel_sin / __kernel_cos polynomials after a three-part
 * Cody-Waite reduction by pi/2; libm beyond |x| < 1e5 (and for NaN, inf). As vjm_kernel.c. */
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

/* vjm_chain.chain_walk of one pose q (6): R_base_6 (row-major) into rb (9), the tip position
 * into p (3), the joint axes into oz (6 x 6, row per joint: z axis, origin). */
INLINE void chain_walk(const double *F, const double *sign, const double *offset, double c23,
                       const double *q, double *oz, double *rb, double *p) {
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
        double *o = oz + 6 * j;
        o[0] = r02;
        o[1] = r12;
        o[2] = r22;
        o[3] = px;
        o[4] = py;
        o[5] = pz;
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
    rb[0] = r00, rb[1] = r01, rb[2] = r02;
    rb[3] = r10, rb[4] = r11, rb[5] = r12;
    rb[6] = r20, rb[7] = r21, rb[8] = r22;
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

/* kernel.fk_deflection: tip rotation R (3 x 3, row stride rs) and deflection d (6) = J K^-1 J^T W
 * of pose q; scr (20 x 6) rows 0-5 the joint axes, 6-11 the Jacobian, 12 K^-1 J^T W. W and d may
 * be the same memory (W is read whole before d is written, as in the numba kernel). */
static void fk_defl(const double *F, const double *sign, const double *offset, double c23,
                    const double *kinv, const double *q, const double *W, double *d, double *R,
                    int64_t rs, double *scr) {
    double *oz = scr;
    double *Jl = scr + 36;
    double *a = scr + 72;
    double rb[9], p[3];
    chain_walk(F, sign, offset, c23, q, oz, rb, p); /* vjm_chain.chain_jacobian */
    tip_jacobian(sign, c23, oz, p, Jl);
    for (int k = 0; k < 3; k++) { /* R_base_tip = R_base_6 . R_6_tip */
        R[0 * rs + k] = rb[0] * FX(6, 0, k) + rb[1] * FX(6, 1, k) + rb[2] * FX(6, 2, k);
        R[1 * rs + k] = rb[3] * FX(6, 0, k) + rb[4] * FX(6, 1, k) + rb[5] * FX(6, 2, k);
        R[2 * rs + k] = rb[6] * FX(6, 0, k) + rb[7] * FX(6, 1, k) + rb[8] * FX(6, 2, k);
    }
    for (int j = 0; j < 6; j++) {
        double tau = 0.0;
        for (int i = 0; i < 6; i++) tau += Jl[i * 6 + j] * W[i];
        a[j] = tau * kinv[j];
    }
    for (int i = 0; i < 6; i++) {
        double acc = 0.0;
        for (int j = 0; j < 6; j++) acc += Jl[i * 6 + j] * a[j];
        d[i] = acc;
    }
}

/* kernel.fk_deflection, R (3, 3) C-contiguous. */
void fk_deflection(const double *F, const double *sign, const double *offset, double c23,
                   const double *kinv, const double *q, const double *W, double *d, double *R,
                   double *scr) {
    fk_defl(F, sign, offset, c23, kinv, q, W, d, R, 3, scr);
}

/* kernel.sample_kernel; a: F, sign, offset, kinv, R_tip_sensor, X_ts, grav, tare, plaus, W_s, q,
 * st, y, scr. Returns 1 (sample filtered into y) or 0 (dropped). */
int64_t sample_kernel(void *const *a, double c23, double cutoff, double t) {
    const double *F = a[0], *sign = a[1], *offset = a[2], *kinv = a[3];
    const double *R_tip_sensor = a[4], *X_ts = a[5], *grav = a[6], *tare = a[7];
    const double *plaus = a[8], *W_s = a[9], *q = a[10];
    double *st = a[11], *y = a[12], *scr = a[13];

    for (int i = 0; i < 6; i++) {
        if (!isfinite(W_s[i])) return 0;
    }
    if (!isfinite(t) || (st[S_HAVE] > 0 && t <= st[S_LAST_SAMPLE])) return 0;
    double *W_c = scr + 13 * 6;
    double m = grav[0];
    if (m != 0.0) {
        double *R = scr + 14 * 6; /* scr[14:17, 0:3] */
        fk_defl(F, sign, offset, c23, kinv, q, scr + 19 * 6, scr + 19 * 6, R, 6, scr);
        /* sensor axes: R_sensor_base = (R_base_tip R_tip_sensor)^T */
        for (int i = 0; i < 3; i++) {
            double acc = 0.0;
            for (int k = 0; k < 3; k++) {
                double rbs = 0.0; /* R_base_sensor[k, i] */
                for (int l = 0; l < 3; l++) rbs += R[k * 6 + l] * R_tip_sensor[l * 3 + i];
                acc += rbs * grav[4 + k];
            }
            W_c[i] = m * acc; /* weight in sensor axes */
        }
        double cx = grav[1], cy = grav[2], cz = grav[3];
        double fx = W_c[0], fy = W_c[1], fz = W_c[2];
        W_c[3] = cy * fz - cz * fy;
        W_c[4] = cz * fx - cx * fz;
        W_c[5] = cx * fy - cy * fx;
    } else {
        for (int i = 0; i < 6; i++) W_c[i] = 0.0;
    }
    for (int i = 0; i < 6; i++) W_c[i] = W_s[i] - tare[i] - W_c[i];
    /* plausibility: the force's magnitude, its distance from the filtered force, the moment at
     * the tool tip */
    double f2 = W_c[0] * W_c[0] + W_c[1] * W_c[1] + W_c[2] * W_c[2];
    int bad = f2 > plaus[0] * plaus[0];
    if (st[S_HAVE] > 0 && !bad) {
        double e0 = W_c[0] - y[0], e1 = W_c[1] - y[1], e2 = W_c[2] - y[2];
        double d2 = e0 * e0 + e1 * e1 + e2 * e2;
        double allowed = plaus[1];
        if (plaus[2] > 0.0 && allowed < INFINITY) allowed += plaus[2] * (t - st[S_LAST_SAMPLE]);
        bad = d2 > allowed * allowed;
    }
    if (!bad && plaus[3] < INFINITY) {
        double m2 = 0.0;
        for (int i = 3; i < 6; i++) {
            double acc = 0.0;
            for (int k = 0; k < 6; k++) acc += X_ts[i * 6 + k] * W_c[k];
            m2 += acc * acc;
        }
        bad = m2 > plaus[3] * plaus[3];
    }
    if (bad) {
        st[S_BAD] += 1.0;
        if (!(t <= st[S_LAST_BAD])) st[S_LAST_BAD] = t;
        return 0;
    }
    if (st[S_HAVE] == 0) {
        for (int i = 0; i < 6; i++) y[i] = W_c[i];
        st[S_HAVE] = 1.0;
    } else {
        double alpha = 1.0 - exp(-2.0 * PI * cutoff * (t - st[S_LAST_SAMPLE]));
        for (int i = 0; i < 6; i++) y[i] += alpha * (W_c[i] - y[i]);
    }
    st[S_LAST_SAMPLE] = t;
    return 1;
}

/* kernel.cycle_kernel; a: F, sign, offset, kinv, X_ts, k_tip, R_base_work, lim, q, st, y, corr,
 * W_tip, delta, scr. Returns the status bits. */
int64_t cycle_kernel(void *const *a, double c23, double t) {
    const double *F = a[0], *sign = a[1], *offset = a[2], *kinv = a[3];
    const double *X_ts = a[4], *k_tip = a[5], *R_base_work = a[6], *lim = a[7], *q = a[8];
    double *st = a[9], *y = a[10], *corr = a[11], *W_tip = a[12], *delta = a[13], *scr = a[14];

    const double deadband = lim[0], size = lim[1], rate = lim[2], cycle = lim[3], hold = lim[4],
                 ramp = lim[5];
    int64_t status = 0;
    double *tgt = scr + 18 * 6; /* scr[18, 0:3] */
    int finite_q = 1;
    for (int i = 0; i < 6; i++) {
        if (!isfinite(q[i])) finite_q = 0;
    }
    double age = t - st[S_LAST_SAMPLE];
    double dt = (st[S_LAST_CYCLE] > -INFINITY) ? t - st[S_LAST_CYCLE] : cycle;
    if (!(dt > 0.0)) { /* NaN, or not after the last cycle: no step at all */
        dt = 0.0;
    } else if (dt > 2.0 * cycle) {
        dt = 2.0 * cycle;
    }
    double step_max = rate * dt;
    if (st[S_STOP] > 0) {
        status |= STATUS_STOP;
        step_max = py_min(step_max, ramp * dt);
        for (int i = 0; i < 3; i++) tgt[i] = 0.0;
    } else if (!finite_q || !isfinite(t)) {
        status |= STATUS_BAD_INPUT;
        for (int i = 0; i < 3; i++) tgt[i] = corr[i];
    } else if (st[S_HAVE] == 0 || age > hold) {
        /* watchdog: hold the last correction for hold s, then ramp it to zero */
        status |= (st[S_HAVE] == 0) ? STATUS_NO_SAMPLE : STATUS_HOLD;
        if (st[S_HAVE] == 0 || age > 2.0 * hold) {
            status |= STATUS_RAMP;
            step_max = py_min(step_max, ramp * dt);
            for (int i = 0; i < 3; i++) tgt[i] = 0.0;
        } else {
            for (int i = 0; i < 3; i++) tgt[i] = corr[i];
        }
    } else if (t - st[S_LAST_BAD] < hold) {
        /* an implausible sample lately: hold what was sent until the force is plausible again */
        status |= STATUS_IMPLAUSIBLE | STATUS_HOLD;
        for (int i = 0; i < 3; i++) tgt[i] = corr[i];
    } else {
        double *R = scr + 14 * 6; /* scr[14:17, 0:3] */
        double *Wb = scr + 17 * 6;
        double *Wt = scr + 13 * 6;
        /* tip axes: X_ts y; base axes: blkdiag(R, R) */
        fk_defl(F, sign, offset, c23, kinv, q, scr + 19 * 6, scr + 19 * 6, R, 6, scr); /* R */
        for (int i = 0; i < 6; i++) {
            double acc = 0.0;
            for (int k = 0; k < 6; k++) acc += X_ts[i * 6 + k] * y[k];
            Wt[i] = acc;
        }
        for (int i = 0; i < 3; i++) {
            double f = 0.0;
            double mm = 0.0;
            for (int k = 0; k < 3; k++) {
                f += R[i * 6 + k] * Wt[k];
                mm += R[i * 6 + k] * Wt[3 + k];
            }
            Wb[i] = f;
            Wb[3 + i] = mm;
        }
        for (int i = 0; i < 6; i++) W_tip[i] = Wb[i];
        fk_defl(F, sign, offset, c23, kinv, q, W_tip, delta, R, 6, scr);
        for (int i = 0; i < 6; i++) {
            double acc = 0.0;
            for (int k = 0; k < 6; k++) acc += k_tip[i * 6 + k] * W_tip[k];
            delta[i] += acc;
        }
        double nrm = 0.0;
        for (int i = 0; i < 3; i++) { /* -R_base_work^T delta */
            double acc = 0.0;
            for (int k = 0; k < 3; k++) acc += R_base_work[k * 3 + i] * delta[k];
            tgt[i] = -acc;
            nrm += acc * acc;
        }
        nrm = sqrt(nrm);
        if (!isfinite(nrm)) {
            status |= STATUS_BAD_INPUT;
            for (int i = 0; i < 3; i++) tgt[i] = corr[i];
        } else if (nrm < deadband) {
            status |= STATUS_DEADBAND;
            for (int i = 0; i < 3; i++) tgt[i] = 0.0;
        } else if (nrm > size) {
            status |= STATUS_LIMITED;
            for (int i = 0; i < 3; i++) tgt[i] *= size / nrm;
        }
    }
    /* rate limit: the step from the last correction, then the size limit once more (rounding) */
    double s2 = 0.0;
    for (int i = 0; i < 3; i++) {
        double e = tgt[i] - corr[i];
        s2 += e * e;
    }
    double s = sqrt(s2);
    if (s > step_max) {
        double f = step_max / s;
        const int64_t quiet =
            STATUS_HOLD | STATUS_RAMP | STATUS_NO_SAMPLE | STATUS_BAD_INPUT | STATUS_STOP;
        if ((status & quiet) == 0) status |= STATUS_LIMITED;
        for (int i = 0; i < 3; i++) corr[i] += f * (tgt[i] - corr[i]);
    } else {
        for (int i = 0; i < 3; i++) corr[i] = tgt[i];
    }
    double n2 = 0.0;
    for (int i = 0; i < 3; i++) n2 += corr[i] * corr[i];
    if (n2 > size * size) {
        double f = size / sqrt(n2) * (1.0 - 1e-12);
        for (int i = 0; i < 3; i++) corr[i] *= f;
    }
    if (isfinite(t) && !(t <= st[S_LAST_CYCLE])) st[S_LAST_CYCLE] = t;
    st[S_STATUS] = (double)status;
    st[S_CYCLES] += 1.0;
    return status;
}

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_online_kernel_c",
    "C kernels of roboisf.online.kernel, called through ctypes (roboisf.jit.native).", -1, NULL};

PyMODINIT_FUNC PyInit__online_kernel_c(void) { return PyModule_Create(&module); }
