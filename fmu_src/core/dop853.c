/*
 * dop853.c -- adaptive DOP853 with dense output and event location (dop853.h), operation for operation as
 * vibromodel/integrate.py's Dop853.  Where Python raises inside Dop853._trial's try (ArithmeticError,
 * ValueError), the step fails as there; anywhere else the exception escapes, and here the call returns
 * DOP_RAISED with the exception's text.
 */
#include "dop853.h"

#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "dop853_tableau.h"
#include "pyfloat.h"
#include "roots.h"

/* integrate.py's step control constants */
#define SAFETY 0.9
#define MIN_FACTOR 0.2
#define MAX_FACTOR 10.0
#define ERROR_EXPONENT (-1.0 / 8.0)
/* integrate.py's PI controller (the comment at PI_BETA) */
#define PI_BETA 0.04
#define PI_ALPHA (1.0 / 8.0 - 0.75 * PI_BETA)
#define PI_ERROR_FLOOR 1e-4
/* integrate.EVENT_SCREEN (event location: docs/events.md; the search itself: roots.c) */
#define EVENT_SCREEN 2.0
/* UNROLL(n): unroll the next loop n times (the stage sums below). The fuzz build (tests/fuzz/run.py) defines
   VK_NO_UNROLL: under ASan + UBSan + coverage, clang took 37 s to compile this file unrolled and 2 s rolled (per
   model, three times per build). Unrolling changes no operation and no order, only the code's size. */
#define VK_PRAGMA(text) _Pragma(#text)
#ifdef VK_NO_UNROLL
#define UNROLL(n)
#else
#define UNROLL(n) VK_PRAGMA(GCC unroll n)
#endif

/* The stages of one step: k[stage][component], stages 0..n-1 (stage-major, as Dop853.k) */
typedef struct {
    double k[DOP_STAGES][DOP_MAX_DIM];
    int n;
} Stages;

/* Two components per SSE2 operation (GCC/Clang vector extension).  Each lane does the scalar code's IEEE operation
   on its own component (no contraction: -ffp-contract=off), so every sum has the same terms in the same order as
   integrate.py's per-component loops: the same bits, fewer instructions. */
typedef double v2 __attribute__((vector_size(16)));

static inline __attribute__((always_inline)) v2 load2(const double *p)
{
    v2 v;
    memcpy(&v, p, sizeof v);
    return v;
}

static inline __attribute__((always_inline)) void store2(double *p, v2 v) { memcpy(p, &v, sizeof v); }

/* out[i] = sum of row[j] * k[j][i] over j < m, left to right from 0.0, for every component i < n at once (with
   skip_zero, the terms of zero coefficients left out).  The sums live in registers while the stages stream by when
   n is a constant (the callers' n == 2 and n == 11 branches: the component loops unroll). */
static inline __attribute__((always_inline)) void combine(const double *row, int m, const Stages *k, int n,
                                                          int skip_zero, double *out)
{
    v2 acc[DOP_MAX_DIM / 2] = {{0.0, 0.0}};  /* every pair +0.0, as the scalar sums start */
    double tail = 0.0;
    int pairs = n / 2;
UNROLL(16)
    for (int j = 0; j < m; j++) {
        double a = row[j];
        if (skip_zero && a == 0.0) continue;
        v2 av = {a, a};
UNROLL(8)
        for (int p = 0; p < pairs; p++) acc[p] += av * load2(k->k[j] + 2 * p);
        if (n & 1) tail += a * k->k[j][n - 1];
    }
UNROLL(8)
    for (int p = 0; p < pairs; p++) store2(out + 2 * p, acc[p]);
    if (n & 1) out[n - 1] = tail;
}

/* out[i] = y[i] + h * sum[i], i < n */
static inline __attribute__((always_inline)) void step_from(const double *y, double h, const double *sum, int n,
                                                            double *out)
{
    int i = 0;
    v2 hv = {h, h};
UNROLL(8)
    for (; i + 1 < n; i += 2) store2(out + i, load2(y + i) + hv * load2(sum + i));
    if (i < n) out[i] = y[i] + h * sum[i];
}

