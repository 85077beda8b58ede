/* state_checks.h -- what a native FMU checks in an FMU state before it takes it (issue 25). */
#ifndef STATE_CHECKS_H
#define STATE_CHECKS_H

#include <stddef.h>

#include "fmi2_native.h"

/* 1 and why (naming the field, its value and the rule) when state s could not have been left by this FMU: a field
   that indexes, sizes or divides out of its range (the phase, the flags, the status, Integer and Boolean values, the
   compiled model's counts and switches: state_fields.h), a double of the model that is not finite, a text without
   its NUL, or a model whose constants differ from those the state's own parameters build (native_rebuild); else 0.
   Called by fmi2DeSerializeFMUstate (a forger can recompute the serialized state's checksum): the one way to a live
   state other than fmi2GetFMUstate's copy of an instance's own, so fmi2SetFMUstate does not check a state again.
   current: the instance's own state (built by it, so valid), or NULL: when s has current's parameters, experiment and
   model constants, the rebuild is skipped (it would build current's; the common case, a host rolling back). */
int native_state_refusal(const State *s, const State *current, char *why, size_t size);

/* 1 and why when state s was left by an instance of the other interface: a Model Exchange state (its ME mode set)
   given to a Co-Simulation instance, or a running Co-Simulation state given to a Model Exchange one (its continuous
   states would be stale).  Called beside native_state_refusal by fmi2DeSerializeFMUstate, and by fmi2SetFMUstate:
   a state may be set into another instance of the binary than the one that made or deserialized it. */
int native_interface_refusal(const State *s, int model_exchange, char *why, size_t size);

/* fmi2_native.c: the State that the parameters and experiment in s (inputs at their start values: they are not
   among the model's constants) build at
   fmi2ExitInitializationMode, into *fresh, in a silent scratch instance; 1 when the model was built (fresh->halted
   says whether its initialisation then failed). */
int native_rebuild(const State *s, State *fresh);

#endif
