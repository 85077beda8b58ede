/* series.h -- the coefficients of Eq. 7 and the series (5) for the polynomial fidelities 1 and 2. */
#ifndef VIBRO_SERIES_H
#define VIBRO_SERIES_H

/* poly = a0..a5 of Eq. 7 (corrected Eq. 8, or as printed when printed != 0), g1..g3 = the series (5), as
   vibromodel.forces computes them, operation for operation (R^k is pow, as Python's float **). */
void vibro_series(int printed, double alpha, double gamma, double R, double poly[6], double g1[6], double g2[6],
                  double g3[6]);

#endif
