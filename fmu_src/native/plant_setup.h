/* plant_setup.h -- the plant model's constants (compiled._model_fields) and plant.rk4_drive_warnings from an FMU's
   parameters, shared by the native plant and the native closed loop (both have the scene's parameters). */
#ifndef PLANT_SETUP_H
#define PLANT_SETUP_H

#include "fmi2_native.h"

/* The compiled model of `fidelity` (fidelity.h: VK_FIDELITIES[fidelity].model, which must not be VK_MODEL_NONE) of
   the scene in s->value into *m (other fields untouched). */
void native_plant_model(VkModel *m, const State *s, int fidelity);
/* plant.rk4_drive_warnings: the forcing terms RK4 steps of max_step do not resolve, logged as fmi2Warning. */
void native_rk4_drive_warnings(Instance *inst, const State *s, double max_step);

#endif
