/* plant_setup.c -- see plant_setup.h. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fidelity.h"
#include "plant_setup.h"
#include "rules.h"
#include "series.h"

double native_drive_ceiling(const State *s, double extra)
{
    const double omega = s->value[VR_omega], Omega = s->value[VR_Omega];
    double fastest = s->value[VR_Delta] != 0.0 ? omega : 0.0;  /* Python's max, left to right: the same double */
    const double candidates[3] = {s->value[VR_beta] != 0.0 ? Omega : 0.0, s->value[VR_gamma] != 0.0 ? 2.0 * Omega : 0.0,
                                  extra};
    for (int i = 0; i < 3; i++)
        if (candidates[i] > fastest) fastest = candidates[i];
    return fastest > 0.0 ? NATIVE_DRIVE_STEP_TURN / fastest : INFINITY;
}

double native_error_memory(const State *s)
{
    const double mu = s->value[VR_mu], span = s->stop_time - s->start_time;
    double memory = mu > 0.0 ? 2.0 / mu : INFINITY;
    if (s->has_stop && span > 0.0 && span < memory) memory = span;
    return memory;
}

double native_tolerance_factor(const State *s)
{
    double factor = RULE_ERROR_MEMORY_REFERENCE / native_error_memory(s);
    if (factor < RULE_TOLERANCE_FACTOR_FLOOR) factor = RULE_TOLERANCE_FACTOR_FLOOR;
    if (factor > 1.0) factor = 1.0;
    return factor;
}

int native_step_outputs_finite(Instance *inst, const double *out, const fmi2ValueReference *vrs, int n, double t)
{
    for (int i = 0; i < n; i++)
        if (!isfinite(out[i])) {
            native_error(inst, "simulation stopped: output with valueReference %u is %g (not finite) after the step "
                         "from tau = %.17g; the parameters are beyond the model's numerical range", (unsigned)vrs[i],
                         out[i], t);
            return 0;
        }
    return 1;
}

void native_plant_model(VkModel *m, const State *s, int fidelity)
{
#define COPY_PARAMETER(name) m->name = s->value[VR_##name]; /* models.scene_fields: the scene's own values */
    SCENE_MODEL_FIELDS(COPY_PARAMETER)
#undef COPY_PARAMETER
    const double Delta = m->Delta, alpha = m->alpha, beta = m->beta, gamma = m->gamma, R = m->R;
    m->pull_in_c = 2.0 / (3.0 * R); /* models.pull_in_slope */
    m->pull_in_gap = RULE_PULL_IN_GAP;
    m->load_forcing = Delta != 0.0;
    m->ac = beta != 0.0 || gamma != 0.0;
    const int model = VK_FIDELITIES[fidelity].model; /* the registry's compiled model of the level (fidelity.h) */
    if (model == VK_MODEL_EXACT) {
        m->polynomial = 0;
        m->electrostatics = alpha != 0.0 || m->ac;
    } else { /* (models.PolynomialModel's "R out of range" cannot happen: the rules keep R in [1e-6, 1e6]) */
        m->polynomial = 1;
        m->electrostatics = m->ac;
        vibro_series(model == VK_MODEL_POLYNOMIAL_PRINTED, alpha, gamma, R, m->poly, m->g1, m->g2, m->g3);
    }
}

/* plant.rk4_drive_warnings: the forcing terms RK4 steps of max_step do not resolve, logged as fmi2Warning; the gain
   G_x is the solver's own (core/rk4.c vk_rk4_drive_gain_x), the limits RULE_RK4_DRIVE_* generated from integrate.py. */
