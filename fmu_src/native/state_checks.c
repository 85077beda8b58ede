/*
 * state_checks.c -- the checks of an FMU state a native FMU takes (see state_checks.h).
 *
 * A serialized state carries a checksum (FNV-1a, fmi2_native.c), which notices accidents, not a forger who
 * recomputes it: before these checks 85 of 15,000 forged states (one field changed, the checksum recomputed)
 * crashed the host (issue 25), through an index (the phase, the closed loop's reference, the solver's stage
 * count), a size or a divisor.  The rules are those of the pythonfmu FMUs' snapshots (vibromodel.compiled.
 * check_structure), generated into state_fields.h from the same ctypes layouts.
 */
#include "state_checks.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "me_model.h"
#include "state_fields.h"

_Static_assert(sizeof(((ModelData *)0)->STATE_MODEL_MEMBER) == STATE_MODEL_SIZE,
               "state_fields.h was generated for another layout of the compiled model");

static int flag(const char *name, int64_t value, int64_t low, int64_t high, char *why, size_t size)
{
    if (value >= low && value <= high) return 0;
    snprintf(why, size, "state field %s = %lld outside [%lld, %lld]", name, (long long)value, (long long)low,
             (long long)high);
    return 1;
}

/* The compiled model's fields outside its constants (state_fields.h). */
static int model_fields_refusal(const unsigned char *model, char *why, size_t size)
{
    for (size_t i = 0; i < STATE_N_FIELDS; i++) {
        const StateField *f = &STATE_FIELDS[i];
        if (f->kind == STATE_FINITE) {
            double value;
            memcpy(&value, model + f->offset, sizeof value);
            if (!isfinite(value)) {
                snprintf(why, size, "state field %s = %g is not finite", f->path, value);
                return 1;
            }
        } else if (f->kind == STATE_RANGE) {
            int64_t value;
            memcpy(&value, model + f->offset, sizeof value);
            if (flag(f->path, value, f->low, f->high, why, size)) return 1;
        } else if (memchr(model + f->offset, '\0', f->size) == NULL) {
            snprintf(why, size, "state field %s is not NUL-terminated", f->path);
            return 1;
        }
    }
    return 0;
}

/* The bytes of s and of other that decide a model's build: the parameters (every value but the outputs, inputs and
   the status), the experiment, ModelData's fields before the model and the model's constants. */
static int same_build(const State *s, const State *other)
{
    for (size_t i = 0; i < N_VARIABLES; i++)
        if (VARIABLES[i].causality == C_PARAMETER && memcmp(&s->value[i], &other->value[i], sizeof s->value[i]) != 0)
            return 0;
    if (s->start_time != other->start_time || s->has_tolerance != other->has_tolerance ||
        memcmp(&s->tolerance, &other->tolerance, sizeof s->tolerance) != 0)
        return 0;
    const size_t member = offsetof(ModelData, STATE_MODEL_MEMBER);
    const unsigned char *a = (const unsigned char *)&s->model, *b = (const unsigned char *)&other->model;
    if (memcmp(a, b, member) != 0) return 0;
    for (size_t r = 0; r < STATE_N_CONSTANTS; r++) {
        const StateRange *c = &STATE_CONSTANTS[r];
        if (memcmp(a + member + c->begin, b + member + c->begin, c->end - c->begin) != 0) return 0;
    }
    return 1;
}

/* The model's constants (and ModelData's fields before the model: built, the closed loop's reference index)
   against those the state's own parameters build. */
static int constants_refusal(const State *s, char *why, size_t size)
{
    State *fresh = malloc(sizeof *fresh);
    if (fresh == NULL) {
        snprintf(why, size, "out of memory while checking the state");
        return 1;
    }
    int refused = 0;
    if (!native_rebuild(s, fresh) || (fresh->halted && !s->halted)) {
        snprintf(why, size, "its parameters do not build a model (%.400s)", fresh->halt_message);
        refused = 1;
    } else {
        const size_t member = offsetof(ModelData, STATE_MODEL_MEMBER);
        const unsigned char *a = (const unsigned char *)&s->model, *b = (const unsigned char *)&fresh->model;
        if (memcmp(a, b, member) != 0) {
            snprintf(why, size, "its model's set-up differs from the one its parameters build");
            refused = 1;
        }
        for (size_t r = 0; !refused && r < STATE_N_CONSTANTS; r++) {
            const StateRange *c = &STATE_CONSTANTS[r];
            if (memcmp(a + member + c->begin, b + member + c->begin, c->end - c->begin) == 0) continue;
            snprintf(why, size, "its model's constants (bytes %zu to %zu of the compiled model) differ from those its "
                     "parameters build", c->begin, c->end);
            refused = 1;
        }
    }
    free(fresh);
    return refused;
}

#ifdef ME_N_STATES
static int finite_field(const char *name, double value, char *why, size_t size)
{
    if (isfinite(value)) return 0;
    snprintf(why, size, "state field %s = %g is not finite", name, value);
    return 1;
}

/* The Model Exchange and early-return block (me_data.h): its mode and flags in range, its times and states finite
   (the continuous states are the model's state when mode != ME_OFF: what getters and derivatives read), and, when
   the model is running, inside the model's domain: no pull-in event indicator (z[1] ...) at or below 0 (the states
   beyond an electrode: the model stops there, me_stop_at_pull_in; so does a co-simulation). */
