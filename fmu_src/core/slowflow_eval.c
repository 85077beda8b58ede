/* slowflow_eval.c -- see slowflow_eval.h for the formulas. */
#include <math.h>

#include "slowflow_eval.h"

/* SlowFlowSolution._reconstruct: x = x_e + p + y2 + psi and its exact derivatives from A, B and theirs. */
static void reconstruct(const SfTable *T, double t, double A, double B, double dA, double dB, double ddA,
                        double ddB, double *xva)
{
    double w = T->omega;
    double c = cos(w * t), sn = sin(w * t);
    double p = A * c + B * sn, q = A * sn - B * c;
    double dp = dA * c + dB * sn - w * q, dq = dA * sn - dB * c + w * p;
    double ddp = ddA * c + ddB * sn - 2 * w * (dA * sn - dB * c) - w * w * p;
    double ddq = ddA * sn - ddB * c + 2 * w * (dA * c + dB * sn) - w * w * q;
    double h = T->harmonic, m = T->mean_shift;
    double x = T->x_e + p + h * (p * p - q * q) - m * (A * A + B * B);
    double v = dp + 2 * h * (p * dp - q * dq) - 2 * m * (A * dA + B * dB);
    double a = ddp + 2 * h * (dp * dp + p * ddp - dq * dq - q * ddq) - 2 * m * (dA * dA + A * ddA + dB * dB + B * ddB);
    if (T->ac) {  /* psi of Eq. 46: P sin Wt + Q cos 2Wt */
        double P = T->psi_sin, Q = T->psi_cos, W = T->Omega;
        double s1 = sin(W * t), c1 = cos(W * t);
        double s2 = 2.0 * s1 * c1, c2 = c1 * c1 - s1 * s1;
        x += P * s1 + Q * c2;
        v += W * (P * c1 - 2.0 * Q * s2);
        a -= W * W * (P * s1 + 4.0 * Q * c2);
    }
    xva[0] = x;
    xva[1] = v;
    xva[2] = a;
}

int vk_slowflow_state(const SfTable *T, double t, double *xva)
{
    if (!(t <= T->t_end)) return 1;
    double u = (t - T->t0) / T->spacing;
    double last = (double)(T->first + T->n_cells - 1);
    double fi = trunc(u) < last ? trunc(u) : last;  /* min(int(u), first + n - 1) */
    int64_t i = (int64_t)fi;
    double s = u - fi;
    if (i < T->first) return 1;
    const double *k = T->cells + 8 * (i - T->first);
    double a0 = k[0], a1 = k[1], a2 = k[2], a3 = k[3], b0 = k[4], b1 = k[5], b2 = k[6], b3 = k[7];
    double g = 1.0 / T->spacing;
    reconstruct(T, t, a0 + s * (a1 + s * (a2 + s * a3)), b0 + s * (b1 + s * (b2 + s * b3)),
                g * (a1 + s * (2 * a2 + 3 * s * a3)), g * (b1 + s * (2 * b2 + 3 * s * b3)),
                g * g * (2 * a2 + 6 * s * a3), g * g * (2 * b2 + 6 * s * b3), xva);
    return 0;
}