void native_drive_warnings(Instance *inst, const State *s, const VkSolverOps *solver, double max_step)
{
    if (solver->drive_gain_x == NULL) return;
    const double Omega = s->value[VR_Omega], omega = s->value[VR_omega];
    typedef struct { const char *what, *name; double value, nu; const char *term; } Drive;
    Drive drives[2];
    int n = 0;
    if (s->value[VR_gamma] != 0.0) {
        Drive d = {"AC drive", "Omega", Omega, 2.0 * Omega, "gamma cos(2 Omega tau)"};
        drives[n++] = d;
    } else if (s->value[VR_beta] != 0.0) {
        Drive d = {"AC drive", "Omega", Omega, Omega, "beta sin(Omega tau)"};
        drives[n++] = d;
    }
    if (s->value[VR_Delta] != 0.0) {
        Drive d = {"load forcing", "omega", omega, omega, "Delta cos(omega tau)"};
        drives[n++] = d;
    }
    for (int i = 0; i < n; i++) {
        const double theta = drives[i].nu * max_step;
        if (theta <= RULE_RK4_DRIVE_THETA * (1.0 + 1e-12)) continue;
        const double error = fabs(solver->drive_gain_x(theta) - 1.0);
        char wrong[96];
        if (error <= 10.0) snprintf(wrong, sizeof wrong, "by %.0f%%", 100.0 * error);
        else snprintf(wrong, sizeof wrong, "by more than 1000%% (near 2 pi k rad per step, a resonance)");
        native_log(inst, fmi2Warning, "RK4 max_step = %g does not resolve the %s at %s = %g: its term %s turns by "
                   "%.3g rad per step (more than %.3g, i.e. fewer than %.2g steps per period), so RK4 gets the ripple "
                   "it drives in x wrong %s; the largest step that resolves it (ripple within %.0f%%) is max_step = "
                   "%.3g", max_step, drives[i].what, drives[i].name, drives[i].value, drives[i].term, theta,
                   RULE_RK4_DRIVE_THETA, 2.0 * 3.141592653589793 /* math.pi */ / RULE_RK4_DRIVE_THETA, wrong, 100.0 * RULE_RK4_DRIVE_ERROR,
                   RULE_RK4_DRIVE_THETA / drives[i].nu);
    }
}


/* error_estimates.linear_gain: H(s) = 1/(k1 - s^2 + i mu s), by CPython's complex division (_Py_c_quot) so that
   the digits are Python's */
static void gain(double k1, double mu, double s, double *re, double *im)
{
    const double br = k1 - s * s, bi = mu * s;
    if (fabs(br) >= fabs(bi)) {
        if (br == 0.0) { *re = *im = NAN; return; } /* Python: ZeroDivisionError, the estimate NaN */
        const double ratio = bi / br, denom = br + bi * ratio;
        *re = 1.0 / denom;
        *im = -ratio / denom;
    } else {
        const double ratio = br / bi, denom = br * ratio + bi;
        *re = ratio / denom;
        *im = -1.0 / denom;
    }
}

static double gain_modulus(double k1, double mu, double s)
{
    double re, im;
    gain(k1, mu, s, &re, &im);
    return hypot(re, im);
}

/* error_estimates.round_estimate: to 3 significant digits, as the Python FMU publishes it */
static double round3(double value)
{
    char text[40];
    snprintf(text, sizeof text, "%.3g", value);
    return strtod(text, NULL);
}

/* error_estimates.response_parts */
typedef struct {
    double x_s, a1, p, mu, mu_eff, memory, free;
    int n_forced;
    double forced[3][2]; /* (amplitude, frequency) */
} Parts;

static double min_first(double a, double b) { return b < a ? b : a; } /* Python's min(a, b) */

static void response_parts(const State *s, double span, Parts *r)
{
    const double mu = s->value[VR_mu], alpha = s->value[VR_alpha], gamma = s->value[VR_gamma], R = s->value[VR_R];
    const double Omega = s->value[VR_Omega];
    r->a1 = 1.0 - 8.0 * alpha / (3.0 * R) - 4.0 * gamma / (3.0 * R);
    r->mu = mu;
    r->memory = mu <= 0.0 ? span : min_first(span, 2.0 / mu); /* _memory */
    r->mu_eff = 2.0 / r->memory;
    const double pp = r->a1 - 0.25 * mu * mu;
    r->p = sqrt(pp > 1e-300 ? pp : 1e-300);
    r->x_s = gamma / r->a1;
    double dx = s->value[VR_x_start] - r->x_s, dv = s->value[VR_v_start];
    const double drives[3][3] = {{s->value[VR_Delta], 0.0, s->value[VR_omega]}, {0.0, -s->value[VR_beta], Omega},
                                 {-gamma, 0.0, 2.0 * Omega}};
    r->n_forced = 0;
    for (int i = 0; i < 3; i++) {
        double hr, hi;
        gain(r->a1, r->mu_eff, drives[i][2], &hr, &hi);
        const double zr = drives[i][0] * hr - drives[i][1] * hi, zi = drives[i][0] * hi + drives[i][1] * hr;
        if (zr != 0.0 || zi != 0.0) {
            r->forced[r->n_forced][0] = hypot(zr, zi);
            r->forced[r->n_forced][1] = drives[i][2];
            r->n_forced++;
            dx -= zr;
            dv += drives[i][2] * zi;
        }
    }
    r->free = hypot(dx, (dv + 0.5 * mu * dx) / r->p);
}

