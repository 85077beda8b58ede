/*
 * controller.c -- the adaptive Lyapunov controller of controller.h: control.py's Controller and
 * HeldInputEstimator, operation for operation (each function names its Python twin).
 */
#include "controller.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

enum { DELTA = 6 };  /* index of Delta in theta (control.DELTA) */

/* forces.horner: sum c_k x^k from the highest power down */
static inline double horner6(const double *c, double x)
{
    double value = 0.0;
    for (int k = 5; k >= 0; k--) value = value * x + c[k];
    return value;
}

/* control._dot: sum a_i b_i left to right from 0 */
static inline double dot(const double *a, const double *b)
{
    double total = 0.0;
    for (int i = 0; i < VC_N; i++) total += a[i] * b[i];
    return total;
}

/* math.cos / math.sin: ValueError for an infinite argument */
static inline int trig(int sine, double x, double *value)
{
    if (isinf(x)) return VC_RAISED;
    *value = sine ? sin(x) : cos(x);
    return VC_OK;
}

/* control._trig_integral: int_t^(t+h) trig(nu s) ds = h trig(nu (t + h/2)) sinc(nu h/2) */
static int trig_integral(int sine, double nu, double t, double h, double *value)
{
    double y = 0.5 * nu * h, s, sy;
    double sinc = 1.0;
    if (y != 0.0) {
        if (trig(1, y, &sy)) return VC_RAISED;
        sinc = sy / y;
    }
    if (trig(sine, nu * (t + 0.5 * h), &s)) return VC_RAISED;
    *value = h * s * sinc;
    return VC_OK;
}

/* Regressor.__call__; time != NULL: its time functions cos(w_delta t), sin(w_beta t), cos(w_gamma t) too;
   cos_delta != NULL: cos(w_delta t) as the caller computed it (math.cos's value, from the same angle) */
static inline __attribute__((always_inline)) int regressor(const VcController *c, const VcRegressor *r, double t,
                                                           double x1, double x2, double *phi, double *time,
                                                           const double *cos_delta)
{
    double G3 = horner6(c->g3, x1), x1_2 = x1 * x1, cd, sb, cg;
    if (cos_delta != NULL) {
        if (isinf(r->w_delta * t)) return VC_RAISED;  /* math.cos's ValueError */
        cd = *cos_delta;
    } else if (trig(0, r->w_delta * t, &cd)) {
        return VC_RAISED;
    }
    if (trig(1, r->w_beta * t, &sb) || trig(0, r->w_gamma * t, &cg)) return VC_RAISED;
    if (time != NULL) {
        time[0] = cd;
        time[1] = sb;
        time[2] = cg;
    }
    phi[0] = -x2;
    phi[1] = -x1;
    phi[2] = -x1_2;
    phi[3] = -x1_2 * x1;
    phi[4] = -x1_2 * x1_2;
    phi[5] = -x1_2 * x1_2 * x1;
    phi[6] = r->delta_sign * cd;
    phi[7] = G3 * sb;
    phi[8] = 1.0 - G3 * cg;
    return VC_OK;
}

/* Regressor.integral: int_t^(t+h) phi(x1, x2, s) ds with x1, x2 held */
static int regressor_integral(const VcController *c, const VcRegressor *r, double t, double h, double x1, double x2,
                              double *out)
{
    double G3 = horner6(c->g3, x1), x1_2 = x1 * x1, id, ib, ig;
    if (trig_integral(0, r->w_delta, t, h, &id) || trig_integral(1, r->w_beta, t, h, &ib)
        || trig_integral(0, r->w_gamma, t, h, &ig))
        return VC_RAISED;
    out[0] = -x2 * h;
    out[1] = -x1 * h;
    out[2] = -x1_2 * h;
    out[3] = -x1_2 * x1 * h;
    out[4] = -x1_2 * x1_2 * h;
    out[5] = -x1_2 * x1_2 * x1 * h;
    out[6] = r->delta_sign * id;
    out[7] = G3 * ib;
    out[8] = h - G3 * ig;
    return VC_OK;
}

/* Controller.errors (Eq. 74) */
void vk_controller_errors(const VcController *c, double x, double v, const double *ref, double *e1, double *e2)
{
    *e1 = x - ref[0];
    *e2 = v - ref[1] + c->c * *e1;
}

/* Controller.control from the regressor phi and e2 */
static inline __attribute__((always_inline)) double control(const VcController *c, const double *phi, double e2,
                                                            const double *ref, const double *theta_hat)
{
    double th[VC_N];
    const double *estimates = theta_hat;
    if (c->law == 2) {  /* a copy only where one estimate is replaced */
        memcpy(th, theta_hat, sizeof th);
        th[DELTA] = c->true_delta;
        estimates = th;
    }
    double u = -dot(phi, estimates) + ref[2] - c->c * e2;
    if (c->law == 1) u -= c->k_damping * e2;
    return u;
}

