/*
 * closedloop.h -- plant + adaptive controller + reference as one system (vibromodel/closedloop.py), compiled.
 *
 * State y = (x, v, theta^[9]): x' = v, v' = the plant model's x'' (Eq. 3 or Eq. 7) with U the control law
 * (Eq. 78 corrected), theta^' = the update law (Eq. 81 corrected) -- both controller.c's; the reference x~ is the
 * OAFM closed form evaluated by oafm_eval.c at every stage. Per stage: reference, U and theta^', then x''.
 * do_step: pre-checks, the integrator to t + h, then the outputs at t + h: x, v, x~, U, e1, e2, V (Eq. 76),
 * V' by the chain rule, the V' the law promises (Eq. 85), theta^.
 *
 * Layout: the constants (model, controller, reference, settings) come first and are rebuilt from the FMU's
 * parameters; everything from `t` on is the state: those bytes are the closed-loop FMU's model state.
 */
#ifndef VIBRO_CLOSEDLOOP_H
#define VIBRO_CLOSEDLOOP_H

#include <stddef.h>
#include <stdint.h>

#include "controller.h"
#include "oafm_eval.h"

#define VL_DIM 11        /* x, v, theta^[9] */
#define VL_OUTPUTS 18    /* x, v, x_ref, U, e1, e2, V, V_rate, V_rate_promised, theta^[9] */
#define VL_MESSAGE 480

#endif
