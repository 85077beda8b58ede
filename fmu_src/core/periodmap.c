/*
 * periodmap.c -- the n-period map with its variational equations (periodmap.h), on the core's DOP853.
 */
#include "periodmap.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "dop853.h"
#include "model.h"

#define PM_TWO_PI 6.283185307179586

typedef struct {
    double mu, Delta, w, alpha, gamma, R;  /* w = 1 / omega */
    int64_t param;
} PmField;

/* forces.electrostatic_mean and its x-derivative (forces.electrostatic_mean_stiffness): the AC drive at its mean */
static double em_mean(double x, double alpha, double gamma, double R)
{
    double u = 2.0 * x / (3.0 * R);
    return (alpha + gamma) / ((1.0 - u) * (1.0 - u)) - alpha / ((1.0 + u) * (1.0 + u));
}

static double em_stiffness(double x, double alpha, double gamma, double R)
{
    double u = 2.0 * x / (3.0 * R);
    double upper = 1.0 / ((1.0 - u) * (1.0 - u) * (1.0 - u)), lower = 1.0 / ((1.0 + u) * (1.0 + u) * (1.0 + u));
    return 4.0 / (3.0 * R) * (alpha * (upper + lower) + gamma * upper);
}

/* forces.hertz_stiffness: (1 + 2x/3)^(1/2) in contact, 0 without */
static double hertz_stiffness(double x)
{
    double s = 1.0 + 2.0 * x / 3.0;
    return s > 0.0 ? sqrt(s) : 0.0;
}

/* shooting.variational_rhs */
static int pm_rhs(void *context, double s, const double *y, double *f)
{
    const PmField *m = (const PmField *)context;
    double x = y[0], v = y[1], w = m->w;
    double g = vm_hertz(x) - 1.0 - em_mean(x, m->alpha, m->gamma, m->R);
    double g_x = hertz_stiffness(x) - em_stiffness(x, m->alpha, m->gamma, m->R);
    double dx = v * w, dv = (m->Delta * cos(s) - m->mu * v - g) * w;
    double kx = -g_x * w, kv = -m->mu * w, fx = 0.0, fv = 0.0;
    switch (m->param) {
    case PM_OMEGA: fx = -dx * w; fv = -dv * w; break;
    case PM_DELTA: fv = cos(s) * w; break;
    case PM_MU: fv = -v * w; break;
    case PM_ALPHA: fv = em_mean(x, 1.0, 0.0, m->R) * w; break;
    case PM_GAMMA: fv = em_mean(x, 0.0, 1.0, m->R) * w; break;
    default: break;
    }
    f[0] = dx;
    f[1] = dv;
    f[2] = y[3] * w;
    f[3] = kx * y[2] + kv * y[3];
    f[4] = y[5] * w;
    f[5] = kx * y[4] + kv * y[5];
    f[6] = y[7] * w + fx;
    f[7] = kx * y[6] + kv * y[7] + fv;
    return 0;
}

enum { EV_CONTACT = 0, EV_UPPER = 1, EV_LOWER = 2, EV_TURN = 3 };

int vk_period_map(const double *scene, int64_t param, int64_t periods, const double *z0, double *out,
                  int64_t *counts, char *message, int64_t size)
{
    if (message && size > 0) message[0] = '\0';
    double omega = scene[2], R = scene[5], gap = scene[8];
    if (!(omega > 0.0) || !(R > 0.0) || periods < 1 || param < PM_OMEGA || param > PM_GAMMA) {
        if (message && size > 0) snprintf(message, (size_t)size, "bad argument (omega %g, R %g, periods %lld, param %lld)",
                                          omega, R, (long long)periods, (long long)param);
        return PM_BAD_ARGUMENT;
    }
    PmField field = {scene[0], scene[1], 1.0 / omega, scene[3], scene[4], R, param};
    static const Dop853 blank;
    Dop853 s = blank;
    DopReport report;
    s.n = 8;
    s.rtol = scene[6];
    s.atol = scene[7];
    s.max_step = INFINITY;
    s.step_budget = INFINITY;
    s.n_events = 4;
    double c = 2.0 / (3.0 * R);
    s.events[EV_CONTACT].c0 = 1.0;
    s.events[EV_CONTACT].c[0] = 2.0 / 3.0;
    s.events[EV_UPPER].c0 = 1.0 - gap;
    s.events[EV_UPPER].c[0] = -c;
    s.events[EV_UPPER].terminal = 1;
    s.events[EV_LOWER].c0 = 1.0 - gap;
    s.events[EV_LOWER].c[0] = c;
    s.events[EV_LOWER].terminal = 1;
    s.events[EV_TURN].c[1] = 1.0;
    double y0[8] = {z0[0], z0[1], 1.0, 0.0, 0.0, 1.0, 0.0, 0.0};
    int code = dop_restart(&s, pm_rhs, &field, 0.0, y0, &report);
    double s_end = PM_TWO_PI * (double)periods, x_min = y0[0], x_max = y0[0];
    int64_t crossings = 0, turns = 0;
    while (code == DOP_OK && s.t < s_end) {
        double remaining = s_end - s.t;
        if (remaining <= 64.0 * (nextafter(s_end, INFINITY) - s_end)) break;  /* a rounding short of the end */
        s.max_step = remaining;  /* the last step ends at s_end exactly */
        int64_t contact = s.side[EV_CONTACT], turn = s.side[EV_TURN];
        code = dop_advance(&s, pm_rhs, &field, nextafter(s.t, INFINITY), &report);  /* one step */
        if (code != DOP_OK) break;
        if (s.side[EV_CONTACT] != contact) crossings += 1;
        if (s.side[EV_TURN] != turn) {
            turns += 1;
            x_min = fmin(x_min, s.y[0]);
            x_max = fmax(x_max, s.y[0]);
        }
    }
    if (code == DOP_TERMINAL) {
        if (message && size > 0) snprintf(message, (size_t)size, "pull-in (an electrode gap below %g) at x = %.6g",
                                          gap, report.y[0]);
        return PM_PULL_IN;
    }
    if (code != DOP_OK) {
        if (message && size > 0) snprintf(message, (size_t)size, "DOP853 failed at s = %.6g: %s", report.t,
                                          report.message);
        return PM_FAILED;
    }
    memcpy(out, s.y, 8 * sizeof(double));
    out[8] = fmin(x_min, s.y[0]);
    out[9] = fmax(x_max, s.y[0]);
    counts[0] = crossings;
    counts[1] = turns;
    counts[2] = s.n_steps;
    return PM_OK;
}