/* Controller.control: U = -phi^T theta^ + x~'' - c e2 (- k e2 damped; true Delta in theta^ paper-literal) */
int vk_controller_control(const VcController *c, double t, double x, double v, const double *ref, const double *theta_hat,
               double *U)
{
    double e1, e2, phi[VC_N];
    vk_controller_errors(c, x, v, ref, &e1, &e2);
    if (regressor(c, &c->phi, t, x, v, phi, NULL, NULL)) return VC_RAISED;
    *U = control(c, phi, e2, ref, theta_hat);
    return VC_OK;
}

/* vk_controller_control and vk_controller_rates together: the same values, with the regressor evaluated once where both laws use the
   same one (all but paper-literal) */
int vk_controller_control_rates(const VcController *c, double t, double x, double v, const double *ref, const double *theta_hat,
                     double *U, double *rates, double *time, const double *cos_delta)
{
    double e1, e2, phi[VC_N], phi_update[VC_N];
    vk_controller_errors(c, x, v, ref, &e1, &e2);
    if (regressor(c, &c->phi, t, x, v, phi, time, cos_delta)) return VC_RAISED;
    *U = control(c, phi, e2, ref, theta_hat);
    const double *update = phi;
    if (c->law == 2) {
        if (regressor(c, &c->phi_update, t, x, v, phi_update, NULL, NULL)) return VC_RAISED;
        update = phi_update;
    }
    for (int i = 0; i < VC_N; i++) rates[i] = c->adaptation[i] * update[i] * e2;
    return VC_OK;
}

/* Controller.rates: theta^' = lambda2 Lambda^-1 phi e2 */
int vk_controller_rates(const VcController *c, double t, double x, double v, const double *ref, double *rates)
{
    double e1, e2, phi[VC_N];
    vk_controller_errors(c, x, v, ref, &e1, &e2);
    if (regressor(c, &c->phi_update, t, x, v, phi, NULL, NULL)) return VC_RAISED;
    for (int i = 0; i < VC_N; i++) rates[i] = c->adaptation[i] * phi[i] * e2;
    return VC_OK;
}

/* Controller.increment */
int vk_controller_increment(const VcController *c, double t, double h, double x, double v, const double *ref, double *inc)
{
    double e1, e2, integral[VC_N];
    vk_controller_errors(c, x, v, ref, &e1, &e2);
    if (regressor_integral(c, &c->phi_update, t, h, x, v, integral)) return VC_RAISED;
    for (int i = 0; i < VC_N; i++) inc[i] = c->adaptation[i] * integral[i] * e2;
    return VC_OK;
}

/* Controller.lyapunov (Eq. 76) */
double vk_controller_lyapunov(const VcController *c, double e1, double e2, const double *theta_hat)
{
    double square[VC_N];
    for (int i = 0; i < VC_N; i++) {
        double tilde = theta_hat[i] - c->theta[i];
        square[i] = tilde * tilde;
    }
    return 0.5 * (c->l1 * e1 * e1 + c->l2 * e2 * e2 + dot(c->Lambda, square));
}

/* Controller.lyapunov_rate: chain rule, e1' = x2 - x~', e2' = x2' - x~'' + c e1' */
double vk_controller_lyapunov_rate(const VcController *c, double x, double v, double accel, const double *ref,
                        const double *theta_hat, const double *theta_hat_rate)
{
    double e1, e2, product[VC_N];
    vk_controller_errors(c, x, v, ref, &e1, &e2);
    double de1 = v - ref[1];
    double de2 = accel - ref[2] + c->c * de1;
    for (int i = 0; i < VC_N; i++) product[i] = (theta_hat[i] - c->theta[i]) * theta_hat_rate[i];
    return c->l1 * e1 * de1 + c->l2 * e2 * de2 + dot(c->Lambda, product);
}

/* Controller.promised_rate: Eq. 85, or -lambda1 c e1^2 - lambda2 k e2^2 (damped) */
double vk_controller_promised_rate(const VcController *c, double e1, double e2)
{
    if (c->law == 1) return -c->l1 * c->c * e1 * e1 - c->l2 * c->k_damping * e2 * e2;
    return c->promised_e1 * e1 * e1;
}

/* AdaptiveLyapunovController._publish at time t with estimates theta_hat, into out[] (all computed first) */
int vk_controller_outputs(const VcController *c, double t, const double *theta_hat, double *out)
{
    const double *ref = c->in + 2;
    double e1, e2;
    vk_controller_errors(c, c->in[0], c->in[1], ref, &e1, &e2);
    if (vk_controller_control(c, t, c->in[0], c->in[1], ref, theta_hat, &out[0])) return VC_RAISED;
    out[1] = e1;
    out[2] = e2;
    out[3] = vk_controller_lyapunov(c, e1, e2, theta_hat);
    memcpy(out + 4, theta_hat, VC_N * sizeof(double));
    return VC_OK;
}

