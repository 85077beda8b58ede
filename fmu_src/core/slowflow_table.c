/* slowflow_table.c -- see slowflow_table.h. */
#include <math.h>
#include <string.h>

#include "dop853.h"
#include "slowflow_eval.h"
#include "slowflow_table.h"

/* averaging.SlowFlow.rhs */
static int slow_rhs(void *context, double t, const double *z, double *f)
{
    (void)t;
    const double *flow = context;
    double A = z[0], B = z[1];
    double r = sqrt(A * A + B * B);  /* Python: (A * A + B * B) ** 0.5 (pow: within an ulp of it) */
    double r2 = r * r;
    double nu = flow[SF_DETUNING] - r2 * (flow[SF_KAPPA2] + flow[SF_KAPPA4] * r2);
    double half_mu = 0.5 * flow[SF_MU];
    f[0] = -half_mu * A - nu * B;
    f[1] = -half_mu * B + nu * A + flow[SF_DRIVE];
    return 0;
}

/* Z at t >= the last point read: the steps advanced until they cover t, then the dense output */
static int value(Dop853 *s, double *flow, double t, double *z, DopReport *report)
{
    if (t > s->t) {
        int code = dop_advance(s, slow_rhs, flow, t, report);
        if (code) return code;
    }
    return dop_value_at(s, slow_rhs, flow, t, z, report);
}

/* One grid of n cells: cells (when room), the largest midpoint error, max|Z| at the nodes, Z at t_start + span */
static int grid(double *flow, double t_start, const double *z0, double span, double rtol, double atol,
                double max_step, double spacing, int64_t n, double *cells, double *error, double *largest,
                double *z_end, double *steps, DopReport *report)
{
    Dop853 s;
    memset(&s, 0, sizeof s);
    s.n = 2;
    s.rtol = rtol;
    s.atol = atol;
    s.max_step = max_step;
    s.step_budget = INFINITY;
    int code = dop_restart(&s, slow_rhs, flow, t_start, z0, report);
    if (code) return code;
    double t_end = t_start + span, z[2], dz[2], z_prev[2] = {0.0, 0.0}, dz_prev[2] = {0.0, 0.0}, mid[2] = {0.0, 0.0};
    int end_read = 0;
    *error = 0.0;
    *largest = 0.0;
    for (int64_t k = 0; k <= n; k++) {
        double node = t_start + spacing * (double)k;
        if (k == n && t_end <= node) {
            if ((code = value(&s, flow, t_end, z_end, report))) return code;
            end_read = 1;
        }
        if ((code = value(&s, flow, node, z, report))) return code;
        slow_rhs(flow, node, z, dz);
        for (int i = 0; i < 2; i++) {
            dz[i] *= spacing;
            double size = fabs(z[i]);
            if (size > *largest || isnan(size)) *largest = size;
        }
        if (k > 0) {
            double *cell = cells + 8 * (k - 1);
            for (int i = 0; i < 2; i++) {
                double c0 = z_prev[i], c1 = dz_prev[i];
                double c2 = 3 * (z[i] - z_prev[i]) - 2 * dz_prev[i] - dz[i];
                double c3 = 2 * (z_prev[i] - z[i]) + dz_prev[i] + dz[i];
                if (cell) {
                    cell[4 * i] = c0;
                    cell[4 * i + 1] = c1;
                    cell[4 * i + 2] = c2;
                    cell[4 * i + 3] = c3;
                }
                double miss = fabs(c0 + 0.5 * c1 + 0.25 * c2 + 0.125 * c3 - mid[i]);
                if (miss > *error || isnan(miss)) *error = miss;
            }
        }
        if (k < n && (code = value(&s, flow, node + 0.5 * spacing, mid, report))) return code;
        z_prev[0] = z[0], z_prev[1] = z[1], dz_prev[0] = dz[0], dz_prev[1] = dz[1];
    }
    if (!end_read && (code = value(&s, flow, t_end, z_end, report))) return code;
    *steps = (double)s.n_steps;
    return DOP_OK;
}

int vk_slowflow_tabulate(const double *flow_in, double t_start, const double *z0, double span, double rtol,
                         double atol, double max_step, double spacing, int64_t n, int64_t max_refinements,
                         int64_t capacity, double *cells, double *out, char *message)
{
    double flow[SF_FLOW], z_end[2] = {0.0, 0.0}, error = 0.0, largest = 0.0, steps = 0.0, tolerance = 0.0;
    memcpy(flow, flow_in, sizeof flow);
    DopReport report;
    memset(&report, 0, sizeof report);
    int refine = !(spacing > 0.0);
    if (refine) n = (int64_t)ceil(span);
    for (int64_t round = 0; round < (refine ? max_refinements : 1); round++) {
        if (refine) spacing = span / (double)n;
        out[ST_CELLS] = (double)n;
        if (n > capacity) return ST_CAPACITY;
        int code = grid(flow, t_start, z0, span, rtol, atol, max_step, spacing, n, cells, &error, &largest, z_end,
                        &steps, &report);
        if (code) {
            memcpy(message, report.message, DOP_MESSAGE);
            message[DOP_MESSAGE - 1] = '\0';
            return ST_FAILED;
        }
        tolerance = rtol * largest + atol;
        if (!refine || error <= tolerance) break;
        if (round + 1 < max_refinements) n *= 2;
    }
    out[ST_SPACING] = spacing;
    out[ST_A_END] = z_end[0];
    out[ST_B_END] = z_end[1];
    out[ST_ERROR] = error;
    out[ST_TOLERANCE] = tolerance;
    out[ST_STEPS] = steps;
    return ST_OK;
}

