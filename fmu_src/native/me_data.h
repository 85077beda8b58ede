/* me_data.h -- the Model Exchange (and FMI 3.0 early-return) part of a native model's state: plain data, kept in
   the model's ModelData (config.h) so that the FMU state holds it.  The hooks that use it: me_model.h. */
#ifndef ME_DATA_H
#define ME_DATA_H

#include <stdint.h>

#define ME_MAX_STATES 16
#define ME_MAX_INDICATORS 4

/* The Model Exchange modes after initialisation (0: the instance is not in Model Exchange use) */
enum { ME_OFF = 0, ME_EVENT_MODE = 1, ME_CONTINUOUS_TIME_MODE = 2, ME_TERMINATED = 3 };

typedef struct {
    int64_t mode;                  /* ME_*: an instance of fmuType Model Exchange after fmi2ExitInitializationMode */
    int64_t stopped;               /* a terminal event (pull-in) was handled: terminateSimulation */
    double t;                      /* the time fmi2SetTime gave */
    double x[ME_MAX_STATES];       /* the continuous states fmi2SetContinuousStates gave */
    /* FMI 3.0 co-simulation with early return: the solver's last step ended on an event at event_t (pending while
       the solver is still there) */
    int64_t event_pending;
    double event_t;
    double reached;                /* the time the last doStep reached */
    int64_t step_event;            /* it ended on an event (early when reached < t + h) */
    int64_t locals_stale;          /* the values computed on demand need computing (model_lazy_locals: the
                                      closed loop's der(...); model_lazy_outputs: the plant's x'' and forces) */
} MeData;

#endif