/* dst[i] = src[i], i < n: inline for the plant's two components (a memcpy call of a size known only at run time
   costs more than the copy), memcpy otherwise */
static inline __attribute__((always_inline)) void copy_n(double *dst, const double *src, int n)
{
    if (n == 2) {
        dst[0] = src[0];
        dst[1] = src[1];
    } else {
        memcpy(dst, src, sizeof(double) * (size_t)n);
    }
}

int dop_report(DopReport *r, int n, int code, double t, const double *y, const char *format, ...)
{
    va_list args;
    va_start(args, format);
    vsnprintf(r->message, DOP_MESSAGE, format, args);
    va_end(args);
    r->t = t;
    memcpy(r->y, y, sizeof(double) * (size_t)n);
    r->event = -1;
    return code;
}

/* The exception a fault raises in Python, escaping. */
static int raise_fault(const Dop853 *s, DopReport *r, int fault)
{
    char text[DOP_MESSAGE];
    py_fault_text(fault, text, sizeof text);
    return dop_report(r, s->n, DOP_RAISED, s->t, s->y, "%s", text);
}

/* integrate._dot over the first m stages, for every component i < n at once: out[i] = sum of c[j] * k[j][i], left
   to right from 0 (every term, zero coefficients included); n a constant where it is the plant's (2) or the closed
   loop's (11), as in run_stages */
static inline __attribute__((always_inline)) void dots(const double *c, int m, const Stages *k, int n, double *out)
{
    if (n == 2) combine(c, m, k, 2, 0, out);
    else if (n == 11) combine(c, m, k, 11, 0, out);
    else combine(c, m, k, n, 0, out);
}

double dop_event_g(const Dop853 *s, int i, const double *y)
{
    const DopEvent *e = &s->events[i];
    double g = e->c0;
    for (int j = 0; j < s->n; j++)
        if (e->c[j] != 0.0) g += e->c[j] * y[j];
    return g;
}

/* sum of c[j] * values[j] over the event's nonzero coefficients, from 0.0 (the rate of g along f, and the like) */
static double event_linear(const Dop853 *s, int i, const double *values)
{
    const DopEvent *e = &s->events[i];
    double g = 0.0;
    for (int j = 0; j < s->n; j++)
        if (e->c[j] != 0.0) g += e->c[j] * values[j];
    return g;
}

/* Dop853._f: counted evaluation */
static int counted(Dop853 *s, DopRhs rhs, void *ctx, double t, const double *y, double *f)
{
    s->nfev += 1;
    return rhs(ctx, t, y, f);
}

/* Dop853._run_stages for rows first..last of DOP_A (row st has st coefficients, node DOP_C[st]) or, with
 * first = DOP_N_STAGES, the FSAL stage (row DOP_B, node 1); a stage is appended once its derivative is in. */
static inline __attribute__((always_inline)) int stages_of(DopRhs rhs, void *ctx, double t, const double *y,
                                                           double h, int first, int last, Stages *k, double *y_last,
                                                           int n)
{
    double ys[DOP_MAX_DIM];
UNROLL(16)
    for (int st = first; st <= last; st++) {
        const double *row = st == DOP_N_STAGES ? DOP_B : DOP_A[st];
        double c = st == DOP_N_STAGES ? 1.0 : DOP_C[st];
        double ts = t + c * h;
        int m = st < k->n ? st : k->n;
        double sum[DOP_MAX_DIM];  /* integrate._tableau_dot for every component at once: each sum in the same order */
        /* integrate._tableau_dot: the zero coefficients (38 of 120) are skipped -- for the plant's two components
           free of tests, the stage loops unrolled with the tableau's constants (1 % fewer instructions per
           output of the native FMU than every term: 2274 -> 2251 on the paper scene at rtol 1e-4) */
        combine(row, m, k, n, 1, sum);
        step_from(y, h, sum, n, ys);
        int fault = rhs(ctx, ts, ys, k->k[k->n]);  /* the derivative straight into its stage row */
        if (fault) return fault;
        k->n += 1;
        memcpy(y_last, ys, sizeof(double) * (size_t)n);
    }
    return FAULT_NONE;
}

