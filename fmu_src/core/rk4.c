/*
 * rk4.c -- fixed-step RK4 (rk4.h), operation for operation as vibromodel/integrate.py's Rk4.
 */
#include "rk4.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "pyfloat.h"
#include "roots.h"

/* integrate._rk4_growth: |R(zr + i zi)| */
static double growth(double zr, double zi)
{
    double pr = 1.0 / 6.0 + zr / 24.0, pi = zi / 24.0, qr, qi;
    qr = 0.5 + (zr * pr - zi * pi);
    qi = zr * pi + zi * pr;
    pr = 1.0 + (zr * qr - zi * qi);
    pi = zr * qi + zi * qr;
    qr = 1.0 + (zr * pr - zi * pi);
    qi = zr * pi + zi * pr;
    double w[2] = {qr, qi};
    return vk_python_hypot(w, 2);
}

/* Rk4._check_stability: refuse h if RK4 is unstable on the local linearisation x'' = -k x - c x' */
static inline __attribute__((always_inline)) int check_stability(Rk4 *s, DopRhs rhs, void *ctx, double h,
                                                                 DopReport *r)
{
    int n = (int)s->n;
    double y[DOP_MAX_DIM], f[DOP_MAX_DIM], values[4], t = s->t, x = s->y[0], v = s->y[1];
    double dx = 1e-6 * py_max(1.0, fabs(x)), dv = 1e-6 * py_max(1.0, fabs(v));
    const double shifts[4][2] = {{dx, 0.0}, {-dx, 0.0}, {0.0, dv}, {0.0, -dv}};
    for (int j = 0; j < 4; j++) {
        memcpy(y, s->y, sizeof(double) * (size_t)n);
        if (j < 2) y[0] = x + shifts[j][0];
        else y[1] = v + shifts[j][1];
        if (rhs(ctx, t, y, f)) return DOP_OK;  /* a model error: no verdict (Python's except: return) */
        values[j] = f[1];
    }
    double k = -(values[0] - values[1]) / (2.0 * dx);
    double c = -(values[2] - values[3]) / (2.0 * dv);
    s->nfev += 4;
    double disc = c * c / 4.0 - k, half = -c / 2.0, eigen[2][2];
    int count;
    if (disc >= 0.0) {
        double root = sqrt(disc);
        eigen[0][0] = half + root;
        eigen[0][1] = 0.0;
        eigen[1][0] = half - root;
        eigen[1][1] = 0.0;
        count = 2;
    } else {  /* a complex pair: the conjugate has the same |R| */
        eigen[0][0] = half;
        eigen[0][1] = sqrt(-disc);
        count = 1;
    }
    for (int j = 0; j < count; j++) {
        double re = eigen[j][0], im = eigen[j][1], zr = h * re, zi = h * im;
        if (re <= 0.0 && growth(zr, zi) > 1.0 + 1e-12) {
            double size = vk_python_hypot(eigen[j], 2);
            number_text h_text, t_text, zr_text, size_text, limit_text;
            char zi_text[48];
            snprintf(zi_text, sizeof zi_text, isnan(zi) ? "+nan" : "%+.3g", zi);
            return dop_report(r, s->n, DOP_FAILED, t, s->y, "RK4 unstable: step h = %s at tau = %s gives h*lambda = %s%sj "
                          "outside the stability region (|lambda| = %s); reduce max_step below %s", g_number_text(h_text, h, 3),
                          g_number_text(t_text, t, 10), g_number_text(zr_text, zr, 3), zi_text, g_number_text(size_text, size, 3),
                          g_number_text(limit_text, 2.5 / size, 3));
        }
    }
    return DOP_OK;
}

/* One fixed step's cubic Hermite interpolant (integrate._hermite_event's state) */
typedef struct {
    double x, v, h, x_new, v_new, c0, cx;
    int nan_seen;
    double nan_at;
} Hermite;

static void hermite_state(const Hermite *c, double s, double *xs, double *vs)
{
    double s2 = s * s, s3 = s * s * s;
    *xs = (2 * s3 - 3 * s2 + 1) * c->x + (s3 - 2 * s2 + s) * c->h * c->v + (3 * s2 - 2 * s3) * c->x_new +
          (s3 - s2) * c->h * c->v_new;
    *vs = ((6 * s2 - 6 * s) * (c->x - c->x_new) / c->h + (3 * s2 - 4 * s + 1) * c->v + (3 * s2 - 2 * s) * c->v_new);
}

static double hermite_g(const Hermite *c, double s)
{
    double xs, vs;
    hermite_state(c, s, &xs, &vs);
    return c->c0 + c->cx * xs;
}

