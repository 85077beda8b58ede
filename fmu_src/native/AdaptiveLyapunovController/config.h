/* config.h -- the native controller FMU AdaptiveLyapunovController: its identifier and model data (plain data). */
#ifndef ADAPTIVE_LYAPUNOV_CONTROLLER_CONFIG_H
#define ADAPTIVE_LYAPUNOV_CONTROLLER_CONFIG_H

#include "controller.h"

#define MODEL_IDENTIFIER "AdaptiveLyapunovController"
#define STATE_FORMAT "AdaptiveLyapunovController native state 2"

typedef struct {
    int64_t built;    /* the controller below is set up (after a successful fmi2ExitInitializationMode) */
    VcController c;   /* constants, estimates, held inputs, outputs (no pointers) */
} ModelData;

#endif