/* stages_of with the dimension a constant where it is the plant's (2) or the closed loop's (11: x, v and nine
   estimates, closedloop.h): the compiler unrolls the component loops */
static inline __attribute__((always_inline)) int run_stages(const Dop853 *s, DopRhs rhs, void *ctx, double t, const double *y, double h, int first,
                      int last, Stages *k, double *y_last)
{
    if (s->n == 2) return stages_of(rhs, ctx, t, y, h, first, last, k, y_last, 2);
    if (s->n == 11) return stages_of(rhs, ctx, t, y, h, first, last, k, y_last, 11);
    return stages_of(rhs, ctx, t, y, h, first, last, k, y_last, (int)s->n);
}

/* Dop853._near_kink: a non-terminal event (a kink of the right-hand side) changes side over the step from y (rate
   s->f) to y_new (rate: the last stage), or lies within one step of its ends: |g| <= h max(|g'|) at the nearer end */
static int near_kink(const Dop853 *s, const double *y, const double *y_new, const Stages *k, double h)
{
    const double *f_new = k->k[DOP_N_STAGES];
    for (int i = 0; i < s->n_events; i++) {
        if (s->events[i].terminal) continue;
        double g0 = dop_event_g(s, i, y), g1 = dop_event_g(s, i, y_new);
        double rate = py_max(fabs(event_linear(s, i, s->f)), fabs(event_linear(s, i, f_new)));
        if ((g0 > 0.0) != (g1 > 0.0) || py_min(fabs(g0), fabs(g1)) <= h * rate) return 1;
    }
    return 0;
}

/* Dop853._trial: one step of size h from (t, y) with derivative s->f. Stages into k, new state into y_new;
 * *error is the scaled error norm, inf when a stage raised (caught, as Python's try) or the error is not
 * finite. Returns a fault that Python would not catch (an overflowing square, a zero divisor). */
static int trial(Dop853 *s, DopRhs rhs, void *ctx, double t, const double *y, double h, Stages *k,
                 double *y_new, double *error)
{
    int n = (int)s->n, fault = FAULT_NONE;
    double scale[DOP_MAX_DIM];
    copy_n(k->k[0], s->f, n);
    k->n = 1;
    if (run_stages(s, rhs, ctx, t, y, h, 1, DOP_N_STAGES, k, y_new) != FAULT_NONE) {
        s->nfev += k->n;  /* Python: self.nfev += len(stages[1]) */
        memcpy(y_new, y, sizeof(double) * (size_t)n);
        *error = INFINITY;
        return FAULT_NONE;
    }
    s->nfev += DOP_N_STAGES;
    for (int i = 0; i < n; i++) scale[i] = s->atol + s->rtol * py_max(fabs(y[i]), fabs(y_new[i]));
    double e5 = 0.0, e3 = 0.0, d5[DOP_MAX_DIM], d3[DOP_MAX_DIM];
    dots(DOP_E5, DOP_N_STAGES + 1, k, n, d5);
    dots(DOP_E3, DOP_N_STAGES + 1, k, n, d3);
    for (int i = 0; i < n; i++) {
        double term = py_square(d5[i] / scale[i], &fault);
        if (fault) return fault;
        e5 += term;
    }
    for (int i = 0; i < n; i++) {
        double term = py_square(d3[i] / scale[i], &fault);
        if (fault) return fault;
        e3 += term;
    }
    if (!isfinite(e5 + e3)) {
        memcpy(y_new, y, sizeof(double) * (size_t)n);
        *error = INFINITY;
    } else {
        double weight3 = near_kink(s, y, y_new, k, h) ? 0.0 : 0.01;  /* integrate.py: the error norm's comment */
        if (e5 == 0.0 && weight3 * e3 == 0.0) *error = 0.0;
        else *error = py_div(fabs(h) * e5, sqrt((e5 + weight3 * e3) * (double)n), &fault);
    }
    return fault;
}

