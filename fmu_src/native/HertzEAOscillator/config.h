/* config.h -- the native plant FMU HertzEAOscillator: its identifier and its model data (plain data). */
#ifndef HERTZEA_OSCILLATOR_CONFIG_H
#define HERTZEA_OSCILLATOR_CONFIG_H

#include "plant.h"  /* fmu_src/core: the compiled plant */

#define MODEL_IDENTIFIER "HertzEAOscillator"
#define STATE_FORMAT "HertzEAOscillator native state 3"

typedef struct {
    int64_t built;  /* the kernel below is set up (after a successful fmi2ExitInitializationMode) */
    VkPlant plant;  /* the compiled plant: model, integrator, outputs (no pointers) */
} ModelData;

#endif