#define NAN_FOUND 1
static int hermite_root_function(void *context, double s, double *f)
{
    Hermite *c = context;
    *f = hermite_g(c, s);
    if (isnan(*f)) {  /* scipy's _wrap_nan_raise */
        c->nan_seen = 1;
        c->nan_at = s;
        return NAN_FOUND;
    }
    return 0;
}

/* The event search's view of a terminal event on the step's cubic: beyond(s) = !(g(x(s)) > 0) */
static int hermite_beyond(void *context, double s, int *beyond)
{
    *beyond = !(hermite_g(context, s) > 0.0);
    return 0;
}

/* The Bernstein coefficients b[0..3] of an event's g = c0 + cx x(s) on one fixed step's cubic Hermite interpolant of
   x (integrate._hermite_event's, the same operations) */
static inline __attribute__((always_inline)) void hermite_bernstein(double c0, double cx, double x, double v, double h,
                                                                    double x_new, double v_new, double *b)
{
    b[0] = c0 + cx * x;
    b[1] = c0 + cx * (x + h * v / 3.0);
    b[2] = c0 + cx * (x_new - h * v_new / 3.0);
    b[3] = c0 + cx * x_new;
}

/* The search's first verdict on coefficients b[0..3]: every one > 0, so g > 0 over the whole step (no event) */
static inline __attribute__((always_inline)) int hermite_clear(const double *b)
{
    return py_min(py_min(py_min(b[0], b[1]), b[2]), b[3]) > 0.0;
}

/* integrate._hermite_event: *found and the fraction *s_event of the first point where terminal event e is
   reached on the step's cubic (the search: roots.c's bernstein_search); DOP_RAISED where Python's brentq raises */
static int hermite_event(int n, const double *y, Hermite *c, double t, int *found, double *s_event, DopReport *r)
{
    double b[4], s_a, s_b;
    int at_start;
    *found = 0;
    if (!(c->c0 + c->cx * c->x > 0.0)) {
        *found = 1;
        *s_event = 0.0;
        return DOP_OK;
    }
    hermite_bernstein(c->c0, c->cx, c->x, c->v, c->h, c->x_new, c->v_new, b);
    if (hermite_clear(b)) return DOP_OK;  /* the search's first verdict, inline */
    double scale = fabs(c->c0) + fabs(c->cx) * (fabs(c->x) + fabs(c->x_new) + fabs(c->h * c->v) +
                                                 fabs(c->h * c->v_new));  /* what b and g round against */
    if (bernstein_search(b, 3, 1, ROOT_EVENT_ROUNDING * scale, hermite_beyond, c, found, &s_a, &s_b, &at_start) ==
        ROOT_EVENT_UNSETTLED)
        return dop_report(r, n, DOP_RAISED, t, y, "RuntimeError: %s", ROOT_EVENT_UNSETTLED_TEXT);
    if (!*found) return DOP_OK;
    if (at_start) {
        *s_event = s_a;
        return DOP_OK;
    }
    int iterations, code = brentq(hermite_root_function, c, s_a, s_b, s_event, &iterations);
    number_text text;
    if (code == NAN_FOUND)
        return dop_report(r, n, DOP_RAISED, t, y, "ValueError: The function value at x=%s is NaN; solver "
                      "cannot continue.", exact_number_text(text, c->nan_at));
    if (code == ROOT_SIGN_ERROR)
        return dop_report(r, n, DOP_RAISED, t, y, "ValueError: f(a) and f(b) must have different signs");
    if (code == ROOT_NO_CONVERGENCE)
        return dop_report(r, n, DOP_RAISED, t, y, "RuntimeError: Failed to converge after %d iterations.",
                      iterations);
    return DOP_OK;
}