/* Dop853._accept (t, y may not alias s->y) */
static void accept(Dop853 *s, double t, const double *y, double h, const double *y_new, const Stages *k)
{
    int n = (int)s->n;
    s->t_old = t;
    copy_n(s->y_old, y, n);
    copy_n(s->f_old, s->f, n);
    s->has_old = 1;
    for (int j = 0; j < k->n; j++) copy_n(s->k[j], k->k[j], n);
    copy_n(s->f, k->k[k->n - 1], n);
    s->n_stages = k->n;
    s->dense_ready = 0;
    s->t = t + h;
    copy_n(s->y, y_new, n);
    s->n_steps += 1;
}

/* Dop853._build_dense: coefficients of scipy's Dop853DenseOutput from three extra stages (uncounted unless
 * all three succeed). */
static int build_dense(Dop853 *s, DopRhs rhs, void *ctx)
{
    Stages k;
    int n = (int)s->n;
    double h = s->t - s->t_old, y_last[DOP_MAX_DIM];
    k.n = (int)s->n_stages;
    for (int j = 0; j < k.n; j++) copy_n(k.k[j], s->k[j], n);
    int fault = run_stages(s, rhs, ctx, s->t_old, s->y_old, h, DOP_N_STAGES + 1, DOP_STAGES - 1, &k, y_last);
    if (fault) return fault;
    s->nfev += DOP_STAGES - DOP_N_STAGES - 1;
    for (int i = 0; i < n; i++) {
        double dy = s->y[i] - s->y_old[i];
        s->dense[0][i] = dy;
        s->dense[1][i] = h * s->f_old[i] - dy;
        s->dense[2][i] = 2.0 * dy - h * (s->f[i] + s->f_old[i]);
    }
    for (int row = 0; row < 4; row++) {
        double sum[DOP_MAX_DIM];
        dots(DOP_D[row], k.n, &k, n, sum);
        for (int i = 0; i < n; i++) s->dense[3 + row][i] = h * sum[i];
    }
    s->dense_ready = 1;
    return FAULT_NONE;
}

/* y_old + integrate._evaluate for every component: the dense output at the fraction f of the step into y */
static void interpolate(const Dop853 *s, double f, int n, double *y)
{
    double g = 1.0 - f;
    v2 fv = {f, f}, gv = {g, g};
    int i = 0;
    for (; i + 1 < n; i += 2) {
        v2 acc = {0.0, 0.0};
        for (int j = DOP_DENSE - 1; j >= 0; j--) {
            acc += load2(s->dense[j] + i);
            acc *= (DOP_DENSE - 1 - j) % 2 == 0 ? fv : gv;
        }
        store2(y + i, load2(s->y_old + i) + acc);
    }
    for (; i < n; i++) {
        double acc = 0.0;
        for (int j = DOP_DENSE - 1; j >= 0; j--) {
            acc += s->dense[j][i];
            acc *= (DOP_DENSE - 1 - j) % 2 == 0 ? f : g;
        }
        y[i] = s->y_old[i] + acc;
    }
}

/* Dop853.value_at (with _interpolant) */
int dop_value_at(Dop853 *s, DopRhs rhs, void *ctx, double t, double *y, DopReport *r)
{
    int n = (int)s->n;
    if (t == s->t) {
        memcpy(y, s->y, sizeof(double) * (size_t)n);
        return DOP_OK;
    }
    if (!s->has_old || !(s->t_old <= t && t <= s->t)) {
        number_text t_text, old_text, end_text;
        return dop_report(r, s->n, DOP_RAISED, s->t, s->y, "ValueError: tau = %s is outside the last step [%s, %s]",
                      exact_number_text(t_text, t), s->has_old ? exact_number_text(old_text, s->t_old) : "None", exact_number_text(end_text, s->t));
    }
    if (!s->dense_ready) {
        int fault = build_dense(s, rhs, ctx);
        if (fault) return raise_fault(s, r, fault);
    }
    double f = (t - s->t_old) / (s->t - s->t_old);  /* the step has a length: t_old < t */
    interpolate(s, f, n, y);
    return DOP_OK;
}

