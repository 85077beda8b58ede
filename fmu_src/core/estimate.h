/*
 * estimate.h -- vibromodel.error_estimates.polynomial_estimate (fidelities 1 and 2: the solver's error and the
 * polynomial's truncation) in C, operation for operation and with Python's float semantics (pyfloat.h), so that
 * its terms are the Python function's bits: the Python function's ~200 interpreted operations were most of the
 * estimate's cost at initialisation. Python computes what it shares with the plant's set-up (a1, the drive's step
 * ceiling, the tolerance factor) and falls back to its own code wherever Python would raise (a fault here).
 */
#ifndef VIBRO_ESTIMATE_H
#define VIBRO_ESTIMATE_H

/* in[]: the scene, the run and the settings, the polynomial's coefficients */
enum {
    PE_ALPHA, PE_GAMMA, PE_R, PE_MU, PE_DELTA, PE_OMEGA, PE_BETA, PE_BIG_OMEGA, PE_X_START, PE_V_START,
    PE_SPAN, PE_RTOL, PE_FIXED, PE_STEP, PE_CEILING, PE_FACTOR, PE_A1, PE_POLY, PE_G3 = PE_POLY + 6,
    PE_INPUTS = PE_G3 + 6
};
/* constants[]: error_estimates' constants and its cosines of the cycle's samples */
enum {
    PC_ESTIMATOR, PC_LOCAL, PC_ADAPTIVE, PC_LOCAL_FACTOR, PC_FIXED, PC_TRUNCATION, PC_MIN_RTOL, PC_TIMES,
    PC_N_COSINES, PC_FORCED_ESTIMATOR, PC_FORCED_LOCAL, PC_TARGET, PC_SERIES, PC_N_SERIES = 8,
    PC_COSINES = PC_SERIES + PC_N_SERIES, PC_MAX_COSINES = 16, PC_CONSTANTS = PC_COSINES + PC_MAX_COSINES
};
/* out[]: solver_terms' solver, accumulated, local (adaptive), step (adaptive), amplitude; truncation_terms'
   truncation, mean, stiffness, harmonics, amplitude */
enum {
    PO_SOLVER, PO_ACCUMULATED, PO_LOCAL, PO_STEP, PO_SIZE, PO_TRUNCATION, PO_MEAN, PO_STIFFNESS, PO_HARMONICS,
    PO_AMPLITUDE, PO_OUTPUTS
};

/* 0, or 1 where the Python function raises (the caller runs it then); compensated: Python's sum() adds floats
   with Neumaier's compensation (CPython 3.12 on), else one by one. */
int vk_polynomial_estimate(const double *in, const double *constants, int compensated, double *out);
/* The exact model's estimate (error_estimates.solver_terms): out[PO_SOLVER .. PO_SIZE] alone (in[]'s polynomial
   coefficients are not read); 0, or 1 where the Python function raises. */
int vk_solver_estimate(const double *in, const double *constants, int compensated, double *out);

#endif