static inline __attribute__((always_inline)) int step_events(int n, int n_events, const DopEvent *events, double t,
                                                             const double *y, double h, const double *y_new,
                                                             DopReport *r)
{
    for (int i = 0; i < n_events; i++) {
        const DopEvent *e = &events[i];
        if (!e->terminal) continue;
        double b[4];  /* hermite_event's verdict "no event in this step" (g > 0 at the step's start, then every
                         coefficient > 0: its first two checks, the same operations) before its state is built: the
                         common step stores nothing (b stays in registers) */
        hermite_bernstein(e->c0, e->c[0], y[0], y[1], h, y_new[0], y_new[1], b);
        if (b[0] > 0.0 && hermite_clear(b)) continue;
        Hermite c = {y[0], y[1], h, y_new[0], y_new[1], e->c0, e->c[0], 0, 0.0};
        int found, code;
        double s_event = 0.0;  /* written by hermite_event when found (the initialiser: GCC's -O3 cannot tell) */
        code = hermite_event(n, y, &c, t, &found, &s_event, r);
        if (code) return code;
        if (found) {
            double xe, ve;
            if (s_event == 0.0 && !(e->c0 + e->c[0] * y[0] > 0.0)) {  /* on the event at the step's start */
                xe = y[0];
                ve = y[1];
            } else {
                hermite_state(&c, s_event, &xe, &ve);
            }
            r->t = t + s_event * h;
            memcpy(r->y, y, sizeof(double) * (size_t)n);
            r->y[0] = xe;
            r->y[1] = ve;
            r->event = i;
            r->message[0] = '\0';
            return DOP_TERMINAL;
        }
    }
    return DOP_OK;
}

int rk4_step_events(int n, int n_events, const DopEvent *events, double t, const double *y, double h,
                    const double *y_new, DopReport *r)
{
    return step_events(n, n_events, events, t, y, h, y_new, r);
}

/* The drive's phasors of a phased advance (Rk4._phases): p[2k], p[2k+1] = cos, sin of freq[k] t */
typedef struct {
    Rk4PhasedRhs rhs;
    int n_freq;
    const double *freq;
    double rotation[2 * RK4_MAX_PHASES];  /* cos, sin of freq[k] h/2 */
    double at_t[2 * RK4_MAX_PHASES];      /* the phasors at the step's start */
    int64_t since_anchor;                 /* steps since at_t was evaluated directly (-1: never) */
} Phases;

/* cos and sin of freq[k] t directly (integrate._phases_at); a fault as math.cos/math.sin raise */
static int phases_at(const Phases *ph, double t, double *p)
{
    int fault = FAULT_NONE;
    for (int k = 0; k < ph->n_freq; k++) {
        double angle = ph->freq[k] * t;
        p[2 * k] = py_cos(angle, &fault);
        p[2 * k + 1] = py_sin(angle, &fault);
    }
    return fault;
}

/* p_out = p rotated by `rotation` (integrate._rotate): angle addition */
static void rotate(const Phases *ph, const double *p, double *p_out)
{
    for (int k = 0; k < ph->n_freq; k++) {
        double c = p[2 * k], sn = p[2 * k + 1], rc = ph->rotation[2 * k], rs = ph->rotation[2 * k + 1];
        p_out[2 * k] = c * rc - sn * rs;
        p_out[2 * k + 1] = sn * rc + c * rs;
    }
}

/* Rk4._step (ph == NULL: rhs; else ph->rhs with the phasors of each stage's time); inlined into each advance, so
   that rk4_advance and rk4_advance_phased each get the step of their kind (no ph tests per stage) */
