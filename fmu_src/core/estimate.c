/* estimate.c -- see estimate.h: error_estimates.polynomial_estimate, operation for operation. */
#include <math.h>

#include "estimate.h"
#include "pyfloat.h"

#define PI 3.141592653589793 /* math.pi */

/* Python's sum() of floats (builtin_sum_impl): 0 + the first, then each added, with Neumaier's compensation from
   CPython 3.12 on; 0.0 for none (Python's int 0, which the callers add to a float) */
static double py_sum(const double *values, int n, int compensated)
{
    if (n == 0) return 0.0;
    double total = 0.0 + values[0], c = 0.0;
    for (int i = 1; i < n; i++) {
        const double x = values[i];
        if (!compensated) {
            total += x;
            continue;
        }
        const double t = total + x;
        if (fabs(total) >= fabs(x))
            c += (total - t) + x;
        else
            c += (x - t) + total;
        total = t;
    }
    if (compensated && c != 0.0 && isfinite(c)) total += c;
    return total;
}

/* 1.0 / complex(re, im) (CPython's _Py_c_quot with a = 1 + 0i); 1 where Python raises ZeroDivisionError */
static int py_inverse(double re, double im, double *qr, double *qi)
{
    const double abs_re = re < 0 ? -re : re, abs_im = im < 0 ? -im : im;
    if (abs_re >= abs_im) {
        if (abs_re == 0.0) return 1;
        const double ratio = im / re, denom = re + im * ratio;
        *qr = (1.0 + 0.0 * ratio) / denom;
        *qi = (0.0 - 1.0 * ratio) / denom;
    } else if (abs_im >= abs_re) {
        const double ratio = re / im, denom = re * ratio + im;
        *qr = (1.0 * ratio + 0.0) / denom;
        *qi = (0.0 * ratio - 1.0) / denom;
    } else {
        *qr = *qi = NAN;
    }
    return 0;
}

/* abs(complex) (CPython's _Py_c_abs); 1 where Python raises OverflowError */
static int py_complex_abs(double re, double im, double *value)
{
    if (!isfinite(re) || !isfinite(im)) {
        if (isinf(re)) *value = fabs(re);
        else if (isinf(im)) *value = fabs(im);
        else *value = NAN;
        return 0;
    }
    *value = hypot(re, im);
    return !isfinite(*value);
}

/* x ** w for a float w (float_pow): pyfloat.c's vk_python_pow; 1 where Python raises or hands back a complex (a
   negative x to a non-integer power, 0 to a negative one, an overflow from finite operands) */
static int py_pow(double x, double w, double *value)
{
    int fault = FAULT_NONE;
    *value = vk_python_pow(x, w, &fault);
    return fault != FAULT_NONE;
}

static double hypot2(double a, double b)
{
    const double values[2] = {a, b};
    return vk_python_hypot(values, 2);
}

/* error_estimates.local_growth: |sum_j series[j] (i theta)^j| */
static double local_growth(const double *k, double theta)
{
    const double *c = k + PC_SERIES, t2 = theta * theta;
    const double real = c[0] - t2 * (c[2] - t2 * (c[4] - t2 * c[6]));
    const double imaginary = theta * (c[1] - t2 * (c[3] - t2 * (c[5] - t2 * c[7])));
    return hypot2(real, imaginary);
}

typedef struct {
    double x_s, a1, p, mu, mu_eff, memory, free;
    int n_forced;
    double forced[3][2]; /* (abs(z), s) */
} Parts;

/* error_estimates.linear_gain(k1, mu, s) */
static int gain(double k1, double mu, double s, double *re, double *im)
{
    return py_inverse(k1 - s * s, mu * s, re, im);
}

