/* plant_setup.h -- the plant model's constants (compiled._model_fields) and plant.rk4_drive_warnings from an FMU's
   parameters, shared by the native plant and the native closed loop (both have the scene's parameters). */
#ifndef PLANT_SETUP_H
#define PLANT_SETUP_H

#include "fmi2_native.h"
#include "solver.h"

/* The compiled model of `fidelity` (fidelity.h: VK_FIDELITIES[fidelity].model, which must not be VK_MODEL_NONE) of
   the scene in s->value into *m (other fields untouched). */
void native_plant_model(VkModel *m, const State *s, int fidelity);
/* settings.checked_settings's drive warnings for a solver that has them (solver->drive_gain_x: RK4): the forcing
   terms its steps of max_step do not resolve (plant.rk4_drive_warnings), logged as fmi2Warning; none for another. */
void native_drive_warnings(Instance *inst, const State *s, const VkSolverOps *solver, double max_step);

#endif