static inline __attribute__((always_inline)) int step(Rk4 *s, DopRhs rhs, Phases *ph, void *ctx, double h, DopReport *r)
{
    int n = (int)s->n;
    double t = s->t, *y = s->y, half = 0.5 * h;
    double k1[DOP_MAX_DIM], k2[DOP_MAX_DIM], k3[DOP_MAX_DIM], k4[DOP_MAX_DIM], ys[DOP_MAX_DIM], y_new[DOP_MAX_DIM];
    double p_half[2 * RK4_MAX_PHASES], p_end[2 * RK4_MAX_PHASES];
    int fault = FAULT_NONE;
    if (ph) {
        if (ph->since_anchor < 0 || ph->since_anchor >= RK4_PHASE_RESYNC) {
            if (ph->since_anchor < 0) {  /* the rotations, at the advance's first step */
                fault = phases_at(ph, half, ph->rotation);
            }
            if (!fault) fault = phases_at(ph, t, ph->at_t);
            ph->since_anchor = 0;
        }
        if (!fault) {
            rotate(ph, ph->at_t, p_half);
            rotate(ph, p_half, p_end);
        }
    }
    if (!fault) fault = ph ? ph->rhs(ctx, t, ph->at_t, y, k1) : rhs(ctx, t, y, k1);
    if (!fault) {
        for (int i = 0; i < n; i++) ys[i] = y[i] + half * k1[i];
        fault = ph ? ph->rhs(ctx, t + half, p_half, ys, k2) : rhs(ctx, t + half, ys, k2);
    }
    if (!fault) {
        for (int i = 0; i < n; i++) ys[i] = y[i] + half * k2[i];
        fault = ph ? ph->rhs(ctx, t + half, p_half, ys, k3) : rhs(ctx, t + half, ys, k3);
    }
    if (!fault) {
        for (int i = 0; i < n; i++) ys[i] = y[i] + h * k3[i];
        fault = ph ? ph->rhs(ctx, t + h, p_end, ys, k4) : rhs(ctx, t + h, ys, k4);
    }
    if (fault) {
        number_text h_text, t_text, x_text;
        return dop_report(r, s->n, DOP_FAILED, t, y, "RK4 step h = %s from tau = %s left the model's domain (x = %s); "
                      "reduce max_step", g_number_text(h_text, h, 3), g_number_text(t_text, t, 10), g_number_text(x_text, y[0], 10));
    }
    s->nfev += 4;
    for (int i = 0; i < n; i++) y_new[i] = y[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    if (!(isfinite(y_new[0]) && isfinite(y_new[1]))) {
        number_text t_text, h_text;
        return dop_report(r, s->n, DOP_FAILED, t, y, "RK4 unstable: the state became non-finite after tau = %s with h = %s; "
                      "reduce max_step", g_number_text(t_text, t, 10), g_number_text(h_text, h, 3));
    }
    int code = step_events(n, (int)s->n_events, s->events, t, y, h, y_new, r);
    if (code) return code;
    memcpy(s->y, y_new, sizeof(double) * (size_t)n);
    s->n_steps += 1;
    if (ph) {  /* the next step starts from this one's end */
        memcpy(ph->at_t, p_end, sizeof p_end);
        ph->since_anchor += 1;
    }
    return DOP_OK;
}

/* The stability check's right-hand side on a phased advance: the phasors at the advance's start (the check's
   time), which are direct cos and sin, the same values as the plain right-hand side computes */
typedef struct {
    Phases *ph;
    void *ctx;
} AnchorContext;

static int anchor_rhs(void *context, double t, const double *y, double *f)
{
    const AnchorContext *a = context;
    return a->ph->rhs(a->ctx, t, a->ph->at_t, y, f);
}

static inline __attribute__((always_inline)) int advance(Rk4 *s, DopRhs rhs, Phases *ph, void *ctx, double t_target,
                                                         DopReport *r)
{
    double span = t_target - s->t;
    if (span <= 0.0) return DOP_OK;
    double count = ceil(span / s->max_step * (1.0 - 1e-12));
    if (count < 1.0) count = 1.0;
    double h = span / count, t0 = s->t;
    AnchorContext anchor = {ph, ctx};
    int code = DOP_OK;
    if (!ph) {
        code = check_stability(s, rhs, ctx, h, r);
    } else if (!phases_at(ph, 0.5 * h, ph->rotation) && !phases_at(ph, s->t, ph->at_t)) {
        ph->since_anchor = 0;  /* the first step's rotations and phasors, evaluated here for the check too */
        code = check_stability(s, anchor_rhs, &anchor, h, r);
    }  /* else a fault: no verdict (as where the right-hand side faults); the first step meets it again */
    if (code) return code;
    for (double i = 1.0; i <= count; i += 1.0) {
        code = step(s, rhs, ph, ctx, h, r);
        if (code) return code;
        s->t = i == count ? t_target : t0 + i * h;
    }
    return DOP_OK;
}

int rk4_advance(Rk4 *s, DopRhs rhs, void *ctx, double t_target, DopReport *r)
{
    return advance(s, rhs, NULL, ctx, t_target, r);
}

int rk4_advance_phased(Rk4 *s, Rk4PhasedRhs rhs, void *ctx, int n_freq, const double *freq, double t_target,
                       DopReport *r)
{
    Phases ph = {rhs, n_freq, freq, {0}, {0}, -1};
    return advance(s, NULL, &ph, ctx, t_target, r);
}

int rk4_value_at(const Rk4 *st, double t, double *y, DopReport *r)
{
    if (t != st->t) {  /* Rk4._require_current */
        number_text own, asked;
        return dop_report(r, (int)st->n, DOP_RAISED, st->t, st->y, "ValueError: RK4 holds only tau = %s, not %s",
                          exact_number_text(own, st->t), exact_number_text(asked, t));
    }
    for (int64_t i = 0; i < st->n; i++) y[i] = st->y[i];  /* a loop: n is 2 in the plant (no memcpy call) */
    return DOP_OK;
}

double vk_rk4_drive_gain_x(double theta)
{
    const double phi = 0.5 * theta, s = sin(phi);
    if (theta == 0.0) return 1.0;
    if (fabs(s) < 1e-300) return INFINITY;
    return theta * theta * (1.0 + 2.0 * cos(phi)) / (12.0 * s * s);
}