/* error_estimates.response_parts */
static int response_parts(const double *in, Parts *r)
{
    const double mu = in[PE_MU], span = in[PE_SPAN], gamma = in[PE_GAMMA], Omega = in[PE_BIG_OMEGA];
    r->a1 = in[PE_A1];
    r->mu = mu;
    r->memory = mu <= 0.0 ? span : py_min(span, 2.0 / mu);
    if (r->memory == 0.0 || r->a1 == 0.0) return 1; /* ZeroDivisionError */
    r->mu_eff = 2.0 / r->memory;
    r->p = sqrt(py_max(r->a1 - 0.25 * mu * mu, 1e-300));
    r->x_s = gamma / r->a1;
    double dx = in[PE_X_START] - r->x_s, dv = in[PE_V_START];
    const double drives[3][3] = {{in[PE_DELTA], 0.0, in[PE_OMEGA]}, {0.0, -in[PE_BETA], Omega},
                                 {-gamma, 0.0, 2.0 * Omega}};
    r->n_forced = 0;
    for (int i = 0; i < 3; i++) {
        double hr, hi, modulus;
        if (gain(r->a1, r->mu_eff, drives[i][2], &hr, &hi)) return 1;
        const double zr = drives[i][0] * hr - drives[i][1] * hi, zi = drives[i][0] * hi + drives[i][1] * hr;
        if (zr != 0.0 || zi != 0.0) {
            if (py_complex_abs(zr, zi, &modulus)) return 1;
            r->forced[r->n_forced][0] = modulus;
            r->forced[r->n_forced][1] = drives[i][2];
            r->n_forced++;
            dx -= zr;
            dv += drives[i][2] * zi;
        }
    }
    r->free = hypot2(dx, (dv + 0.5 * mu * dx) / r->p);
    return 0;
}

/* error_estimates._remembered */
static int remembered(double s, const Parts *r, double *value)
{
    const double distance = hypot2(s - r->p, 0.5 * r->mu);
    if (distance * r->memory <= 1.0) {
        *value = r->memory;
        return 0;
    }
    if (distance == 0.0) return 1;
    *value = 1.0 / distance;
    return 0;
}

/* error_estimates.solver_terms (AdaptiveEstimator(...).terms(rtol) or the fixed step's) */
static int solver_terms(const double *in, const double *k, const Parts *r, int compensated, double *out)
{
    double amplitudes[4] = {0}, frequencies[4] = {0}, forced[3] = {0};
    for (int i = 0; i < r->n_forced; i++) forced[i] = r->forced[i][0];
    amplitudes[0] = r->free + py_sum(forced, r->n_forced, compensated); /* _components */
    frequencies[0] = r->p;
    for (int i = 0; i < r->n_forced; i++) {
        amplitudes[i + 1] = r->forced[i][0];
        frequencies[i + 1] = r->forced[i][1];
    }
    const int n = r->n_forced + 1;
    const double size = fabs(r->x_s) + py_sum(amplitudes, n, compensated);
    double remember[4] = {0};
    for (int i = 0; i < n; i++)
        if (remembered(frequencies[i], r, &remember[i])) return 1;
    if (in[PE_FIXED] != 0.0) {
        const double h = in[PE_STEP];
        double accumulated = 0.0;
        for (int i = 0; i < n; i++) {
            double s5, h4;
            if (py_pow(frequencies[i], 5.0, &s5) || py_pow(h, 4.0, &h4)) return 1;
            accumulated += amplitudes[i] * py_min(2.0, s5 * h4 / 120.0 * remember[i]);
        }
        out[PO_SOLVER] = k[PC_FIXED] * accumulated;
        out[PO_ACCUMULATED] = accumulated;
        out[PO_SIZE] = size;
        return 0;
    }
    const double scale_x = 0.01 + size;
    double velocities[4] = {0}, shares[4] = {0}, estimators[4] = {0};
    for (int i = 0; i < n; i++) velocities[i] = amplitudes[i] * frequencies[i];
    const double scale_v = 0.01 + py_sum(velocities, n, compensated);
    for (int i = 0; i < n; i++) { /* AdaptiveEstimator: the free part the test equation's, a forced one by its share */
        if (i == 0) {
            shares[i] = 1.0;
        } else { /* stiffness_share */
            const double stiffness = py_max(r->a1, 0.0), s2 = frequencies[i] * frequencies[i];
            shares[i] = s2 <= stiffness ? 1.0 : stiffness / s2;
        }
        estimators[i] = k[PC_FORCED_ESTIMATOR] + (k[PC_ESTIMATOR] - k[PC_FORCED_ESTIMATOR]) * shares[i];
    }
    const double factor = in[PE_FACTOR];
    const double rtol = factor == 1.0 ? in[PE_RTOL] : py_max(k[PC_MIN_RTOL], in[PE_RTOL] * factor);
    double h = in[PE_CEILING];
    for (int i = 0; i < n; i++) {
        const double a = amplitudes[i], s = frequencies[i];
        if (!(a > 0.0 && s > 0.0)) continue;
        if (scale_x == 0.0 || scale_v == 0.0) return 1;
        const double weight = estimators[i] * a * hypot2(1.0 / scale_x, s / scale_v) / sqrt(2.0);
        double root;
        if (weight == 0.0 || py_pow(k[PC_TARGET] * rtol / weight, 0.125, &root)) return 1;
        h = py_min(h, root / s);
    }
    double accumulated = 0.0, local = 0.0;
    for (int i = 0; i < n; i++) {
        const double a = amplitudes[i], s = frequencies[i], theta = s * h;
        double p9, p8;
        if (py_pow(theta, 9.0, &p9) || py_pow(theta, 8.0, &p8) || h == 0.0) return 1;
        const double constant = k[PC_FORCED_LOCAL] + (k[PC_LOCAL] * local_growth(k, theta) - k[PC_FORCED_LOCAL])
                                * shares[i];
        accumulated += a * py_min(2.0, constant * p9 / h * remember[i]);
        local = py_max(local, a * estimators[i] * p8);
    }
    out[PO_SOLVER] = k[PC_ADAPTIVE] * accumulated + k[PC_LOCAL_FACTOR] * local;
    out[PO_ACCUMULATED] = accumulated;
    out[PO_LOCAL] = local;
    out[PO_STEP] = h;
    out[PO_SIZE] = size;
    return 0;
}