/* Dop853._restart */
int dop_restart(Dop853 *s, DopRhs rhs, void *ctx, double t, const double *y, DopReport *r)
{
    s->t = t;
    memmove(s->y, y, sizeof(double) * (size_t)s->n);
    int fault = counted(s, rhs, ctx, t, s->y, s->f);
    if (fault) return raise_fault(s, r, fault);
    s->has_old = 0;
    s->dense_ready = 0;
    s->stopped = 0;
    for (int i = 0; i < s->n_events; i++)
        if (!s->events[i].terminal) s->side[i] = dop_event_g(s, i, s->y) > 0.0;
    return DOP_OK;
}

/* Dop853._initial_step: Hairer's starting step (scipy's select_initial_step) over all components */
static int initial_step(Dop853 *s, DopRhs rhs, void *ctx, double *h)
{
    int n = (int)s->n, fault;
    double scale[DOP_MAX_DIM], w[DOP_MAX_DIM] = {0.0}, y1[DOP_MAX_DIM] = {0.0}, f1[DOP_MAX_DIM] = {0.0}, t = s->t;
    double root_n = sqrt((double)n);
    for (int i = 0; i < n; i++) scale[i] = s->atol + fabs(s->y[i]) * s->rtol;
    for (int i = 0; i < n; i++) w[i] = s->y[i] / scale[i];
    double d0 = vk_python_hypot(w, n) / root_n;
    for (int i = 0; i < n; i++) w[i] = s->f[i] / scale[i];
    double d1 = vk_python_hypot(w, n) / root_n;
    double h0 = d0 < 1e-5 || d1 < 1e-5 ? 1e-6 : 0.01 * d0 / d1;
    h0 = py_min(h0, s->max_step);
    for (int i = 0; i < n; i++) y1[i] = s->y[i] + h0 * s->f[i];
    fault = counted(s, rhs, ctx, t + h0, y1, f1);
    if (fault) return fault;
    for (int i = 0; i < n; i++) w[i] = (f1[i] - s->f[i]) / scale[i];
    double d2 = py_div(vk_python_hypot(w, n) / root_n, h0, &fault);
    if (fault) return fault;
    double d_max = py_max(d1, d2);
    double h1 = d_max <= 1e-15 ? py_max(1e-6, h0 * 1e-3) : vk_python_pow(0.01 / d_max, 1.0 / 9.0, &fault);
    if (fault) return fault;
    *h = py_min(py_min(100.0 * h0, h1), s->max_step);
    return FAULT_NONE;
}

/* ---- event location ---- */

/* The function brentq sees: f(tt) = g(value_at(tt)) wrapped by scipy's _wrap_nan_raise. */
static int root_function(Dop853 *s, DopRhs rhs, void *ctx, int event, double tt, double *f, DopReport *r)
{
    double y[DOP_MAX_DIM];
    int code = dop_value_at(s, rhs, ctx, tt, y, r);
    if (code) return code;
    *f = dop_event_g(s, event, y);
    if (isnan(*f)) {
        number_text text;
        return dop_report(r, s->n, DOP_RAISED, s->t, s->y,
                      "ValueError: The function value at x=%s is NaN; solver cannot continue.", exact_number_text(text, tt));
    }
    return DOP_OK;
}

typedef struct {
    Dop853 *s;
    DopRhs rhs;
    void *ctx;
    int event;
    DopReport *r;
} RootContext;

static int event_on_dense(void *context, double tt, double *f)
{
    RootContext *c = context;
    return root_function(c->s, c->rhs, c->ctx, c->event, tt, f, c->r);
}

/* Dop853._locate: brentq on the dense output in [xa, xb], its errors as Python raises them */
static int locate(Dop853 *s, DopRhs rhs, void *ctx, int event, double xa, double xb, double *root, DopReport *r)
{
    RootContext c = {s, rhs, ctx, event, r};
    int iterations, code = brentq(event_on_dense, &c, xa, xb, root, &iterations);
    if (code == ROOT_SIGN_ERROR)
        return dop_report(r, s->n, DOP_RAISED, s->t, s->y, "ValueError: f(a) and f(b) must have different signs");
    if (code == ROOT_NO_CONVERGENCE)
        return dop_report(r, s->n, DOP_RAISED, s->t, s->y, "RuntimeError: Failed to converge after %d iterations.", iterations);
    return code;
}

