/* C form of roboisf.parts.pyramid_kernel (the numba kernel of pyramid_kernel.py), loaded with
 * ctypes by roboisf.jit.native: the same arithmetic in the same order, so the same bits
 * (tests/test_native_pyramid.py). The points come as a pointer to element [0, 0] and strides in
 * elements; the packed pyramid and the outputs are C-contiguous. Built by pip install with the
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

/* The packed pyramid's scalars (pyramid_kernel.pack; the same indices there). */
enum {
    DEPTH, BX, BY, BR, SLOPE, FW, OX, OY, ORC, OXF, OYF, ORCF, HC, CA, CA_SIN, CA_MSIN, CA_COS,
    R0, DR, DZ, L2, CXP, CXM, CYP, CYM, ISQ2, NPRM
};
/* A wall's row: origin, in-plane axes, tool-side normal, wall angle, its sine. */
enum { WO = 0, WE1 = 3, WE2 = 6, WN = 9, WA = 12, WSA = 13, NWALL = 14 };
/* The tie rule [m] (pyramid.TIE): a later patch is taken only when nearer by more than this. */
#define TIE 1e-12
/* Most vertices of a wall polygon (pyramid_kernel.MAX_VERTICES). */
#define MAXV 8

/* _rounded_rectangle_abs of pyramid.py for one point: the closest boundary point's |x|, |y| and
 * the signed distance of (ax, ay) to the rounded rectangle of half sizes a, b and radius r. */
static inline void rr_abs(double ax, double ay, double a, double b, double r, double *cx,
                          double *cy, double *sd) {
    const double qx = ax - (a - r), qy = ay - (b - r);
    if (qx >= qy) {
        *cx = a, *cy = ay, *sd = qx - r;
    } else {
        *cx = ax, *cy = b, *sd = qy - r;
    }
    if (qx > 0.0 && qy > 0.0) {
        const double nq = hypot(qx, qy);
        const double scale = r / nq;
        *cx = (a - r) + qx * scale, *cy = (b - r) + qy * scale, *sd = nq - r;
    }
}

/* pyramid_kernel._closest: the closest point of each of X (n rows, strides rs, cs) on the
 * packed pyramid — prm (NPRM,), nw walls (nw, NWALL) with their polygons' nv[i] vertices
 * uv (nw, MAXV, 2), region codes (flange, wall, bottom) — into foot, normal (n, 3), dist,
 * alpha, s, region (n,). The patches in the numpy query's order and tie rule (a later patch
 * wins only when nearer by more than TIE): walls, corner cones, bottom, flange; a wall whose
 * plane is farther than the bottom's, the flange's or the best so far is skipped, as there. numpy's
 * clip(t, 0, 1) and minimum(a, b) are spelled out as numpy defines them for numbers:
 * max(a, b) = a > b ? a : b, min(a, b) = a < b ? a : b. */
