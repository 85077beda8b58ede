/* controller_setup.h -- control.Controller's constants from an FMU's parameters, by core/controller.c's
   vk_controller_constants (as compiled_loop.fill_controller does for the pythonfmu FMUs), shared by the native controller and
   the native closed loop (both have the controller's parameters). */
#ifndef CONTROLLER_SETUP_H
#define CONTROLLER_SETUP_H

#include "fmi2_native.h"

/* Zero *c, then its constants from the parameters in s->value (and t = start time, theta^ = the initial
   estimates, enabled = 1 for the controller FMU's own use). */
void native_controller_constants(VcController *c, const State *s);

#endif