/* The event search's view of event i on the last step's dense output: beyond(s) = whether g at the fraction s of
   the step (t_old + s h, the step's ends exactly) is past the event from the side `positive` */
typedef struct {
    Dop853 *s;
    DopRhs rhs;
    void *ctx;
    int i, positive;
    DopReport *r;
} DenseEvent;

#define BEYOND(positive, g) ((positive) ? !((g) > 0.0) : (g) > 0.0)

/* the time of the fraction s of the last step, as Dop853._first_zero computes it */
static double fraction_time(const Dop853 *s, double f)
{
    if (f == 1.0) return s->t;
    if (f == 0.0) return s->t_old;
    return s->t_old + f * (s->t - s->t_old);
}

static int beyond_on_dense(void *context, double f, int *beyond)
{
    DenseEvent *c = context;
    double y[DOP_MAX_DIM];
    int code = dop_value_at(c->s, c->rhs, c->ctx, fraction_time(c->s, f), y, c->r);
    if (code) return code;
    *beyond = BEYOND(c->positive, dop_event_g(c->s, c->i, y));
    return DOP_OK;
}

/* Dop853._first_zero: the earliest time in the last step where event i is reached on the dense output
 * (terminal: g <= 0; other: g on the other side than side[i]); *found = 0 if none. The search is roots.c's. */
static int first_zero(Dop853 *s, DopRhs rhs, void *ctx, int i, int *found, double *t_event, DopReport *r)
{
    const DopEvent *e = &s->events[i];
    int positive = e->terminal ? 1 : (int)s->side[i], code;
    *found = 0;
    double g0 = dop_event_g(s, i, s->y_old), g1 = dop_event_g(s, i, s->y);
    if (BEYOND(positive, g0)) {
        *found = 1;
        *t_event = s->t_old;
        return DOP_OK;
    }
    double h = s->t - s->t_old;
    if (!BEYOND(positive, g1)) {
        double reach = EVENT_SCREEN * (fabs(g1 - g0) + h * (fabs(event_linear(s, i, s->f_old)) +
                                                            fabs(event_linear(s, i, s->f))));
        if (fabs(g0) > reach && fabs(g1) > reach) return DOP_OK;
    }
    if (!s->dense_ready) {
        int fault = build_dense(s, rhs, ctx);
        if (fault) return raise_fault(s, r, fault);
    }
    double G[DOP_DENSE], b[DOP_DENSE + 1];
    for (int j = 0; j < DOP_DENSE; j++) {
        G[j] = event_linear(s, i, s->dense[j]);
    }
    double scale = fabs(e->c0);  /* the magnitudes b and g's evaluation round against (Dop853._first_zero's) */
    for (int j = 0; j < s->n; j++)
        if (e->c[j] != 0.0) scale += fabs(e->c[j] * s->y_old[j]);
    for (int j = 0; j < DOP_DENSE; j++) scale += fabs(G[j]);
    for (int k = 0; k < 8; k++) {
        double sum = 0.0;
        for (int j = 0; j < DOP_DENSE; j++) sum += G[j] * DOP_BERNSTEIN[j][k];
        b[k] = g0 + sum;
    }
    DenseEvent c = {s, rhs, ctx, i, positive, r};
    double s_a, s_b;
    int at_start;
    code = bernstein_search(b, DOP_DENSE, positive, ROOT_EVENT_ROUNDING * scale, beyond_on_dense, &c, found, &s_a,
                            &s_b, &at_start);
    if (code == ROOT_EVENT_UNSETTLED)
        return dop_report(r, s->n, DOP_RAISED, s->t, s->y, "RuntimeError: %s", ROOT_EVENT_UNSETTLED_TEXT);
    if (code || !*found) return code;
    if (at_start) {
        *t_event = fraction_time(s, s_a);
        return DOP_OK;
    }
    return locate(s, rhs, ctx, i, fraction_time(s, s_a), fraction_time(s, s_b), t_event, r);  /* one zero there */
}
#undef BEYOND

