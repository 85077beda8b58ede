/* plant_setup.c -- see plant_setup.h. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "estimate.h"
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


/* error_estimates.round_estimate: to 3 significant digits, as the Python FMU publishes it */
static double round3(double value)
{
    char text[40];
    snprintf(text, sizeof text, "%.3g", value);
    return strtod(text, NULL);
}

/* The level's error estimate (error_estimates.exact_estimate, polynomial_estimate) by the compiled core's
   core/estimate.c, the code the Python kernel path runs (one C implementation): its inputs are the ones
   error_estimates.kernel_polynomial_terms hands it, its constants rules.h's (error_estimates.kernel_constants), and
   it adds as Python 3.12's sum() does (RULE_ESTIMATE_COMPENSATED: error_estimates.NATIVE_COMPENSATED says why).
   NaN where the Python code would raise (the estimate cannot be made). */
double native_error_estimate(const State *s, int fidelity, double rtol, int fixed_step)
{
    static const double constants[PC_CONSTANTS] = RULE_ESTIMATE_CONSTANTS;
    const double alpha = s->value[VR_alpha], gamma = s->value[VR_gamma], R = s->value[VR_R];
    const double max_step = s->value[VR_max_step];
    /* the estimate's span: the experiment's, else error_estimates.DEFAULT_SPAN */
    const double stop_span = s->stop_time - s->start_time;
    const double span = s->has_stop && isfinite(stop_span) ? stop_span : RULE_DEFAULT_SPAN;
    double in[PE_INPUTS] = {0}, out[PO_OUTPUTS] = {0};
    in[PE_ALPHA] = alpha;
    in[PE_GAMMA] = gamma;
    in[PE_R] = R;
    in[PE_MU] = s->value[VR_mu];
    in[PE_DELTA] = s->value[VR_Delta];
    in[PE_OMEGA] = s->value[VR_omega];
    in[PE_BETA] = s->value[VR_beta];
    in[PE_BIG_OMEGA] = s->value[VR_Omega];
    in[PE_X_START] = s->value[VR_x_start];
    in[PE_V_START] = s->value[VR_v_start];
    in[PE_SPAN] = span;
    in[PE_RTOL] = rtol;
    in[PE_FIXED] = fixed_step ? 1.0 : 0.0;
    if (fixed_step) {
        in[PE_STEP] = max_step != 0.0 ? max_step : RULE_RK4_DEFAULT_STEP; /* settings.max_step or FIXED_DEFAULT_STEP */
        in[PE_FACTOR] = 1.0;
    } else { /* the drive's step ceiling and models.tolerance_factor(scene, span) */
        in[PE_CEILING] = max_step > 0.0 ? max_step : native_drive_ceiling(s, 0.0);
        const double mu = s->value[VR_mu];
        double memory = mu > 0.0 ? 2.0 / mu : INFINITY; /* models.error_memory(scene, span) */
        if (span > 0.0 && span < memory) memory = span;
        double factor = RULE_ERROR_MEMORY_REFERENCE / memory;
        if (factor < RULE_TOLERANCE_FACTOR_FLOOR) factor = RULE_TOLERANCE_FACTOR_FLOOR;
        if (factor > 1.0) factor = 1.0;
        in[PE_FACTOR] = factor;
    }
    in[PE_A1] = 1.0 - alpha * (8.0 / (3.0 * R)) - gamma * (4.0 / (3.0 * R)); /* forces.linear_stiffness */
    const int polynomial = VK_FIDELITIES[fidelity].model != VK_MODEL_EXACT;
    if (polynomial) { /* the level's polynomial model: a0..a5 and G3's coefficients (models.PolynomialModel) */
        VkModel poly;
        memset(&poly, 0, sizeof poly);
        native_plant_model(&poly, s, fidelity);
        for (int i = 0; i < 6; i++) {
            in[PE_POLY + i] = poly.poly[i];
            in[PE_G3 + i] = poly.g3[i];
        }
        if (vk_polynomial_estimate(in, constants, RULE_ESTIMATE_COMPENSATED, out)) return NAN;
        return round3(out[PO_SOLVER] + RULE_CALIBRATION_TRUNCATION * out[PO_TRUNCATION]);
    }
    if (vk_solver_estimate(in, constants, RULE_ESTIMATE_COMPENSATED, out)) return NAN;
    return round3(out[PO_SOLVER]);
}