/* error_estimates._remembered */
static double remembered(double sv, const Parts *r)
{
    const double distance = hypot(sv - r->p, 0.5 * r->mu);
    return distance * r->memory <= 1.0 ? r->memory : 1.0 / distance;
}

/* error_estimates.force_error_harmonics: (mean, stiffness, rest) of the polynomial's force error */
static int force_error_harmonics(const VkModel *exact, const VkModel *poly, const State *s, double x_s, double amplitude,
                                 double out[3])
{
    enum { N = RULE_TRUNCATION_ANGLES };
    const double lo = -1.5 + 1e-9, hi = 1.5 * s->value[VR_R] * (1.0 - 1e-3), Omega = s->value[VR_Omega];
    double cosines[N], xs[N];
    for (int i = 0; i < N; i++) {
        cosines[i] = cos(2.0 * 3.141592653589793 * (i + 0.5) / N);
        double x = x_s + amplitude * cosines[i];
        if (lo > x) x = lo;
        if (hi < x) x = hi;
        xs[i] = x;
    }
    const int ac = (s->value[VR_beta] != 0.0 || s->value[VR_gamma] != 0.0) && Omega > 0.0;
    const int n_times = ac ? RULE_TRUNCATION_TIMES : 1;
    double mean = 0.0, stiffness = 0.0, rest = 0.0;
    for (int j = 0; j < n_times; j++) {
        const double t = ac ? 3.141592653589793 / Omega * j / RULE_TRUNCATION_TIMES : 0.0;
        double d[N], m = 0.0, first = 0.0;
        for (int i = 0; i < N; i++) {
            int f1 = 0, f2 = 0;
            d[i] = vm_accel(exact, t, xs[i], 0.0, 0.0, &f1) - vm_accel(poly, t, xs[i], 0.0, 0.0, &f2);
            if (f1 || f2) return 0;
            m += d[i];
            first += d[i] * cosines[i];
        }
        m /= N;
        const double k = amplitude > 0.0 ? 2.0 * first / N / amplitude : 0.0;
        if (fabs(m) > mean) mean = fabs(m);
        if (fabs(k) > stiffness) stiffness = fabs(k);
        for (int i = 0; i < N; i++) {
            const double r = fabs(d[i] - m - k * amplitude * cosines[i]);
            if (r > rest) rest = r;
        }
    }
    out[0] = mean;
    out[1] = stiffness;
    out[2] = rest;
    return 1;
}