/* Dop853._move_to_side: the state onto event i's zero, then ulp by ulp onto its side `side`; a new derivative */
static int move_to_side(Dop853 *s, DopRhs rhs, void *ctx, int i, int side, DopReport *r)
{
    const DopEvent *e = &s->events[i];
    int j = 0, n = (int)s->n;
    for (int m = 1; m < n; m++)
        if (fabs(e->c[m]) > fabs(e->c[j])) j = m;
    double rest = e->c0;
    for (int m = 0; m < n; m++)
        if (m != j && e->c[m] != 0.0) rest += e->c[m] * s->y[m];
    s->y[j] = -rest / e->c[j];
    double direction = (e->c[j] > 0.0) == side ? INFINITY : -INFINITY;
    for (int attempt = 0; attempt < 8; attempt++) {
        if ((dop_event_g(s, i, s->y) > 0.0) == side) break;
        s->y[j] = nextafter(s->y[j], direction);
    }
    int fault = counted(s, rhs, ctx, s->t, s->y, s->f);
    if (fault) return raise_fault(s, r, fault);
    s->dense_ready = 0;
    return DOP_OK;
}

static double step_factor(double error);

/* Dop853._shorten: the step cut at an event failed its error test: an error-controlled shorter step instead */
static int shorten(Dop853 *s, DopRhs rhs, void *ctx, double t0, const double *y0, double h, double error, DopReport *r)
{
    Stages k;
    double y_new[DOP_MAX_DIM];
    double min_step = 10.0 * (nextafter(t0, INFINITY) - t0);
    for (;;) {
        if (!isfinite(error)) h *= MIN_FACTOR;
        else h *= py_max(MIN_FACTOR, step_factor(error));
        if (!(h >= min_step)) {
            number_text h_text, t_text, x_text;
            return dop_report(r, s->n, DOP_FAILED, t0, y0, "step size collapsed to %s at tau = %s, x = %s (stiff or singular)",
                          g_number_text(h_text, h, 3), g_number_text(t_text, t0, 10), g_number_text(x_text, y0[0], 10));
        }
        int fault = trial(s, rhs, ctx, t0, y0, h, &k, y_new, &error);
        if (fault) return raise_fault(s, r, fault);
        if (error < 1.0) break;
    }
    accept(s, t0, y0, h, y_new, &k);
    s->h = py_min(s->h, h);
    return DOP_OK;
}

/* Dop853._handle_events: find the earliest event in the last step; cut the step there (a redone step that fails
   the error test: shorten). */
static int handle_events(Dop853 *s, DopRhs rhs, void *ctx, double t0, const double *y0, DopReport *r)
{
    int earliest = -1, code, found;
    double earliest_t = 0.0, t_event = 0.0;
    for (int i = 0; i < s->n_events; i++) {
        code = first_zero(s, rhs, ctx, i, &found, &t_event, r);
        if (code) return code;
        if (found && (earliest < 0 || t_event < earliest_t)) {
            earliest = i;
            earliest_t = t_event;
        }
    }
    if (earliest < 0) return DOP_OK;
    size_t bytes = sizeof(double) * (size_t)s->n;
    double h = earliest_t - t0;
    s->t = t0;
    memcpy(s->y, y0, bytes);
    memcpy(s->f, s->f_old, bytes);
    if (h > 0.0) {
        Stages k;
        double y_new[DOP_MAX_DIM], error;
        int fault = trial(s, rhs, ctx, t0, y0, h, &k, y_new, &error);
        if (fault) return raise_fault(s, r, fault);
        if (!(error < 1.0)) return shorten(s, rhs, ctx, t0, y0, h, error, r);
        accept(s, t0, y0, h, y_new, &k);
    } else {  /* the event is at the step's start: the step is undone */
        s->has_old = 0;
        s->dense_ready = 0;
    }
    if (s->events[earliest].terminal) {
        s->stopped = earliest + 1;
        s->stop_t = s->t;
        memcpy(s->stop_y, s->y, bytes);
        return DOP_OK;
    }
    int side = !s->side[earliest];
    if ((dop_event_g(s, earliest, s->y) > 0.0) != side) {
        code = move_to_side(s, rhs, ctx, earliest, side, r);
        if (code) return code;
    }
    s->side[earliest] = side;
    return DOP_OK;
}

