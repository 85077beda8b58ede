/*
 * openloop_plant.h -- the plant's doStep at fidelities 3 (averaged slow flow) and 4 (OAFM analytic) in C:
 * vibromodel.plant.Plant.do_step for a plant whose state is a function of time (no integrator, input 0).
 *
 * One step from the communication point t over h: the checks (h finite and > 0, U = 0, t the plant's time),
 * then (x, x', x'') at t + h from slowflow_eval or oafm_eval, then the outputs x, v, a and the exact model's
 * F_contact, F_electrostatic (plant.c's vk_outputs_at on core/model.c, the one C home of Eq. 3's forces), all
 * at the new communication point t + h.  Whatever the C code does not do itself -- a refused step, a time beyond the slow
 * flow's table, a non-finite output -- returns a nonzero code and changes nothing: the FMU then takes the
 * Python path (vibromodel.compiled_open_loop), which raises the matching error or extends the table.
 */
#ifndef OPENLOOP_PLANT_H
#define OPENLOOP_PLANT_H

#include <stddef.h>
#include <stdint.h>

#include "plant.h"
#include "oafm_eval.h"
#include "slowflow_eval.h"

enum {
    OL_REFUSED = 20,     /* a check failed: the Python plant raises the ParameterError */
    OL_BEYOND = 21,      /* fidelity 3: t + h is beyond the slow flow's table */
    OL_NONFINITE = 22    /* an output would not be finite */
};

typedef struct {
    VkPlant plant;       /* the exact model's constants, plant_t, U_input, out[], in_contact, enabled, error */
    int64_t fidelity;    /* an open-loop level (3, 4): its evaluator is fidelity.h's VK_FIDELITIES[fidelity] */
    SfTable slowflow;    /* VK_EVALUATOR_SLOWFLOW (fidelity 3) */
    OeSolution oafm;     /* VK_EVALUATOR_OAFM (fidelity 4) */
} OlPlant;

/* (x, x', x'') at tau into xva: 0, or OL_BEYOND. */
int vk_open_loop_state(const OlPlant *p, double tau, double *xva);
/* Plant.do_step(t, h, U_input): 0 (outputs written, plant_t = t + h) or a nonzero code, nothing changed. */
int vk_open_loop_do_step(OlPlant *p, double t, double h);
/* The compiled floor of fidelities 3 and 4: n do_steps of dt from plant_t, x after each into x_out; stops at the
   first nonzero code and returns it; *done = the steps done. */
int vk_open_loop_run(OlPlant *p, double dt, size_t n, double *x_out, size_t *done);
/* sizeof(OlPlant), sizeof(OePiece), offsetof(OlPlant, slowflow), offsetof(OlPlant, oafm) into sizes[0..3]. */
void vk_open_loop_layout(int64_t *sizes);

#endif
