/*
 * series.c -- vibromodel/forces.py's series_g1, series_g1_printed, series_g2, series_g3, coefficients and
 * coefficients_printed (the series (5) and a0..a5 of Eq. 7/8, docs/model.md, Series and polynomial model) in C for the native FMUs, the
 * same operations in the same order so that they give the same bits (tests/fmus/test_native.py checks it).
 * The Python module stays the one the pythonfmu FMUs and the harness use; this is its compiled twin for an
 * FMU without Python.
 */
#include "series.h"

#include <math.h>

void vibro_series(int printed, double alpha, double gamma, double R, double poly[6], double g1[6], double g2[6],
                  double g3[6])
{
    /* series_g1 (corrected: no R) */
    const double c1[6] = {1.0, 1.0, 1.0 / 6.0, -1.0 / 54.0, 1.0 / 216.0, -1.0 / 648.0};
    /* series_g2: G2 ~ (1 - 2x/3R)^-2 - (1 + 2x/3R)^-2 */
    g2[0] = 0.0; g2[1] = 8.0 / (3.0 * R); g2[2] = 0.0; g2[3] = 64.0 / (27.0 * pow(R, 3));
    g2[4] = 0.0; g2[5] = 128.0 / (81.0 * pow(R, 5));
    /* series_g3: G3 ~ (1 - 2x/3R)^-2 */
    g3[0] = 1.0; g3[1] = 4.0 / (3.0 * R); g3[2] = 4.0 / (3.0 * pow(R, 2)); g3[3] = 32.0 / (27.0 * pow(R, 3));
    g3[4] = 80.0 / (81.0 * pow(R, 4)); g3[5] = 64.0 / (81.0 * pow(R, 5));
    if (!printed) {
        for (int k = 0; k < 6; k++) g1[k] = c1[k];
        /* coefficients: a_k = G1_k - alpha G2_k - gamma G3_k, a0 = -gamma (corrected Eq. 8) */
        poly[0] = -gamma;
        for (int k = 1; k < 6; k++) poly[k] = c1[k] - alpha * g2[k] - gamma * g3[k];
        return;
    }
    /* series_g1_printed: G1 as printed in Eq. 5 */
    g1[0] = 1.0; g1[1] = 1.0 / R; g1[2] = 1.0 / (6.0 * pow(R, 2)); g1[3] = -1.0 / (54.0 * pow(R, 3));
    g1[4] = 1.0 / (432.0 * pow(R, 4)); g1[5] = 1.0 / (1296.0 * pow(R, 5));
    /* coefficients_printed: Eq. 8 as printed */
    poly[0] = -gamma;
    poly[1] = 1.0 - 8.0 * alpha / (3.0 * R) - 4.0 * gamma / (3.0 * R);
    poly[2] = 1.0 / 6.0 - 4.0 * gamma / (3.0 * pow(R, 2));
    poly[3] = -1.0 / 54.0 - 64.0 * alpha / (27.0 * pow(R, 3));
    poly[4] = 1.0 / 432.0 - 80.0 * gamma / (81.0 * pow(R, 5));
    poly[5] = 1.0 / 1296.0 - 128.0 * alpha / (81.0 * pow(R, 5)) - 64.0 * gamma / (81.0 * pow(R, 5));
}