/* error_estimates.exact_accel at one sample (U = 0), with cos(omega t), sin(Omega t), cos(2 Omega t) given */
static double exact_accel(const double *sc, double x, double v, double cos_wt, double sin_Wt, double cos_2Wt)
{
    double s = 1.0 + 2.0 * x / 3.0;
    double positive = s > 0.0 ? s : 0.0;
    double a = 1.0 - sc[SR_MU] * v - positive * sqrt(positive);
    if (sc[SR_DELTA] != 0.0) a = a + sc[SR_DELTA] * cos_wt;
    if (sc[SR_ALPHA] != 0.0 || sc[SR_BETA] != 0.0 || sc[SR_GAMMA] != 0.0) {
        double u = 2.0 * x / (3.0 * sc[SR_R]);
        double f3 = 1.0 / ((1.0 - u) * (1.0 - u));
        double force = sc[SR_ALPHA] * (f3 - 1.0 / ((1.0 + u) * (1.0 + u)));
        if (sc[SR_BETA] != 0.0 || sc[SR_GAMMA] != 0.0)
            force = force + (sc[SR_BETA] * sin_Wt + sc[SR_GAMMA] * (1.0 - cos_2Wt)) * f3;
        a = a + force;
    }
    return a;
}

int vk_slowflow_residual(const void *table, const double *sc, double t0, double span, int64_t n,
                         const double *filter, double *out)
{
    const SfTable *T = table;
    double dt = span / (double)(n - 1);
    double w = T->omega, W = sc[SR_BIG_OMEGA];
    double cw = 1.0, sw = 0.0, cW = 1.0, sW = 0.0;              /* cos, sin of w t and W t at the sample */
    double rc = cos(w * dt), rs = sin(w * dt), Rc = cos(W * dt), Rs = sin(W * dt);  /* one sample's rotation */
    double zr = 0.0, zi = 0.0, f_prev = 0.0, propagated = 0.0, residual = 0.0;
    double g = 1.0 / T->spacing, h = T->harmonic, m = T->mean_shift, p = filter[SR_P];
    double last = (double)(T->first + T->n_cells - 1);
    for (int64_t i = 0; i < n; i++) {
        double t = t0 + (i == n - 1 ? span : (double)i * dt);
        if (!(t <= T->t_end)) return 1;
        if (i % SR_RESYNC == 0 || i == n - 1) {
            cw = cos(w * t), sw = sin(w * t), cW = cos(W * t), sW = sin(W * t);
        } else {
            double c = cw * rc - sw * rs, s = sw * rc + cw * rs;
            cw = c, sw = s;
            c = cW * Rc - sW * Rs, s = sW * Rc + cW * Rs;
            cW = c, sW = s;
        }
        double u = (t - T->t0) * g;
        double fi = trunc(u) < last ? trunc(u) : last;
        int64_t k = (int64_t)fi;
        if (k < T->first) return 1;
        double sl = u - fi;
        const double *c8 = T->cells + 8 * (k - T->first);
        double A = c8[0] + sl * (c8[1] + sl * (c8[2] + sl * c8[3])), B = c8[4] + sl * (c8[5] + sl * (c8[6] + sl * c8[7]));
        double dA = g * (c8[1] + sl * (2 * c8[2] + 3 * sl * c8[3])), dB = g * (c8[5] + sl * (2 * c8[6] + 3 * sl * c8[7]));
        double ddA = g * g * (2 * c8[2] + 6 * sl * c8[3]), ddB = g * g * (2 * c8[6] + 6 * sl * c8[7]);
        /* slowflow_eval.c's reconstruct with the cosines and sines at hand */
        double pp = A * cw + B * sw, q = A * sw - B * cw;
        double dp = dA * cw + dB * sw - w * q, dq = dA * sw - dB * cw + w * pp;
        double ddp = ddA * cw + ddB * sw - 2 * w * (dA * sw - dB * cw) - w * w * pp;
        double ddq = ddA * sw - ddB * cw + 2 * w * (dA * cw + dB * sw) - w * w * q;
        double x = T->x_e + pp + h * (pp * pp - q * q) - m * (A * A + B * B);
        double v = dp + 2 * h * (pp * dp - q * dq) - 2 * m * (A * dA + B * dB);
        double a = ddp + 2 * h * (dp * dp + pp * ddp - dq * dq - q * ddq) - 2 * m * (dA * dA + A * ddA + dB * dB + B * ddB);
        double c2W = cW * cW - sW * sW;
        if (T->ac) {
            double P = T->psi_sin, Q = T->psi_cos;
            x += P * sW + Q * c2W;
            v += W * (P * cW - 2.0 * Q * (2.0 * sW * cW));
            a -= W * W * (P * sW + 4.0 * Q * c2W);
        }
        double f = exact_accel(sc, x, v, cw, sW, c2W) - a;
        if (fabs(f) > residual || isnan(f)) residual = fabs(f);
        if (i > 0) {  /* z = step z + f_prev phi1 + (f - f_prev) phi2 */
            double ur = f_prev * filter[SR_PHI1] + (f - f_prev) * filter[SR_PHI2];
            double ui = f_prev * filter[SR_PHI1 + 1] + (f - f_prev) * filter[SR_PHI2 + 1];
            double nr = filter[SR_STEP] * zr - filter[SR_STEP + 1] * zi + ur;
            double ni = filter[SR_STEP] * zi + filter[SR_STEP + 1] * zr + ui;
            zr = nr, zi = ni;
            double e = fabs(zi / p);
            if (e > propagated || isnan(e)) propagated = e;
        }
        f_prev = f;
    }
    out[SR_PROPAGATED] = propagated;
    out[SR_RESIDUAL] = residual;
    return 0;
}