/* error_estimates.force_error_samples' sampler at the cycle (x_s, amplitude, lo, hi) */
static int samples(const double *in, const double *cosines, int n, double center, double amplitude, double lo,
                   double hi, double *statics, double *electrostatics)
{
    const double *a = in + PE_POLY, *g = in + PE_G3, alpha = in[PE_ALPHA], gamma = in[PE_GAMMA];
    const double three_r = 3.0 * in[PE_R];
    for (int i = 0; i < n; i++) {
        double x = center + amplitude * cosines[i];
        x = lo > x ? lo : x;
        x = hi < x ? hi : x;
        const double s = 1.0 + 2.0 * x / 3.0;
        const double u = 2.0 * x / three_r;
        const double below = (1.0 - u) * (1.0 - u), above = (1.0 + u) * (1.0 + u);
        if (below == 0.0 || above == 0.0) return 1;
        const double f3 = 1.0 / below;
        statics[i] = 1.0 - (s > 0.0 ? s * sqrt(s) : 0.0) + alpha * (f3 - 1.0 / above) + gamma * f3
                     + (a[0] + x * (a[1] + x * (a[2] + x * (a[3] + x * (a[4] + x * a[5])))));
        electrostatics[i] = f3 - (g[0] + x * (g[1] + x * (g[2] + x * (g[3] + x * (g[4] + x * g[5])))));
    }
    return 0;
}

/* error_estimates.force_error_harmonics: (mean, stiffness, rest); with_rest 0: the stiffness alone */
static int harmonics(const double *in, const double *k, double x_s, double amplitude, int with_rest, double low,
                     double high, int compensated, double result[3])
{
    const int n = (int)k[PC_N_COSINES];
    const double *cosines = k + PC_COSINES;
    const double lo = -1.5 + 1e-9, hi = 1.5 * in[PE_R] * (1.0 - 1e-3);
    double a_parts[PC_MAX_COSINES] = {0}, b_parts[PC_MAX_COSINES] = {0}, products[PC_MAX_COSINES] = {0};
    if (n < 1 || n > PC_MAX_COSINES) return 1;
    if (samples(in, cosines, n, x_s, amplitude, lo, hi, a_parts, b_parts)) return 1;
    const double scale = amplitude > 0.0 ? 2.0 / n / amplitude : 0.0;
    for (int i = 0; i < n; i++) products[i] = a_parts[i] * cosines[i];
    const double k_a = scale * py_sum(products, n, compensated);
    for (int i = 0; i < n; i++) products[i] = b_parts[i] * cosines[i];
    const double k_b = scale * py_sum(products, n, compensated);
    result[1] = py_max(fabs(k_a + low * k_b), fabs(k_a + high * k_b));
    if (!with_rest) {
        result[0] = result[2] = NAN;
        return 0;
    }
    const double mean_a = py_sum(a_parts, n, compensated) / n, mean_b = py_sum(b_parts, n, compensated) / n;
    result[0] = py_max(fabs(mean_a + low * mean_b), fabs(mean_a + high * mean_b));
    double rest = 0.0;
    for (int i = 0; i < n; i++) {
        const double ra = a_parts[i] - mean_a - k_a * amplitude * cosines[i];
        const double rb = b_parts[i] - mean_b - k_b * amplitude * cosines[i];
        double value = fabs(ra + low * rb);
        if (value > rest) rest = value;
        value = fabs(ra + high * rb);
        if (value > rest) rest = value;
    }
    result[2] = rest;
    return 0;
}