__attribute__((target_clones("avx2", "default"))) void
closest(const double *X, int64_t n, int64_t rs, int64_t cs, const double *prm, const double *walls,
        const double *uv, const int64_t *nv, int64_t nw, const int64_t *codes, double *foot,
        double *normal, double *dist, double *alpha, double *s, int64_t *region) {
    const double depth = prm[DEPTH], fw = prm[FW];
    for (int64_t k = 0; k < n; k++) {
        const double *p = X + k * rs;
        const double x = p[0], y = p[cs], z = p[2 * cs];
        const double ax = fabs(x), ay = fabs(y);
        /* the bottom: the section at the depth, its inside or its boundary */
        double cx, cy, sd;
        rr_abs(ax, ay, prm[BX], prm[BY], prm[BR], &cx, &cy, &sd);
        const double pbx = sd <= 0.0 ? x : copysign(cx, x);
        const double pby = sd <= 0.0 ? y : copysign(cy, y);
        const double s_bot = prm[SLOPE] - (sd < 0.0 ? sd : 0.0);
        double ex = x - pbx, ey = y - pby, ez = z - -depth;
        const double d_bot = ex * ex + ey * ey + ez * ez;
        double bound = d_bot;
        /* the flange: from the opening's boundary out to its outer edge */
        double pfx = 0.0, pfy = 0.0, s_fl = 0.0, d_fl = INFINITY;
        if (fw > 0.0) {
            double cix, ciy, sdo;
            rr_abs(ax, ay, prm[OX], prm[OY], prm[ORC], &cix, &ciy, &sdo);
            pfx = sdo < 0.0 ? copysign(cix, x) : x;
            pfy = sdo < 0.0 ? copysign(ciy, y) : y;
            if (sdo > fw) {
                double cox, coy, sdf;
                rr_abs(ax, ay, prm[OXF], prm[OYF], prm[ORCF], &cox, &coy, &sdf);
                pfx = copysign(cox, x), pfy = copysign(coy, y);
            }
            double c = sdo > 0.0 ? sdo : 0.0;
            c = c < fw ? c : fw;
            s_fl = -c;
            ex = x - pfx, ey = y - pfy, ez = z - 0.0;
            d_fl = ex * ex + ey * ey + ez * ez;
            bound = bound < d_fl ? bound : d_fl;
        }
        const double bound_r = sqrt(bound);
        double best = INFINITY, best_r = INFINITY;
        int64_t win = -1;
        double fx = 0.0, fy = 0.0, fz = 0.0, nx = 0.0, ny = 0.0, nz = 0.0, al = 0.0, ss = 0.0;
        /* the walls: the exact closest point of each convex polygon, in its own frame */
        for (int64_t w = 0; w < nw; w++) {
            const double *q = walls + NWALL * w;
            const double yx = x - q[WO], yy = y - q[WO + 1], yz = z - q[WO + 2];
            const double h = yx * q[WN] + yy * q[WN + 1] + yz * q[WN + 2];
            /* sqrt(min(bound, best)), as numpy's: sqrt is monotone and correctly rounded */
            const double limr = bound_r < best_r ? bound_r : best_r;
            if (!(fabs(h) <= limr * (1 + 1e-9) + 2 * TIE)) continue;
            const double u = yx * q[WE1] + yy * q[WE1 + 1] + yz * q[WE1 + 2];
            const double v = yx * q[WE2] + yy * q[WE2 + 1] + yz * q[WE2 + 2];
            const double *V = uv + 2 * MAXV * w;
            const int64_t m = nv[w];
            /* inside the polygon (left of every edge): the projection itself; else the
             * nearest of its edges' closest points (the first of equals) */
            int inside = 1;
            for (int64_t i = 0; i < m && inside; i++) {
                const int64_t j = i + 1 < m ? i + 1 : 0;
                const double a0 = V[2 * i], a1 = V[2 * i + 1];
                const double eu = V[2 * j] - a0, ev = V[2 * j + 1] - a1;
                if (!((v - a1) * eu - (u - a0) * ev >= 0.0)) inside = 0;
            }
            double bu = u, bv = v;
            if (!inside) {
                double bd = INFINITY;
                for (int64_t i = 0; i < m; i++) {
                    const int64_t j = i + 1 < m ? i + 1 : 0;
                    const double a0 = V[2 * i], a1 = V[2 * i + 1];
                    const double eu = V[2 * j] - a0, ev = V[2 * j + 1] - a1;
                    const double du = u - a0, dv = v - a1;
                    double t = (du * eu + dv * ev) / (eu * eu + ev * ev);
                    t = t > 0.0 ? t : 0.0;
                    t = t < 1.0 ? t : 1.0;
                    const double cu = t * eu + a0, cv = t * ev + a1;
                    const double gu = u - cu, gv = v - cv;
                    const double d2 = gu * gu + gv * gv;
                    if (d2 < bd) bd = d2, bu = cu, bv = cv;
                }
            }
            const double px = bu * q[WE1] + q[WO] + bv * q[WE2];
            const double py = bu * q[WE1 + 1] + q[WO + 1] + bv * q[WE2 + 1];
            const double pz = bu * q[WE1 + 2] + q[WO + 2] + bv * q[WE2 + 2];
            ex = x - px, ey = y - py, ez = z - pz;
            const double d = ex * ex + ey * ey + ez * ez;
            if (!(d < best)) continue; /* (needed for the next, which implies it) */
            const double dr = sqrt(d);
            if (dr < best_r - TIE) {
                best = d, best_r = dr, win = 1, fx = px, fy = py, fz = pz;
                nx = q[WN], ny = q[WN + 1], nz = q[WN + 2], al = q[WA], ss = -pz / q[WSA];
            }
        }
        /* the corner cones (one wall angle): apex below each corner's centre */
        if (prm[HC] > 0.0) {
            for (int ix = 0; ix < 2; ix++) {
                const double sx = ix == 0 ? 1.0 : -1.0, ccx = ix == 0 ? prm[CXP] : prm[CXM];
                if (!((x - ccx) * sx >= 0.0)) continue;
                for (int iy = 0; iy < 2; iy++) {
                    const double sy = iy == 0 ? 1.0 : -1.0, ccy = iy == 0 ? prm[CYP] : prm[CYM];
                    if (!((y - ccy) * sy >= 0.0)) continue;
                    const double vx = x - ccx, vy = y - ccy;
                    const double r = hypot(vx, vy);
                    const double ux = r > 0.0 ? vx / r : sx * prm[ISQ2];
                    const double uy = r > 0.0 ? vy / r : sy * prm[ISQ2];
                    double t = ((r - prm[R0]) * prm[DR] + z * prm[DZ]) / prm[L2];
                    t = t > 0.0 ? t : 0.0;
                    t = t < 1.0 ? t : 1.0;
                    const double rp = prm[R0] + t * prm[DR];
                    const double px = ccx + rp * ux, py = ccy + rp * uy, pz = t * prm[DZ];
                    ex = x - px, ey = y - py, ez = z - pz;
                    const double d = ex * ex + ey * ey + ez * ez;
                    if (!(d < best)) continue;
                    const double dr = sqrt(d);
                    if (dr < best_r - TIE) {
                        best = d, best_r = dr, win = 1, fx = px, fy = py, fz = pz;
                        nx = prm[CA_MSIN] * ux, ny = prm[CA_MSIN] * uy, nz = prm[CA_COS];
                        al = prm[CA];
                        ss = -pz / prm[CA_SIN];
                    }
                }
            }
        }
        const double r_bot = sqrt(d_bot);
        if (r_bot < best_r - TIE) {
            best = d_bot, best_r = r_bot, win = 2, fx = pbx, fy = pby, fz = -depth;
            nx = 0.0, ny = 0.0, nz = 1.0, al = 0.0, ss = s_bot;
        }
        const double r_fl = sqrt(d_fl);
        if (fw > 0.0 && r_fl < best_r - TIE) {
            best = d_fl, best_r = r_fl, win = 0, fx = pfx, fy = pfy, fz = 0.0;
            nx = 0.0, ny = 0.0, nz = 1.0, al = 0.0, ss = s_fl;
        }
        if (win < 0) fx = fy = fz = nx = ny = nz = al = ss = 0.0;
        foot[3 * k] = fx, foot[3 * k + 1] = fy, foot[3 * k + 2] = fz;
        normal[3 * k] = nx, normal[3 * k + 1] = ny, normal[3 * k + 2] = nz;
        const double dd = best_r;
        ex = x - fx, ey = y - fy, ez = z - fz;
        dist[k] = ex * nx + ey * ny + ez * nz < 0.0 ? -dd : dd;
        alpha[k] = al, s[k] = ss, region[k] = win < 0 ? 0 : codes[win];
    }
}

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_pyramid_kernel_c",
    "C kernel of roboisf.parts.pyramid_kernel, called through ctypes (roboisf.jit.native).", -1,
    NULL};

PyMODINIT_FUNC PyInit__pyramid_kernel_c(void) { return PyModule_Create(&module); }
