/* config.h -- the native plant FMU HertzEAOscillator: its identifier and its model data (plain data). */
#ifndef HERTZEA_OSCILLATOR_CONFIG_H
#define HERTZEA_OSCILLATOR_CONFIG_H

#include "me_data.h" /* Model Exchange and early return (me_model.h) */
#include "plant.h"  /* fmu_src/core: the compiled plant */

#define MODEL_IDENTIFIER "HertzEAOscillator"
#define STATE_FORMAT "HertzEAOscillator native state 4"
/* Model Exchange (fmi2_me.c, me_model.h): states (x, v); event indicators contact 1 + 2x/3, upper gap, lower gap */
/* Model Exchange beside Co-Simulation (fmi2_me.c): fmi2Instantiate accepts both */
#define NATIVE_FMU_TYPES (FMI2_TYPE_BIT(fmi2CoSimulation) | FMI2_TYPE_BIT(fmi2ModelExchange))
#define ME_N_STATES 2
#define ME_N_INDICATORS 3
/* FMI 3.0 co-simulation returns early at contact loss and re-contact (model_do_step_early) */
#define HAS_EARLY_RETURN 1
/* fmi2/3GetDirectionalDerivative: the analytic partials of x, v, a, F_contact, F_electrostatic by x, v, U */
#define HAS_DIRECTIONAL_DERIVATIVES 1
/* after a doStep, x'' and the forces are computed when read (model_lazy_outputs; flag: model.me.locals_stale) */
#define MODEL_LAZY_OUTPUTS 1

typedef struct {
    int64_t built;  /* the kernel below is set up (after a successful fmi2ExitInitializationMode) */
    VkPlant plant;  /* the compiled plant: model, integrator, outputs (no pointers) */
    MeData me;      /* Model Exchange, early return */
} ModelData;

#endif
