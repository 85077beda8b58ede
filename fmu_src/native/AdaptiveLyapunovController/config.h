/* config.h -- the native controller FMU AdaptiveLyapunovController: its identifier and model data (plain data). */
#ifndef ADAPTIVE_LYAPUNOV_CONTROLLER_CONFIG_H
#define ADAPTIVE_LYAPUNOV_CONTROLLER_CONFIG_H

#include "controller.h"
#include "me_data.h" /* Model Exchange (me_model.h) */

#define MODEL_IDENTIFIER "AdaptiveLyapunovController"
#define STATE_FORMAT "AdaptiveLyapunovController native state 3"
/* Model Exchange (fmi2_me.c, me_model.h): states theta^[9] (the update law's integral), no event indicators (the
   controller's right-hand side is smooth in its states, its inputs and time) */
/* Model Exchange beside Co-Simulation (fmi2_me.c): fmi2Instantiate accepts both */
#define NATIVE_FMU_TYPES (FMI2_TYPE_BIT(fmi2CoSimulation) | FMI2_TYPE_BIT(fmi2ModelExchange))
#define ME_N_STATES VC_N
#define ME_N_INDICATORS 0
/* der(theta^_i) are computed when read (model_lazy_locals) */
#define MODEL_LAZY_LOCALS 1

typedef struct {
    int64_t built;    /* the controller below is set up (after a successful fmi2ExitInitializationMode) */
    VcController c;   /* constants, estimates, held inputs, outputs (no pointers) */
    MeData me;        /* Model Exchange */
} ModelData;

#endif
