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

void native_plant_model(VkModel *m, const State *s, int fidelity)
{
    const double Delta = s->value[VR_Delta], alpha = s->value[VR_alpha], beta = s->value[VR_beta],
                 gamma = s->value[VR_gamma], R = s->value[VR_R];
    m->mu = s->value[VR_mu]; m->Delta = Delta; m->omega = s->value[VR_omega]; m->alpha = alpha; m->beta = beta;
    m->gamma = gamma; m->Omega = s->value[VR_Omega]; m->R = R;
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


/* |H(s)| = 1/|k1 - s^2 + i mu s| (error_estimates.linear_gain) */
static double gain(double k1, double mu, double s) { return 1.0 / hypot(k1 - s * s, mu * s); }

/* error_estimates.round_estimate: to 3 significant digits, as the Python FMU publishes it */
static double round3(double value)
{
    char text[40];
    snprintf(text, sizeof text, "%.3g", value);
    return strtod(text, NULL);
}

double native_error_estimate(const State *s, int fidelity, double rtol, int fixed_step)
{
    const double mu = s->value[VR_mu], Delta = s->value[VR_Delta], omega = s->value[VR_omega],
                 Omega = s->value[VR_Omega], alpha = s->value[VR_alpha], beta = s->value[VR_beta],
                 gamma = s->value[VR_gamma], R = s->value[VR_R];
    /* linear_amplitude */
    const double a1 = 1.0 - 8.0 * alpha / (3.0 * R) - 4.0 * gamma / (3.0 * R);
    double pp = a1 - 0.25 * mu * mu;
    const double p = sqrt(pp > 1e-300 ? pp : 1e-300);
    const double x_s = gamma / a1;
    const double free_part = fabs(s->value[VR_x_start] - x_s) + fabs(s->value[VR_v_start]) / p;
    const double forced = fabs(Delta) * gain(a1, mu, omega) + fabs(beta) * gain(a1, mu, Omega)
                          + fabs(gamma) * gain(a1, mu, 2.0 * Omega);
    const double amplitude = free_part + 2.0 * forced;
    /* the estimate's span: the experiment's, else error_estimates.DEFAULT_SPAN */
    const double stop_span = s->stop_time - s->start_time;
    const double span = s->has_stop && isfinite(stop_span) ? stop_span : 1000.0;
    const double memory = mu <= 0.0 ? span : (span < 2.0 / mu ? span : 2.0 / mu);
    double estimate;
    if (!fixed_step) { /* solver_terms, adaptive: the solver's rtol at this span (models.solver_tolerance) */
        double remembered = mu > 0.0 ? 2.0 / mu : INFINITY;
        if (span > 0.0 && span < remembered) remembered = span;
        double factor = RULE_ERROR_MEMORY_REFERENCE / remembered;
        if (factor < RULE_TOLERANCE_FACTOR_FLOOR) factor = RULE_TOLERANCE_FACTOR_FLOOR;
        if (factor > 1.0) factor = 1.0;
        double solver_rtol = rtol * factor;
        if (solver_rtol < RULE_MIN_RTOL) solver_rtol = RULE_MIN_RTOL;
        estimate = solver_rtol * (fabs(x_s) + amplitude) * (1.0 + memory * p / (2.0 * 3.141592653589793));
    } else { /* solver_terms, fixed step: RK4's phase error of each part of the response over the memory */
        const double h = s->value[VR_max_step] != 0.0 ? s->value[VR_max_step] : RULE_RK4_DEFAULT_STEP;
        const double parts[3][2] = {{amplitude, p},
                                    {fabs(beta) * gain(a1, mu, Omega) + fabs(beta) / (Omega * Omega), Omega},
                                    {fabs(gamma) / (4.0 * Omega * Omega), 2.0 * Omega}};
        estimate = 0.0;
        for (int i = 0; i < 3; i++) {
            if (parts[i][0] == 0.0) continue;
            const double sv = parts[i][1], drift = pow(sv, 5) * pow(h, 4) / 120.0 * memory;
            estimate += parts[i][0] * (drift < 2.0 ? drift : 2.0);
        }
    }
    if (VK_FIDELITIES[fidelity].model != VK_MODEL_EXACT) { /* truncation_terms: the polynomial's force error */
        VkModel exact, poly;
        memset(&exact, 0, sizeof exact);
        memset(&poly, 0, sizeof poly);
        native_plant_model(&exact, s, VK_FID_EXACT);
        native_plant_model(&poly, s, fidelity);
        double lo = x_s - amplitude, hi = x_s + amplitude;
        if (lo < -1.5 + 1e-9) lo = -1.5 + 1e-9;
        if (hi > 1.5 * R * (1.0 - 1e-3)) hi = 1.5 * R * (1.0 - 1e-3);
        const int nx = hi > lo ? 41 : 1;
        const double period = Omega > 0.0 ? 2.0 * 3.141592653589793 / (2.0 * Omega) : 1.0;
        double difference = 0.0;
        for (int i = 0; i < 9; i++) {
            const double t = 2.0 * period * i / 8.0;
            for (int j = 0; j < nx; j++) {
                const double x = nx == 1 ? x_s : lo + (hi - lo) * j / 40.0;
                int f1 = 0, f2 = 0;
                const double d = fabs(vm_accel(&exact, t, x, 0.0, 0.0, &f1) - vm_accel(&poly, t, x, 0.0, 0.0, &f2));
                if (!f1 && !f2 && d > difference) difference = d;
            }
        }
        estimate += difference / a1;
    }
    return round3(estimate);
}
