/* config.h -- the native closed-loop FMU HertzEAClosedLoop: its identifier and model data (plain data). */
#ifndef HERTZEA_CLOSED_LOOP_CONFIG_H
#define HERTZEA_CLOSED_LOOP_CONFIG_H

#include "closedloop.h"  /* fmu_src/core: the compiled closed loop */

#define MODEL_IDENTIFIER "HertzEAClosedLoop"
#define STATE_FORMAT "HertzEAClosedLoop native state 3"

typedef struct {
    int64_t built;      /* the loop below is set up (after a successful fmi2ExitInitializationMode) */
    int64_t reference;  /* index of the packed reference (reference.h) the loop uses */
    VlLoop loop;        /* model, controller, solver, outputs; loop.reference points into reference.h's constant
                           tables and is re-pointed from `reference` before every use (a state may come from
                           another process) */
} ModelData;

#endif
