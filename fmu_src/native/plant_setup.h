/* plant_setup.h -- the plant model's constants (what compiled.fill_model takes from the scene's own model) and plant.rk4_drive_warnings from an FMU's
   parameters, shared by the native plant and the native closed loop (both have the scene's parameters). */
#ifndef PLANT_SETUP_H
#define PLANT_SETUP_H

#include "fmi2_native.h"
#include "solver.h"

/* The compiled model of `fidelity` (fidelity.h: VK_FIDELITIES[fidelity].model, which must not be VK_MODEL_NONE) of
   the scene in s->value into *m (other fields untouched). */
void native_plant_model(VkModel *m, const State *s, int fidelity);
/* models.DRIVE_STEP_TURN (tests/model/test_rung_domains.py checks that they are equal) */
#define NATIVE_DRIVE_STEP_TURN 4.0
/* models.drive_step_ceiling: the adaptive solver's step ceiling when max_step = 0, NATIVE_DRIVE_STEP_TURN over the
   fastest forcing term switched on (omega if Delta != 0, Omega if beta != 0, 2 Omega if gamma != 0) and `extra` (a
   closed loop's reference); INFINITY when none. */
double native_drive_ceiling(const State *s, double extra);
/* models.error_memory: 2/mu (INFINITY for mu = 0), or the span stop - start of fmi2SetupExperiment if declared, > 0
   and shorter. */
double native_error_memory(const State *s);
/* models.tolerance_factor: RULE_ERROR_MEMORY_REFERENCE / native_error_memory, within [RULE_TOLERANCE_FACTOR_FLOOR, 1]:
   the adaptive plant's solver runs at rtol times it (not below RULE_MIN_RTOL). */
double native_tolerance_factor(const State *s);
/* settings.checked_settings's drive warnings for a solver that has them (solver->drive_gain_x: RK4): the forcing
   terms its steps of max_step do not resolve (plant.rk4_drive_warnings), logged as fmi2Warning; none for another. */
void native_drive_warnings(Instance *inst, const State *s, const VkSolverOps *solver, double max_step);
/* error_estimates.exact_estimate / polynomial_estimate of the scene in s->value (the level's, fidelity.h), to 3
   significant digits as the Python FMU publishes it (error_estimates.round_estimate): the solver's error at rtol (the
   rtol asked, clamped) or RK4's step, and for a polynomial level the truncation of its forces. */
double native_error_estimate(const State *s, int fidelity, double rtol, int fixed_step);
/* After a doStep from t: 1 when the n outputs out[i] (value references vrs[i]) are finite; else 0, with the status
   shim's fast_outputs_checked error logged (fmi2Error naming the first non-finite one). */
int native_step_outputs_finite(Instance *inst, const double *out, const fmi2ValueReference *vrs, int n, double t);

#endif