static int me_refusal(const State *s, char *why, size_t size)
{
    const MeData *me = &s->model.me;
    if (flag("model.me.mode", me->mode, ME_OFF, ME_TERMINATED, why, size) ||
        flag("model.me.stopped", me->stopped, 0, 1, why, size) ||
        flag("model.me.event_pending", me->event_pending, 0, 1, why, size) ||
        flag("model.me.step_event", me->step_event, 0, 1, why, size) ||
        flag("model.me.locals_stale", me->locals_stale, 0, 1, why, size) ||
        finite_field("model.me.t", me->t, why, size) || finite_field("model.me.event_t", me->event_t, why, size) ||
        finite_field("model.me.reached", me->reached, why, size))
        return 1;
    for (int i = 0; i < ME_MAX_STATES; i++) {
        char name[32];
        snprintf(name, sizeof name, "model.me.x[%d]", i);
        if (finite_field(name, me->x[i], why, size)) return 1;
    }
    if (me->mode != ME_OFF && !s->model.built) {
        snprintf(why, size, "state field model.me.mode = %lld without a built model", (long long)me->mode);
        return 1;
    }
    return 0;
}

/* After the model's fields passed: a running state (built, not halted, not stopped) inside the domain. */
static int domain_refusal(const State *s, char *why, size_t size)
{
    if (!s->model.built || s->halted || s->model.me.stopped) return 0;
    double z[ME_MAX_INDICATORS];
    model_me_indicators(s, z);
    for (int i = 0; i < ME_N_INDICATORS; i++) {
        if (!isfinite(z[i]) || (i > 0 && z[i] <= 0.0)) {
            snprintf(why, size, "its %s (x = %g) is outside the model's domain: event indicator %d = %g%s",
                     s->model.me.mode != ME_OFF ? "state model.me.x" : "model's state", s->model.me.mode != ME_OFF
                     ? s->model.me.x[0] : s->value[VR_x], i, z[i], i > 0 ? " (at or beyond an electrode: pull-in)"
                     : "");
            return 1;
        }
    }
    return 0;
}
#endif

int native_interface_refusal(const State *s, int model_exchange, char *why, size_t size)
{
#ifdef ME_N_STATES
    const int running = s->model.built && !s->halted && s->phase == PHASE_STEP_MODE;
    if (!model_exchange && s->model.me.mode != ME_OFF) {
        snprintf(why, size, "a Model Exchange state (model.me.mode = %lld) given to a Co-Simulation instance",
                 (long long)s->model.me.mode);
        return 1;
    }
    if (model_exchange && running && s->model.me.mode == ME_OFF) {
        snprintf(why, size, "a Co-Simulation state (model.me.mode = 0 in step mode) given to a Model Exchange "
                 "instance");
        return 1;
    }
#else
    (void)s; (void)model_exchange; (void)why; (void)size;
#endif
    return 0;
}

int native_state_refusal(const State *s, const State *current, char *why, size_t size)
{
    if (flag("phase", s->phase, PHASE_INSTANTIATED, PHASE_TERMINATED, why, size) ||
        flag("initialised", s->initialised, 0, 1, why, size) || flag("halted", s->halted, 0, 1, why, size) ||
        flag("has_stop", s->has_stop, 0, 1, why, size) || flag("has_tolerance", s->has_tolerance, 0, 1, why, size) ||
        flag("model.built", s->model.built, 0, 1, why, size))
        return 1;
    if (memchr(s->halt_message, '\0', sizeof s->halt_message) == NULL) {
        snprintf(why, size, "state field halt_message is not NUL-terminated");
        return 1;
    }
    /* start_time, stop_time and tolerance are the host's (fmi2SetupExperiment: any double, refused when used) */
    const double status = s->value[VR_fmi_status];
    if (status != 0.0 && status != 3.0) {
        snprintf(why, size, "state field fmi_status = %g is neither 0 (ok) nor 3 (error)", status);
        return 1;
    }
    for (size_t i = 0; i < N_VARIABLES; i++) {
        const double v = s->value[i];
        if (VARIABLES[i].type == T_BOOLEAN && v != 0.0 && v != 1.0) {
            snprintf(why, size, "state field %s = %g is not a Boolean (0 or 1)", VARIABLES[i].name, v);
            return 1;
        }
        if (VARIABLES[i].type == T_INTEGER && !(v == trunc(v) && v >= -2147483648.0 && v <= 2147483647.0)) {
            snprintf(why, size, "state field %s = %g is not an fmi2Integer", VARIABLES[i].name, v);
            return 1;
        }
    }
    /* a model to step: built (else doStep would run an empty one) and consistent */
    if (s->phase == PHASE_STEP_MODE && !s->halted && !s->model.built) {
        snprintf(why, size, "state field model.built = 0 in step mode without a halt (no model to step)");
        return 1;
    }
#ifdef ME_N_STATES
    if (me_refusal(s, why, size)) return 1;
#endif
    if (!s->model.built) return 0; /* the model's bytes are not read before it is built */
    if (s->phase != PHASE_STEP_MODE && s->phase != PHASE_TERMINATED) {
        snprintf(why, size, "state field model.built = 1 in phase %lld (only after initialisation)",
                 (long long)s->phase);
        return 1;
    }
    if (model_fields_refusal((const unsigned char *)&s->model.STATE_MODEL_MEMBER, why, size)) return 1;
    /* current's own build (valid): the rebuild would give the same */
    const int own_build = current != NULL && current->model.built && !(current->halted && !s->halted) &&
                          same_build(s, current);
    if (!own_build && constants_refusal(s, why, size)) return 1;
#ifdef ME_N_STATES
    /* after the constants: the indicators read the model through them (the solver's dimension indexes its arrays;
       a state with dop.n = 258 read past them here -- found by tests/fuzz's state target) */
    if (domain_refusal(s, why, size)) return 1;
#endif
    return 0;
}