/* error_estimates.drive_ends: min and max of the AC drive over TRUNCATION_TIMES phases */
static int drive_ends(const double *in, const double *k, double *low, double *high)
{
    const double beta = in[PE_BETA], gamma = in[PE_GAMMA], Omega = in[PE_BIG_OMEGA];
    const int ac = (beta != 0.0 || gamma != 0.0) && Omega > 0.0;
    const int times = ac ? (int)k[PC_TIMES] : 1;
    int fault = 0;
    for (int j = 0; j < times; j++) {
        const double t = ac ? PI / Omega * j / (int)k[PC_TIMES] : 0.0;
        const double w = beta * py_sin(Omega * t, &fault) - gamma * py_cos(2.0 * Omega * t, &fault);
        if (j == 0) {
            *low = *high = w;
        } else {
            *low = py_min(*low, w);
            *high = py_max(*high, w);
        }
    }
    return fault != 0;
}

/* error_estimates.truncation_terms */
static int truncation_terms(const double *in, const double *k, const Parts *r, int compensated, double *out)
{
    double forced[3] = {0};
    for (int i = 0; i < r->n_forced; i++) forced[i] = r->forced[i][0];
    const double f = py_sum(forced, r->n_forced, compensated), free = r->free, mu = r->mu, a1 = r->a1;
    const double amplitude = f + free;
    double low = 0.0, high = 0.0, full[3], smaller[3];
    if (drive_ends(in, k, &low, &high)) return 1;
    if (harmonics(in, k, r->x_s, amplitude, 1, low, high, compensated, full)) return 1;
    const double mean = full[0], stiffness = full[1], rest = full[2];
    double memory = r->memory;
    if (free > 0.0 && mu > 0.0 && stiffness > 0.0) {
        const double half = f + 0.5 * free;
        if (harmonics(in, k, r->x_s, half, 0, low, high, compensated, smaller)) return 1;
        double kk = 0.0;
        if (smaller[1] > 0.0) {
            const double ratio = stiffness / smaller[1], spread = amplitude / half;
            if (!(ratio > 0.0) || !(spread > 0.0)) return 1; /* math.log: ValueError (a NaN passes in Python) */
            const double denominator = log(spread);
            if (denominator == 0.0) return 1;
            kk = log(ratio) / denominator;
        }
        const double scaled = py_max(kk, 1.0) * mu;
        if (scaled == 0.0) return 1;
        memory = py_min(memory, 2.0 / scaled);
    }
    double drift = free * py_min(2.0, stiffness / (2.0 * r->p) * memory);
    for (int i = 0; i < r->n_forced; i++) {
        double hr, hi, modulus;
        if (gain(a1, r->mu_eff, r->forced[i][1], &hr, &hi) || py_complex_abs(hr, hi, &modulus)) return 1;
        drift += r->forced[i][0] * py_min(2.0, stiffness * modulus);
    }
    const double harmonic = rest / (3.0 * a1);
    out[PO_TRUNCATION] = mean / a1 + drift + harmonic;
    out[PO_MEAN] = mean / a1;
    out[PO_STIFFNESS] = drift;
    out[PO_HARMONICS] = harmonic;
    out[PO_AMPLITUDE] = fabs(r->x_s) + amplitude;
    return 0;
}

int vk_polynomial_estimate(const double *in, const double *constants, int compensated, double *out)
{
    Parts r;
    if ((int)constants[PC_N_COSINES] > PC_MAX_COSINES) return 1;
    if (response_parts(in, &r)) return 1;
    if (solver_terms(in, constants, &r, compensated, out)) return 1;
    return truncation_terms(in, constants, &r, compensated, out);
}

int vk_solver_estimate(const double *in, const double *constants, int compensated, double *out)
{
    Parts r;
    if (response_parts(in, &r)) return 1;
    return solver_terms(in, constants, &r, compensated, out);
}
