/* config.h -- the native closed-loop FMU HertzEAClosedLoop: its identifier and model data (plain data). */
#ifndef HERTZEA_CLOSED_LOOP_CONFIG_H
#define HERTZEA_CLOSED_LOOP_CONFIG_H

#include "closedloop.h"  /* fmu_src/core: the compiled closed loop */
#include "me_data.h"    /* Model Exchange (me_model.h) */

#define MODEL_IDENTIFIER "HertzEAClosedLoop"
#define STATE_FORMAT "HertzEAClosedLoop native state 4"
/* Model Exchange (fmi2_me.c, me_model.h): states (x, v, theta^[9]); event indicators contact 1 + 2x/3, upper gap,
   lower gap */
/* Model Exchange beside Co-Simulation (fmi2_me.c): fmi2Instantiate accepts both */
#define NATIVE_FMU_TYPES (FMI2_TYPE_BIT(fmi2CoSimulation) | FMI2_TYPE_BIT(fmi2ModelExchange))
#define ME_N_STATES VL_DIM
#define ME_N_INDICATORS 3
/* der(v), der(theta^_i) are computed when read (model_lazy_locals) */
#define MODEL_LAZY_LOCALS 1

typedef struct {
    int64_t built;      /* the loop below is set up (after a successful fmi2ExitInitializationMode) */
    int64_t reference;  /* index of the packed reference (reference.h) the loop uses */
    VlLoop loop;        /* model, controller, solver, outputs; loop.reference points into reference.h's constant
                           tables and is re-pointed from `reference` before every use (a state may come from
                           another process) */
    MeData me;          /* Model Exchange */
} ModelData;

#endif