/* StatusSlave._set_finite: the first non-finite output's index, or -1 */
int vk_controller_non_finite(const double *out)
{
    for (int i = 0; i < VC_OUTPUTS; i++)
        if (!isfinite(out[i])) return i;
    return -1;
}

int vk_controller_publish(VcController *c)
{
    double out[VC_OUTPUTS];
    if (vk_controller_outputs(c, c->t, c->theta_hat, out)) return VC_RAISED;
    if (vk_controller_non_finite(out) >= 0) return VC_NON_FINITE;
    memcpy(c->out, out, sizeof c->out);
    return VC_OK;
}

int vk_controller_advance(VcController *c, double t, double h, double x, double v, const double *ref)
{
    double inc[VC_N];
    if (vk_controller_increment(c, t, h, x, v, ref, inc)) return VC_RAISED;
    for (int i = 0; i < VC_N; i++) c->theta_hat[i] = c->theta_hat[i] + inc[i];
    c->t = t + h;
    return VC_OK;
}

/* AdaptiveLyapunovController._step: pre-checks, HeldInputEstimator.advance, _publish; nothing changes unless
   all of it succeeds (a failure is then reported by the Python path, which raises as Python does). */
int vk_controller_do_step(VcController *c, double t, double h)
{
    if (!(isfinite(h) && h > 0.0)) return VC_BAD_STEP;
    if (!(isfinite(t) && fabs(t - c->t) <= c->time_tolerance * fmax(1.0, fabs(t)))) return VC_BAD_TIME;
    for (int i = 0; i < VC_INPUTS; i++)
        if (!isfinite(c->in[i])) return VC_BAD_INPUT;
    double inc[VC_N], theta_hat[VC_N], out[VC_OUTPUTS];
    if (vk_controller_increment(c, t, h, c->in[0], c->in[1], c->in + 2, inc)) return VC_RAISED;
    for (int i = 0; i < VC_N; i++) theta_hat[i] = c->theta_hat[i] + inc[i];
    if (vk_controller_outputs(c, t + h, theta_hat, out)) return VC_RAISED;
    if (vk_controller_non_finite(out) >= 0) return VC_NON_FINITE;
    memcpy(c->theta_hat, theta_hat, sizeof theta_hat);
    c->t = t + h;
    memcpy(c->out, out, sizeof c->out);
    return VC_OK;
}

void vk_controller_constants(VcController *c, double mu, double Delta, double omega, double Omega, double beta, double gamma,
                  const double *poly, const double *g3, int64_t law, const double *lambdas, double k_damping,
                  double time_tolerance)
{
    memcpy(c->g3, g3, sizeof c->g3);
    const double theta[VC_N] = {mu, poly[1], poly[2], poly[3], poly[4], poly[5], Delta, beta, gamma};
    memcpy(c->theta, theta, sizeof theta);                /* control.true_theta */
    const VcRegressor phi = {omega, 1.0, Omega, 2.0 * Omega};
    c->phi = phi;                                         /* control.Regressor(scene) */
    if (law == 2) { /* Eq. 81 as printed: -cos tau for Delta^, cos Omega tau for gamma^ */
        const VcRegressor literal = {1.0, -1.0, Omega, Omega};
        c->phi_update = literal;
    } else {
        c->phi_update = phi;
    }
    c->l1 = lambdas[0];
    c->l2 = lambdas[1];
    for (int i = 0; i < VC_N; i++) {
        c->Lambda[i] = lambdas[i + 2];
        c->adaptation[i] = c->l2 / c->Lambda[i];          /* lambda2 Lambda^-1 */
    }
    c->c = sqrt(c->l1 / c->l2);                           /* Eq. 84 */
    c->k_damping = k_damping;
    c->promised_e1 = -pow(c->l1, 1.5) / sqrt(c->l2);      /* Eq. 85 */
    c->true_delta = Delta;
    c->law = law;
    c->time_tolerance = time_tolerance;
}

#define FIELD(name) offsetof(VcController, name)
size_t vk_controller_layout(size_t *offsets, size_t n_fields)
{
    const size_t fields[] = {FIELD(g3), FIELD(phi), FIELD(phi_update), FIELD(theta), FIELD(l1), FIELD(l2),
                             FIELD(Lambda), FIELD(adaptation), FIELD(c), FIELD(k_damping), FIELD(promised_e1),
                             FIELD(true_delta), FIELD(law), FIELD(time_tolerance), FIELD(t), FIELD(theta_hat),
                             FIELD(in), FIELD(out), FIELD(enabled)};
    if (n_fields != sizeof fields / sizeof fields[0]) return 0;
    memcpy(offsets, fields, sizeof fields);
    return sizeof(VcController);
}