/* SAFETY * error**ERROR_EXPONENT of Dop853._step: the error is positive and finite there, pow cannot fault */
static double step_factor(double error)
{
    int fault = FAULT_NONE;
    return SAFETY * vk_python_pow(error, ERROR_EXPONENT, &fault);
}

/* integrate.pi_factor: SAFETY error**-PI_ALPHA max(err_old, PI_ERROR_FLOOR)**PI_BETA (1 for the memory term when
   err_old <= 0: none), error positive and finite, err_old finite (a restored state's doubles are finite: state
   checks), so pow cannot fault */
static double pi_factor(double error, double err_old)
{
    int fault = FAULT_NONE;
    double memory = err_old > 0.0 ? vk_python_pow(py_max(err_old, PI_ERROR_FLOOR), PI_BETA, &fault) : 1.0;
    return SAFETY * vk_python_pow(error, -PI_ALPHA, &fault) * memory;
}

/* Dop853._step: one accepted step (the step size adapted on the way), then its events */
static int step(Dop853 *s, DopRhs rhs, void *ctx, DopReport *r)
{
    double t = s->t, y[DOP_MAX_DIM], y_new[DOP_MAX_DIM], h, error;
    int rejected = 0, fault;
    Stages k;
    copy_n(y, s->y, (int)s->n);
    if (s->h <= 0.0) {  /* Dop853.h is None: a chosen step size is > 0 (or NaN) */
        fault = initial_step(s, rhs, ctx, &h);
        if (fault) return raise_fault(s, r, fault);
        s->h = h;
    }
    double min_step = 10.0 * (nextafter(t, INFINITY) - t);
    h = py_min(s->h, s->max_step);
    for (;;) {
        if (!(h >= min_step)) {
            number_text h_text, t_text, x_text;
            return dop_report(r, s->n, DOP_FAILED, t, y, "step size collapsed to %s at tau = %s, x = %s (stiff or singular)",
                          g_number_text(h_text, h, 3), g_number_text(t_text, t, 10), g_number_text(x_text, y[0], 10));
        }
        fault = trial(s, rhs, ctx, t, y, h, &k, y_new, &error);
        if (fault) return raise_fault(s, r, fault);
        if (error < 1.0) {
            double factor = error == 0.0 ? MAX_FACTOR : py_min(MAX_FACTOR, pi_factor(error, s->err_old));
            s->h = h * (rejected ? py_min(1.0, factor) : factor);
            s->err_old = error;
            break;
        }
        if (!isfinite(error)) h *= MIN_FACTOR;
        else h *= py_max(MIN_FACTOR, step_factor(error));
        rejected = 1;
    }
    accept(s, t, y, h, y_new, &k);
    return handle_events(s, rhs, ctx, t, y, r);
}

static int terminal(const Dop853 *s, DopReport *r)
{
    r->t = s->stop_t;
    memcpy(r->y, s->stop_y, sizeof(double) * (size_t)s->n);
    r->event = s->stopped - 1;
    r->message[0] = '\0';
    return DOP_TERMINAL;
}

/* Dop853.advance: step until t_target is covered.  Inline (always_inline, across files under -flto; an external
   definition all the same, dop853.h declaring it plainly): a container's per-solver doStep (solver.h) runs the step
   loop itself, as the plant's and the loop's doStep did before the solver interface (a call less per doStep). */
inline __attribute__((always_inline)) int dop_advance(Dop853 *s, DopRhs rhs, void *ctx, double t_target,
                                                      DopReport *r)
{
    long long steps = 0;
    while (s->t < t_target) {
        if (s->stopped) return terminal(s, r);
        if ((double)steps >= s->step_budget) {
            number_text t_text, target_text;
            return dop_report(r, s->n, DOP_FAILED, s->t, s->y,
                          "%lld steps reached only tau = %s of %s: make smaller communication steps", steps,
                          g_number_text(t_text, s->t, 10), g_number_text(target_text, t_target, 10));
        }
        int code = step(s, rhs, ctx, r);
        if (code) return code;
        steps += 1;
    }
    if (s->stopped && s->stop_t <= t_target) return terminal(s, r);
    return DOP_OK;
}