double native_error_estimate(const State *s, int fidelity, double rtol, int fixed_step)
{
    const double mu = s->value[VR_mu];
    /* the estimate's span: the experiment's, else error_estimates.DEFAULT_SPAN */
    const double stop_span = s->stop_time - s->start_time;
    const double span = s->has_stop && isfinite(stop_span) ? stop_span : 1000.0;
    Parts r;
    response_parts(s, span, &r);
    /* _components */
    double comps[4][2];
    double forced_sum = 0.0;
    for (int i = 0; i < r.n_forced; i++) forced_sum += r.forced[i][0];
    comps[0][0] = r.free + forced_sum;
    comps[0][1] = r.p;
    for (int i = 0; i < r.n_forced; i++) { comps[i + 1][0] = r.forced[i][0]; comps[i + 1][1] = r.forced[i][1]; }
    const int n = r.n_forced + 1;
    double total = 0.0;
    for (int i = 0; i < n; i++) total += comps[i][0];
    const double size = fabs(r.x_s) + total;
    double estimate;
    if (!fixed_step) { /* solver_terms, adaptive: the solver's rtol at this span (models.solver_tolerance) */
        double remembered_span = mu > 0.0 ? 2.0 / mu : INFINITY;
        if (span > 0.0 && span < remembered_span) remembered_span = span;
        double factor = RULE_ERROR_MEMORY_REFERENCE / remembered_span;
        if (factor < RULE_TOLERANCE_FACTOR_FLOOR) factor = RULE_TOLERANCE_FACTOR_FLOOR;
        if (factor > 1.0) factor = 1.0;
        double solver_rtol = factor == 1.0 ? rtol : rtol * factor;
        if (factor != 1.0 && solver_rtol < RULE_MIN_RTOL) solver_rtol = RULE_MIN_RTOL;
        const double scale_x = 0.01 + size;
        double velocity = 0.0;
        for (int i = 0; i < n; i++) velocity += comps[i][0] * comps[i][1];
        const double scale_v = 0.01 + velocity;
        double h = s->value[VR_max_step] > 0.0 ? s->value[VR_max_step] : native_drive_ceiling(s, 0.0);
        for (int i = 0; i < n; i++) {
            const double a = comps[i][0], sv = comps[i][1];
            if (a > 0.0 && sv > 0.0) {
                const double weight = a * hypot(1.0 / scale_x, sv / scale_v) / sqrt(2.0);
                h = min_first(h, pow(solver_rtol / (RULE_DOP853_ESTIMATOR * weight), 0.125) / sv);
            }
        }
        double accumulated = 0.0, local = 0.0;
        for (int i = 0; i < n; i++) {
            const double a = comps[i][0], sv = comps[i][1];
            accumulated += a * min_first(2.0, RULE_DOP853_LOCAL * pow(sv * h, 9.0) / h * remembered(sv, &r));
            local += a * RULE_DOP853_ESTIMATOR * pow(sv * h, 8.0);
        }
        estimate = RULE_CALIBRATION_ADAPTIVE * accumulated + RULE_CALIBRATION_LOCAL * local;
    } else { /* solver_terms, fixed step: RK4's error of each part over the time it is remembered */
        const double h = s->value[VR_max_step] != 0.0 ? s->value[VR_max_step] : RULE_RK4_DEFAULT_STEP;
        double accumulated = 0.0;
        for (int i = 0; i < n; i++) {
            const double a = comps[i][0], sv = comps[i][1];
            accumulated += a * min_first(2.0, pow(sv, 5.0) * pow(h, 4.0) / 120.0 * remembered(sv, &r));
        }
        estimate = RULE_CALIBRATION_FIXED * accumulated;
    }
    if (VK_FIDELITIES[fidelity].model != VK_MODEL_EXACT) { /* truncation_terms: the polynomial's force error */
        VkModel exact, poly;
        memset(&exact, 0, sizeof exact);
        memset(&poly, 0, sizeof poly);
        native_plant_model(&exact, s, VK_FID_EXACT);
        native_plant_model(&poly, s, fidelity);
        const double amplitude = forced_sum + r.free;
        double h3[3], smaller[3];
        if (!force_error_harmonics(&exact, &poly, s, r.x_s, amplitude, h3)) return NAN;
        double memory = r.memory;
        if (r.free > 0.0 && mu > 0.0 && h3[1] > 0.0) {
            const double half = forced_sum + 0.5 * r.free;
            if (!force_error_harmonics(&exact, &poly, s, r.x_s, half, smaller)) return NAN;
            const double k = smaller[1] > 0.0 ? log(h3[1] / smaller[1]) / log(amplitude / half) : 0.0;
            memory = min_first(memory, 2.0 / ((1.0 > k ? 1.0 : k) * mu));
        }
        double drift = r.free * min_first(2.0, h3[1] / (2.0 * r.p) * memory);
        for (int i = 0; i < r.n_forced; i++)
            drift += r.forced[i][0] * min_first(2.0, h3[1] * gain_modulus(r.a1, r.mu_eff, r.forced[i][1]));
        estimate += RULE_CALIBRATION_TRUNCATION * (h3[0] / r.a1 + drift + h3[2] / (3.0 * r.a1));
    }
    return round3(estimate);
}
