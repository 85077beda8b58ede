/*
 * fuzz_native.c -- libFuzzer targets of a native FMU (tests/fuzz/run.py compiles it with one model's sources:
 * fmi2_native.c, fmi2_me.c, fmi3_native.c, the model and the core, and the generated headers).
 *
 * FUZZ_CALLS: an input is a program of FMI calls with arguments taken from the input: FMI 2.0 or 3.0,
 *   Co-Simulation or Model Exchange (the first byte), then calls in any order and any state, value references in
 *   and out of range, NULL arrays, non-finite and extreme numbers, FMU states got, set, serialized and restored.
 * FUZZ_STATE: an input patches a genuine serialized FMU state (taken after a few calls) -- raw bytes, extreme
 *   doubles or integers at aligned offsets, bit flips -- the checksum recomputed so the patch reaches the state
 *   checks; the state is restored (fmi2DeSerializeFMUstate / fmi3DeserializeFMUState, then set) and used.
 *
 * Findings: AddressSanitizer / UndefinedBehaviorSanitizer reports, and the oracles (FUZZ_FAIL): a getter or
 * doStep that answers OK (or Warning) with a non-finite number, a Boolean other than 0/1, a log message with an
 * unescaped '%'.
 */
#define _DEFAULT_SOURCE /* mkdtemp */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmi2Functions.h"
#include "fmi3Functions.h"
#include "fuzz_input.h"
#include "fmi2_native.h" /* variables.h, config.h: N_VARIABLES, FMU_GUID, ME_N_STATES ... */

#ifdef ME_N_STATES
#define N_STATES ME_N_STATES
#define N_INDICATORS ME_N_INDICATORS
#else
#define N_STATES 0
#define N_INDICATORS 0
#endif
/* FMI 3.0 adds `time` (N_VARIABLES) and the event indicators as variables */
#define N_VR3 (N_VARIABLES + 1 + N_INDICATORS)
#define MAXN 12
#ifdef FUZZ_SKIP_NULL
#define NUL(cond) ((void)(cond), 0)
#else
#define NUL(cond) (cond)
#endif /* array lengths of a call: 0 .. MAXN - 1 */

static char resource_dir[256];
static int trace; /* FUZZ_TRACE=1: each call on stderr (replaying a finding) */
static char resource_uri[300];

int LLVMFuzzerInitialize(int *argc, char ***argv)
{
    (void)argc; (void)argv;
    snprintf(resource_dir, sizeof resource_dir, "/tmp/vibrofmu-fuzz-resources-XXXXXX");
    if (mkdtemp(resource_dir) == NULL) abort();
    snprintf(resource_uri, sizeof resource_uri, "file://%s", resource_dir);
    trace = getenv("FUZZ_TRACE") != NULL;
    return 0;
}

/* ---- loggers: read every byte they are given (ASan), check the escaping ---- */

static void logger2(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                    fmi2String message, ...)
{
    (void)env; (void)status;
    check_logged(name, category, message);
}

static void logger3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env; (void)status;
    if (message == NULL) FUZZ_FAIL("fmi3 log message is NULL");
    volatile size_t n = strlen(message) + (category ? strlen(category) : 0);
    (void)n;
}

/* A serialized state of `size` bytes perhaps damaged: a byte xored, the length cut; the length to restore */
static size_t in_damage(In *in, unsigned char *bytes, size_t size)
{
    uint8_t damage = in_u8(in);
    size_t len = size;
    if (damage & 1) bytes[in_u16(in) % size] ^= in_u8(in);
    if (damage & 2) len = in_u16(in) % (size + 1);
    return len;
}

/* Up to 3 log categories for SetDebugLogging, known, unknown, empty or NULL, into cats; how many */
static size_t in_categories(In *in, const char *cats[4])
{
    static const char *const CATS[] = {"logAll", "logStatusError", "logStatusWarning", "nonsense", "", NULL};
    size_t n = in_u8(in) % 4;
    for (size_t i = 0; i < n; i++) cats[i] = CATS[in_u8(in) % 6];
    return n;
}

static const fmi2CallbackFunctions CALLBACKS = {logger2, calloc, free, NULL, NULL};

/* ---- arguments ---- */

static uint32_t in_vr(In *in, uint32_t n_vr)
{
    uint8_t k = in_u8(in);
    if (k < 248) return k % (n_vr + 2);
    static const uint32_t FAR[] = {UINT32_MAX, UINT32_MAX - 1, 0x80000000u, 1000, 65535, 256, 255, 4096};
    return FAR[k % 8];
}

/* n value references (n from the input, < MAXN); NULL array when the input says so */
static size_t in_vrs(In *in, uint32_t vr[MAXN], uint32_t n_vr, int *null_vr, int *null_values)
{
    uint8_t k = in_u8(in);
    size_t n = k % MAXN;
    *null_vr = (k & 0x80) && (k & 0x40);
    *null_values = (k & 0x80) && !(k & 0x40) && (k & 0x20);
#ifdef FUZZ_SKIP_NULL /* run.py --skip-null: no NULL arrays (to look past a known NULL-argument finding) */
    *null_vr = *null_values = 0;
#endif
    for (size_t i = 0; i < n; i++) vr[i] = in_vr(in, n_vr);
    return n;
}

static void check_finite(const char *call, int ok, const double *v, size_t n)
{
    if (!ok || v == NULL) return;
    for (size_t i = 0; i < n; i++)
        if (!isfinite(v[i])) FUZZ_FAIL("%s answered OK with value[%zu] = %g", call, i, v[i]);
}

/* The value references of every Real variable (FMI 3.0: every Float64 but the event indicators -- the Reals, then
   `time`), in one array: the oracle's read of all of them in one call, which answers OK only if every value is
   finite.  (The first MAXN value references read before included fmi_status, an Integer: that call always
   failed, so its values were never checked, and logged an error per execution.) */
static size_t real_vrs(uint32_t vr[N_VARIABLES + 1], int version3)
{
    size_t n = 0;
    for (uint32_t i = 0; i < N_VARIABLES; i++)
        if (VARIABLES[i].type == T_REAL) vr[n++] = i;
    if (version3) vr[n++] = N_VARIABLES;
    return n;
}


/* ---- FMI 2.0 ---- */

typedef struct {
    fmi2Component c;
    fmi2FMUstate states[2];
    double t;
    int me;
} F2;

static void fmi2_free_all(F2 *f)
{
    for (int i = 0; i < 2; i++)
        if (f->states[i] != NULL) fmi2FreeFMUstate(f->c, &f->states[i]);
    fmi2FreeInstance(f->c);
}

#define OK2(st) ((st) == fmi2OK || (st) == fmi2Warning)

/* The whole read, after a read of the first Real (a parameter) alone: when even that is refused -- the
   instantiated state, where the getters read nothing but fmi_status, as after a refused restore -- the rest would
   be refused alike, with a log line each (30 per execution, a third of a controller state target's time). */
static void read_reals2(fmi2Component c)
{
    uint32_t vr[N_VARIABLES + 1];
    double values[N_VARIABLES + 1];
    size_t n = real_vrs(vr, 0);
    if (!OK2(fmi2GetReal(c, vr, 1, values))) return;
    check_finite("fmi2GetReal", OK2(fmi2GetReal(c, vr, n, values)), values, n);
}


static void fmi2_op(F2 *f, In *in)
{
    fmi2Component c = f->c;
    uint32_t vr[MAXN];
    double real[MAXN];
    int32_t ints[MAXN];
    fmi2Boolean bools[MAXN];
    fmi2String strs[MAXN];
    char text[MAXN][24];
    int null_vr, null_values;
    fmi2Status st;
    uint8_t op = in_u8(in);
    if (trace) fprintf(stderr, "fmi2 op %d (t %g)\n", op % 40, f->t);
    switch (op % 40) {
    case 0: {
        fmi2Boolean tol_defined = in_u8(in) & 1, stop_defined = in_u8(in) & 1;
        double tol = in_double(in), start = in_u8(in) & 1 ? in_double(in) : 0.0, stop = in_double(in);
        if (OK2(fmi2SetupExperiment(c, tol_defined, tol, start, stop_defined, stop)) && isfinite(start)) f->t = start;
        break;
    }
    case 1: fmi2EnterInitializationMode(c); break;
    case 2: fmi2ExitInitializationMode(c); break;
    case 3: case 4: case 5: {
        double t = in_u8(in) < 240 ? f->t : in_double(in), h = in_step(in);
        st = fmi2DoStep(c, t, h, in_u8(in) & 1);
        if (OK2(st)) f->t = t + h;
        break;
    }
    case 6: case 7: case 8: {
        size_t n = in_vrs(in, vr, N_VARIABLES, &null_vr, &null_values);
        st = fmi2GetReal(c, null_vr ? NULL : vr, n, null_values ? NULL : real);
        if (!null_vr && !null_values) check_finite("fmi2GetReal", OK2(st), real, n);
        break;
    }
    case 9: case 10: {
        size_t n = in_vrs(in, vr, N_VARIABLES, &null_vr, &null_values);
        for (size_t i = 0; i < n; i++) real[i] = in_double(in);
        fmi2SetReal(c, null_vr ? NULL : vr, n, null_values ? NULL : real);
        break;
    }
    case 11: {
        size_t n = in_vrs(in, vr, N_VARIABLES, &null_vr, &null_values);
        fmi2GetInteger(c, null_vr ? NULL : vr, n, null_values ? NULL : ints);
        break;
    }
    case 12: {
        size_t n = in_vrs(in, vr, N_VARIABLES, &null_vr, &null_values);
        for (size_t i = 0; i < n; i++) ints[i] = in_i32(in);
        fmi2SetInteger(c, null_vr ? NULL : vr, n, null_values ? NULL : ints);
        break;
    }
    case 13: {
        size_t n = in_vrs(in, vr, N_VARIABLES, &null_vr, &null_values);
        st = fmi2GetBoolean(c, null_vr ? NULL : vr, n, null_values ? NULL : bools);
        if (OK2(st) && !null_vr && !null_values)
            for (size_t i = 0; i < n; i++)
                if (bools[i] != fmi2True && bools[i] != fmi2False)
                    FUZZ_FAIL("fmi2GetBoolean answered OK with value[%zu] = %d", i, bools[i]);
        break;
    }
    case 14: {
        size_t n = in_vrs(in, vr, N_VARIABLES, &null_vr, &null_values);
        for (size_t i = 0; i < n; i++) bools[i] = in_u8(in) < 200 ? (in_u8(in) & 1) : in_i32(in);
        fmi2SetBoolean(c, null_vr ? NULL : vr, n, null_values ? NULL : bools);
        break;
    }
    case 15: {
        size_t n = in_vrs(in, vr, N_VARIABLES, &null_vr, &null_values);
        st = fmi2GetString(c, null_vr ? NULL : vr, n, null_values ? NULL : strs);
        if (OK2(st) && !null_vr && !null_values)
            for (size_t i = 0; i < n; i++) {
                volatile size_t len = strs[i] ? strlen(strs[i]) : 0; /* ASan: a readable string */
                (void)len;
            }
        break;
    }
    case 16: {
        size_t n = in_vrs(in, vr, N_VARIABLES, &null_vr, &null_values);
        for (size_t i = 0; i < n; i++) strs[i] = in_string(in, text[i], sizeof text[i]);
        fmi2SetString(c, null_vr ? NULL : vr, n, null_values ? NULL : strs);
        break;
    }
    case 17: { /* get into a slot (new, or overwriting the slot's) */
        int k = in_u8(in) & 1;
        fmi2GetFMUstate(c, &f->states[k]);
        break;
    }
    case 18: fmi2SetFMUstate(c, f->states[in_u8(in) & 1]); break;
    case 19: fmi2FreeFMUstate(c, &f->states[in_u8(in) & 1]); break;
    case 20: { /* serialize a slot, perhaps damage a byte, restore into a slot */
        int k = in_u8(in) & 1;
        size_t size = 0;
        if (f->states[k] == NULL || fmi2SerializedFMUstateSize(c, f->states[k], &size) != fmi2OK) break;
        fmi2Byte *bytes = malloc(size + 1);
        if (fmi2SerializeFMUstate(c, f->states[k], bytes, size) == fmi2OK) {
            size_t len = in_damage(in, (unsigned char *)bytes, size);
            fmi2DeSerializeFMUstate(c, bytes, len, &f->states[in_u8(in) & 1]);
        }
        free(bytes);
        break;
    }
    case 21: fmi2Terminate(c); break;
    case 22: fmi2Reset(c); f->t = 0.0; break;
    case 23: {
        const char *cats[4];
        size_t n = in_categories(in, cats);
        fmi2SetDebugLogging(c, in_u8(in) & 1, n, NUL((in_u8(in) & 7) == 0) ? NULL : cats);
        break;
    }
    case 24: {
        fmi2Status s2;
        fmi2Real r;
        fmi2Integer i;
        fmi2Boolean b;
        fmi2String s;
        int kind = in_u8(in) % 4, null = (in_u8(in) & 7) == 0;
        switch (in_u8(in) % 5) {
        case 0: fmi2GetStatus(c, (fmi2StatusKind)kind, NUL(null) ? NULL : &s2); break;
        case 1: fmi2GetRealStatus(c, (fmi2StatusKind)kind, NUL(null) ? NULL : &r); break;
        case 2: fmi2GetIntegerStatus(c, (fmi2StatusKind)kind, NUL(null) ? NULL : &i); break;
        case 3: fmi2GetBooleanStatus(c, (fmi2StatusKind)kind, NUL(null) ? NULL : &b); break;
        default: fmi2GetStringStatus(c, (fmi2StatusKind)kind, NUL(null) ? NULL : &s); break;
        }
        break;
    }
    case 25: {
        uint32_t known[MAXN];
        double seed[MAXN];
        int nu_null, x, nk_null, y;
        size_t nu = in_vrs(in, vr, N_VARIABLES, &nu_null, &x);
        size_t nk = in_vrs(in, known, N_VARIABLES, &nk_null, &y);
        for (size_t i = 0; i < nk; i++) seed[i] = in_double(in);
        st = fmi2GetDirectionalDerivative(c, NUL(nu_null) ? NULL : vr, nu, NUL(nk_null) ? NULL : known, nk, NUL(y) ? NULL : seed,
                                          NUL(x) ? NULL : real);
        if (!nu_null && !nk_null && !x && !y) check_finite("fmi2GetDirectionalDerivative", OK2(st), real, nu);
        break;
    }
    case 26: {
        fmi2Integer order[MAXN];
        size_t n = in_vrs(in, vr, N_VARIABLES, &null_vr, &null_values);
        for (size_t i = 0; i < n; i++) { order[i] = in_i32(in); real[i] = in_double(in); }
        if (in_u8(in) & 1) fmi2SetRealInputDerivatives(c, null_vr ? NULL : vr, n, order, null_values ? NULL : real);
        else fmi2GetRealOutputDerivatives(c, null_vr ? NULL : vr, n, order, null_values ? NULL : real);
        break;
    }
    case 27: fmi2CancelStep(c); break;
#ifdef ME_N_STATES
    /* Model Exchange (a co-simulation instance refuses them; the controller has none) */
    case 28: fmi2EnterEventMode(c); break;
    case 29: {
        fmi2EventInfo info;
        st = fmi2NewDiscreteStates(c, NUL((in_u8(in) & 7) == 0) ? NULL : &info);
        break;
    }
    case 30: fmi2EnterContinuousTimeMode(c); break;
    case 31: {
        fmi2Boolean enter, terminate;
        int null = in_u8(in);
        fmi2CompletedIntegratorStep(c, in_u8(in) & 1, NUL((null & 1)) ? NULL : &enter, NUL((null & 2)) ? NULL : &terminate);
        break;
    }
    case 32: {
        double t = in_u8(in) < 128 ? f->t + in_step(in) : in_double(in);
        if (OK2(fmi2SetTime(c, t))) f->t = t;
        break;
    }
    case 33: {
        size_t n = in_u8(in) < 224 ? N_STATES : in_u8(in) % MAXN;
        for (size_t i = 0; i < n; i++) real[i] = in_double(in);
        if (trace)
            for (size_t i = 0; i < n; i++) fprintf(stderr, "  x[%zu] = %.17g\n", i, real[i]);
        fmi2SetContinuousStates(c, NUL((in_u8(in) & 15) == 0) ? NULL : real, n);
        break;
    }
    case 34: case 35: case 36: case 37: {
        size_t want = op % 40 == 35 ? N_INDICATORS : N_STATES;
        size_t n = in_u8(in) < 224 ? want : in_u8(in) % MAXN;
        double *out = NUL((in_u8(in) & 15) == 0) ? NULL : real;
        switch (op % 40) {
        case 34: st = fmi2GetDerivatives(c, out, n); check_finite("fmi2GetDerivatives", OK2(st), out, n); break;
        case 35: st = fmi2GetEventIndicators(c, out, n); check_finite("fmi2GetEventIndicators", OK2(st), out, n); break;
        case 36: st = fmi2GetContinuousStates(c, out, n); check_finite("fmi2GetContinuousStates", OK2(st), out, n); break;
        default:
            st = fmi2GetNominalsOfContinuousStates(c, out, n);
            check_finite("fmi2GetNominalsOfContinuousStates", OK2(st), out, n);
            break;
        }
        break;
    }
#endif
    default: /* the whole output, as a host reads it after each step */
        read_reals2(c);
        break;
    }
}

static fmi2Component fmi2_instantiate(In *in, int *me)
{
    uint8_t how = in_u8(in);
    *me = (how & 1) != 0;
    fmi2Type type = *me ? fmi2ModelExchange : fmi2CoSimulation;
    if ((how & 0xf0) == 0xf0) { /* arguments out of the ordinary */
        char name[24], guid[48], uri[48];
        const char *nm = in_string(in, name, sizeof name);
        const char *g = in_u8(in) & 1 ? FMU_GUID : in_string(in, guid, sizeof guid);
        const char *u = in_u8(in) & 1 ? resource_uri : in_string(in, uri, sizeof uri);
        return fmi2Instantiate(nm, (fmi2Type)(in_u8(in) % 3), g, u, NUL((how & 2)) ? NULL : &CALLBACKS, 0, how & 4);
    }
    return fmi2Instantiate("fuzz", type, FMU_GUID, resource_uri, &CALLBACKS, 0, (how & 4) != 0);
}

/* ---- FMI 3.0 ---- */

typedef struct {
    fmi3Instance c;
    fmi3FMUState states[2];
    double t;
} F3;

#define OK3(st) ((st) == fmi3OK || (st) == fmi3Warning)

/* read_reals2's, for FMI 3.0 */
static void read_reals3(fmi3Instance c)
{
    uint32_t vr[N_VARIABLES + 1];
    double values[N_VARIABLES + 1];
    size_t n = real_vrs(vr, 1);
    if (!OK3(fmi3GetFloat64(c, vr, 1, values, 1))) return;
    check_finite("fmi3GetFloat64", OK3(fmi3GetFloat64(c, vr, n, values, n)), values, n);
}

static void fmi3_free_all(F3 *f)
{
    for (int i = 0; i < 2; i++)
        if (f->states[i] != NULL) fmi3FreeFMUState(f->c, &f->states[i]);
    fmi3FreeInstance(f->c);
}

/* nValues: mostly n, sometimes another */
static size_t in_nvalues(In *in, size_t n) { return in_u8(in) < 240 ? n : in_u8(in) % MAXN; }

static void fmi3_op(F3 *f, In *in)
{
    fmi3Instance c = f->c;
    uint32_t vr[MAXN];
    double real[MAXN];
    int32_t ints[MAXN];
    fmi3Boolean bools[MAXN];
    fmi3String strs[MAXN];
    char text[MAXN][24];
    int null_vr, null_values;
    fmi3Status st;
    uint8_t op = in_u8(in);
    if (trace) fprintf(stderr, "fmi3 op %d (t %g)\n", op % 44, f->t);
    switch (op % 44) {
    case 0: {
        fmi3Boolean tol_defined = in_u8(in) & 1, stop_defined = in_u8(in) & 1;
        double tol = in_double(in), start = in_u8(in) & 1 ? in_double(in) : 0.0, stop = in_double(in);
        if (OK3(fmi3EnterInitializationMode(c, tol_defined, tol, start, stop_defined, stop)) && isfinite(start))
            f->t = start;
        break;
    }
    case 1: fmi3ExitInitializationMode(c); break;
    case 2: fmi3EnterEventMode(c); break;
    case 3: fmi3EnterStepMode(c); break;
    case 4: case 5: case 6: {
        double t = in_u8(in) < 240 ? f->t : in_double(in), h = in_step(in), last = NAN;
        fmi3Boolean event = 0, terminate = 0, early = 0;
        int null = in_u8(in) < 8 ? in_u8(in) : 0;
        st = fmi3DoStep(c, t, h, in_u8(in) & 1, NUL((null & 1)) ? NULL : &event, NUL((null & 2)) ? NULL : &terminate,
                        NUL((null & 4)) ? NULL : &early, NUL((null & 8)) ? NULL : &last);
        if (OK3(st) && !(null & 8)) {
            if (!isfinite(last)) FUZZ_FAIL("fmi3DoStep answered OK with lastSuccessfulTime = %g", last);
            f->t = last;
        }
        break;
    }
    case 7: case 8: case 9: {
        size_t n = in_vrs(in, vr, N_VR3, &null_vr, &null_values);
        size_t nv = in_nvalues(in, n);
        st = fmi3GetFloat64(c, null_vr ? NULL : vr, n, null_values ? NULL : real, nv);
        if (!null_vr && !null_values) check_finite("fmi3GetFloat64", OK3(st), real, n < nv ? n : nv);
        break;
    }
    case 10: case 11: {
        size_t n = in_vrs(in, vr, N_VR3, &null_vr, &null_values);
        for (size_t i = 0; i < n; i++) real[i] = in_double(in);
        fmi3SetFloat64(c, null_vr ? NULL : vr, n, null_values ? NULL : real, in_nvalues(in, n));
        break;
    }
    case 12: {
        size_t n = in_vrs(in, vr, N_VR3, &null_vr, &null_values);
        fmi3GetInt32(c, null_vr ? NULL : vr, n, null_values ? NULL : ints, in_nvalues(in, n));
        break;
    }
    case 13: {
        size_t n = in_vrs(in, vr, N_VR3, &null_vr, &null_values);
        for (size_t i = 0; i < n; i++) ints[i] = in_i32(in);
        fmi3SetInt32(c, null_vr ? NULL : vr, n, null_values ? NULL : ints, in_nvalues(in, n));
        break;
    }
    case 14: {
        size_t n = in_vrs(in, vr, N_VR3, &null_vr, &null_values);
        size_t nv = in_nvalues(in, n);
        memset(bools, 0, sizeof bools);
        st = fmi3GetBoolean(c, null_vr ? NULL : vr, n, null_values ? NULL : bools, nv);
        if (OK3(st) && !null_vr && !null_values)
            for (size_t i = 0; i < n && i < nv; i++) {
                unsigned char byte;
                memcpy(&byte, &bools[i], 1);
                if (byte > 1) FUZZ_FAIL("fmi3GetBoolean answered OK with value[%zu] = %u", i, byte);
            }
        break;
    }
    case 15: {
        size_t n = in_vrs(in, vr, N_VR3, &null_vr, &null_values);
        for (size_t i = 0; i < n; i++) bools[i] = in_u8(in) & 1;
        fmi3SetBoolean(c, null_vr ? NULL : vr, n, null_values ? NULL : bools, in_nvalues(in, n));
        break;
    }
    case 16: {
        size_t n = in_vrs(in, vr, N_VR3, &null_vr, &null_values);
        size_t nv = in_nvalues(in, n);
        st = fmi3GetString(c, null_vr ? NULL : vr, n, null_values ? NULL : strs, nv);
        if (OK3(st) && !null_vr && !null_values)
            for (size_t i = 0; i < n && i < nv; i++) {
                volatile size_t len = strs[i] ? strlen(strs[i]) : 0;
                (void)len;
            }
        break;
    }
    case 17: {
        size_t n = in_vrs(in, vr, N_VR3, &null_vr, &null_values);
        for (size_t i = 0; i < n; i++) strs[i] = in_string(in, text[i], sizeof text[i]);
        fmi3SetString(c, null_vr ? NULL : vr, n, null_values ? NULL : strs, in_nvalues(in, n));
        break;
    }
    case 18: fmi3GetFMUState(c, &f->states[in_u8(in) & 1]); break;
    case 19: fmi3SetFMUState(c, f->states[in_u8(in) & 1]); break;
    case 20: fmi3FreeFMUState(c, &f->states[in_u8(in) & 1]); break;
    case 21: {
        int k = in_u8(in) & 1;
        size_t size = 0;
        if (f->states[k] == NULL || fmi3SerializedFMUStateSize(c, f->states[k], &size) != fmi3OK) break;
        fmi3Byte *bytes = malloc(size + 1);
        if (fmi3SerializeFMUState(c, f->states[k], bytes, size) == fmi3OK) {
            size_t len = in_damage(in, (unsigned char *)bytes, size);
            fmi3DeserializeFMUState(c, bytes, len, &f->states[in_u8(in) & 1]);
        }
        free(bytes);
        break;
    }
    case 22: fmi3Terminate(c); break;
    case 23: fmi3Reset(c); f->t = 0.0; break;
    case 24: {
        const char *cats[4];
        size_t n = in_categories(in, cats);
        fmi3SetDebugLogging(c, in_u8(in) & 1, n, NUL((in_u8(in) & 7) == 0) ? NULL : cats);
        break;
    }
    case 25: {
        fmi3Boolean a, b, d, e, g;
        double next = NAN;
        int null = in_u8(in) < 16 ? in_u8(in) : 0;
        st = fmi3UpdateDiscreteStates(c, NUL((null & 1)) ? NULL : &a, NUL((null & 2)) ? NULL : &b, NUL((null & 4)) ? NULL : &d,
                                      NUL((null & 8)) ? NULL : &e, NUL((null & 16)) ? NULL : &g, NUL((null & 32)) ? NULL : &next);
        break;
    }
    case 26: {
        uint32_t known[MAXN];
        double seed[MAXN];
        int nu_null, x, nk_null, y;
        size_t nu = in_vrs(in, vr, N_VR3, &nu_null, &x);
        size_t nk = in_vrs(in, known, N_VR3, &nk_null, &y);
        for (size_t i = 0; i < nk; i++) seed[i] = in_double(in);
        size_t ns = in_nvalues(in, nk), nsens = in_nvalues(in, nu);
        st = fmi3GetDirectionalDerivative(c, NUL(nu_null) ? NULL : vr, nu, NUL(nk_null) ? NULL : known, nk, NUL(y) ? NULL : seed, ns,
                                          NUL(x) ? NULL : real, nsens);
        if (!nu_null && !nk_null && !x && !y) check_finite("fmi3GetDirectionalDerivative", OK3(st), real,
                                                           nu < nsens ? nu : nsens);
        break;
    }
    case 27: { /* what this FMU does not provide: refused, arguments untouched */
        size_t sizes[MAXN];
        fmi3Binary bins[MAXN];
        fmi3Clock clocks[MAXN];
        size_t n = in_vrs(in, vr, N_VR3, &null_vr, &null_values);
        memset(sizes, 0, sizeof sizes);
        memset(bins, 0, sizeof bins);
        memset(clocks, 0, sizeof clocks);
        switch (in_u8(in) % 8) {
        case 0: fmi3GetBinary(c, vr, n, sizes, bins, n); break;
        case 1: fmi3SetBinary(c, vr, n, sizes, bins, n); break;
        case 2: fmi3GetClock(c, vr, n, clocks); break;
        case 3: fmi3SetClock(c, vr, n, clocks); break;
        case 4: fmi3EnterConfigurationMode(c); break;
        case 5: fmi3ExitConfigurationMode(c); break;
        case 6: fmi3EvaluateDiscreteStates(c); break;
        default: {
            size_t count = 0;
            fmi3GetNumberOfVariableDependencies(c, in_vr(in, N_VR3), NUL(in_u8(in) & 1) ? NULL : &count);
            break;
        }
        }
        break;
    }
    case 28: fmi3EnterContinuousTimeMode(c); break;
    case 29: {
        fmi3Boolean enter, terminate;
        int null = in_u8(in);
        fmi3CompletedIntegratorStep(c, in_u8(in) & 1, NUL((null & 1)) ? NULL : &enter, NUL((null & 2)) ? NULL : &terminate);
        break;
    }
    case 30: {
        double t = in_u8(in) < 128 ? f->t + in_step(in) : in_double(in);
        if (OK3(fmi3SetTime(c, t))) f->t = t;
        break;
    }
    case 31: {
        size_t n = in_u8(in) < 224 ? N_STATES : in_u8(in) % MAXN;
        for (size_t i = 0; i < n; i++) real[i] = in_double(in);
        fmi3SetContinuousStates(c, NUL((in_u8(in) & 15) == 0) ? NULL : real, n);
        break;
    }
    case 32: case 33: case 34: case 35: {
        size_t want = op % 44 == 33 ? N_INDICATORS : N_STATES;
        size_t n = in_u8(in) < 224 ? want : in_u8(in) % MAXN;
        double *out = NUL((in_u8(in) & 15) == 0) ? NULL : real;
        switch (op % 44) {
        case 32:
            st = fmi3GetContinuousStateDerivatives(c, out, n);
            check_finite("fmi3GetContinuousStateDerivatives", OK3(st), out, n);
            break;
        case 33: st = fmi3GetEventIndicators(c, out, n); check_finite("fmi3GetEventIndicators", OK3(st), out, n); break;
        case 34: st = fmi3GetContinuousStates(c, out, n); check_finite("fmi3GetContinuousStates", OK3(st), out, n); break;
        default:
            st = fmi3GetNominalsOfContinuousStates(c, out, n);
            check_finite("fmi3GetNominalsOfContinuousStates", OK3(st), out, n);
            break;
        }
        break;
    }
    case 36: {
        size_t count = 0;
        int null = (in_u8(in) & 7) == 0;
        if (in_u8(in) & 1) fmi3GetNumberOfEventIndicators(c, NUL(null) ? NULL : &count);
        else fmi3GetNumberOfContinuousStates(c, NUL(null) ? NULL : &count);
        break;
    }
    default:
        read_reals3(c);
        break;
    }
}

static fmi3Instance fmi3_instantiate(In *in)
{
    uint8_t how = in_u8(in);
    const char *token = FMU_GUID, *path = resource_dir, *name = "fuzz";
    char tok[48], pth[48], nm[24];
    if ((how & 0xf0) == 0xf0) {
        name = in_string(in, nm, sizeof nm);
        if (in_u8(in) & 1) token = in_string(in, tok, sizeof tok);
        if (in_u8(in) & 1) path = in_string(in, pth, sizeof pth);
    }
    fmi3LogMessageCallback log = NUL((how & 8)) ? NULL : logger3;
    if (how & 1) return fmi3InstantiateModelExchange(name, token, path, 0, (how & 4) != 0, NULL, log);
    uint32_t required[2] = {0, 1};
    return fmi3InstantiateCoSimulation(name, token, path, 0, (how & 4) != 0, (how & 2) != 0, (how & 16) != 0,
                                       required, (how & 32) ? 2 : 0, NULL, log, NULL);
}

#define MAX_OPS 48

#ifdef FUZZ_CALLS
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    In in = {data, size};
    int version3 = in_u8(&in) & 1;
    if (!version3) {
        F2 f = {0};
        f.c = fmi2_instantiate(&in, &f.me);
        if (f.c == NULL) return 0;
        for (int k = 0; k < MAX_OPS && in.n > 0; k++) fmi2_op(&f, &in);
        fmi2_free_all(&f);
    } else {
        F3 f = {0};
        f.c = fmi3_instantiate(&in);
        if (f.c == NULL) return 0;
        for (int k = 0; k < MAX_OPS && in.n > 0; k++) fmi3_op(&f, &in);
        fmi3_free_all(&f);
    }
    return 0;
}
#endif

#ifdef FUZZ_STATE
/* fmi2_native.c's serialized state: a header {char format[64]; uint64_t size; uint64_t checksum;} then the State;
   FMI 3.0 puts the mode (int64) and the time (double) before it. */
#define HEADER2 80
#define CHECKSUM_AT 72

/* out of line: coverage_ignore.txt leaves it uninstrumented (a callback per byte otherwise); the harness's own
   checksum of its own buffer (g->size bytes, allocated here), so not checked by the sanitizers either (a check per
   byte: 7 % of a state target's time) -- the FMU's checksum of the same bytes is */
__attribute__((noinline, no_sanitize("address", "undefined"))) static uint64_t fnv1a(const unsigned char *bytes,
                                                                                      size_t n)
{
    uint64_t h = 14695981039346656037ULL;
    for (size_t i = 0; i < n; i++) {
        h ^= bytes[i];
        h *= 1099511628211ULL;
    }
    return h;
}

static const int64_t INTEGERS[] = {0, 1, -1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 16, 64, 1000, 100000, INT32_MAX,
                                   (int64_t)INT32_MAX + 1, INT64_MAX, INT64_MIN, -2, 255, 256, 1 << 20};

/* The input's patches applied to a serialized state of `size` bytes (the fmi2 part from `inner`) */
static void patch(In *in, unsigned char *bytes, size_t size, size_t inner)
{
    size_t n_patches = 1 + in_u8(in) % 8;
    for (size_t k = 0; k < n_patches && in->n > 0; k++) {
        uint8_t kind = in_u8(in);
        size_t at = in_u16(in) % size;
        size_t aligned = inner + ((at - at % 8) >= inner ? at - at % 8 - inner : 0);
        if (aligned + 8 > size) aligned = size - 8;
        switch (kind % 4) {
        case 0: {
            size_t len = 1 + in_u8(in) % 16;
            for (size_t i = 0; i < len && at + i < size; i++) bytes[at + i] = in_u8(in);
            break;
        }
        case 1: {
            double d = in_double(in);
            memcpy(bytes + aligned, &d, 8);
            break;
        }
        case 2: {
            uint8_t j = in_u8(in);
            int64_t v = j < 2 * sizeof INTEGERS / sizeof INTEGERS[0] ? INTEGERS[j % (sizeof INTEGERS / sizeof INTEGERS[0])]
                                                                   : (int64_t)in_u64(in);
            if (in_u8(in) & 1) memcpy(bytes + aligned, &v, 8);
            else { int32_t w = (int32_t)v; memcpy(bytes + aligned + 4 * (in_u8(in) & 1), &w, 4); }
            break;
        }
        default: bytes[at] ^= (unsigned char)(1u << (in_u8(in) % 8)); break;
        }
    }
}

/* The genuine states, serialized once per kind (version, interface, how far it ran): an input pays for the
   restore and what follows, not for the initialisation that made the state. */
typedef struct {
    unsigned char *bytes;
    size_t size;
} Genuine;
static Genuine genuine_states[2][2][4];

static fmi2Component new2(int me)
{
    fmi2Component c = fmi2Instantiate("fuzz", me ? fmi2ModelExchange : fmi2CoSimulation, FMU_GUID, resource_uri,
                                      &CALLBACKS, 0, 0);
    if (c == NULL) abort();
    return c;
}

static fmi3Instance new3(int me, int event_mode, int early)
{
    fmi3Instance c = me ? fmi3InstantiateModelExchange("fuzz", FMU_GUID, resource_dir, 0, 0, NULL, logger3)
                        : fmi3InstantiateCoSimulation("fuzz", FMU_GUID, resource_dir, 0, 0, event_mode, early, NULL, 0,
                                                      NULL, logger3, NULL);
    if (c == NULL) abort();
    return c;
}

static const Genuine *genuine(int version3, int me, size_t steps)
{
    Genuine *g = &genuine_states[version3][me][steps];
    if (g->bytes != NULL) return g;
    if (!version3) {
        fmi2Component c = new2(me);
        if (steps > 0) {
            fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0);
            fmi2EnterInitializationMode(c);
            fmi2ExitInitializationMode(c);
            for (size_t k = 1; k < steps; k++) {
                if (me) { fmi2EnterContinuousTimeMode(c); fmi2SetTime(c, 0.1 * (double)k); }
                else fmi2DoStep(c, 0.1 * (double)(k - 1), 0.1, 1);
            }
        }
        fmi2FMUstate state = NULL;
        if (fmi2GetFMUstate(c, &state) != fmi2OK || fmi2SerializedFMUstateSize(c, state, &g->size) != fmi2OK) abort();
        g->bytes = malloc(g->size);
        if (fmi2SerializeFMUstate(c, state, (fmi2Byte *)g->bytes, g->size) != fmi2OK) abort();
        fmi2FreeFMUstate(c, &state);
        fmi2FreeInstance(c);
    } else {
        fmi3Instance c = new3(me, 1, 1);
        if (steps > 0) {
            fmi3EnterInitializationMode(c, 0, 0.0, 0.0, 0, 0.0);
            fmi3ExitInitializationMode(c);
            for (size_t k = 1; k < steps; k++) {
                if (me) { fmi3EnterContinuousTimeMode(c); fmi3SetTime(c, 0.1 * (double)k); }
                else {
                    fmi3Boolean a, b, e;
                    double last;
                    fmi3DoStep(c, 0.1 * (double)(k - 1), 0.1, 1, &a, &b, &e, &last);
                }
            }
        }
        fmi3FMUState state = NULL;
        if (fmi3GetFMUState(c, &state) != fmi3OK || fmi3SerializedFMUStateSize(c, state, &g->size) != fmi3OK) abort();
        g->bytes = malloc(g->size);
        if (fmi3SerializeFMUState(c, state, (fmi3Byte *)g->bytes, g->size) != fmi3OK) abort();
        fmi3FreeFMUState(c, &state);
        fmi3FreeInstance(c);
    }
    return g;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    In in = {data, size};
    uint8_t how = in_u8(&in);
    int version3 = how & 1, me = (how & 2) != 0, keep_checksum = (how & 0x78) == 0x78;
#ifndef ME_N_STATES
    me = 0;
#endif
    size_t steps = in_u8(&in) % 4; /* how far the genuine state ran */
    const Genuine *g = genuine(version3, me, steps);
    unsigned char *bytes = malloc(g->size);
    memcpy(bytes, g->bytes, g->size);
    size_t n = g->size, inner = version3 ? 16 : 0; /* FMI 3.0: mode and time first */
    patch(&in, bytes, n, inner + HEADER2);
    if (!keep_checksum) {
        uint64_t sum = fnv1a(bytes + inner + HEADER2, n - inner - HEADER2);
        memcpy(bytes + inner + CHECKSUM_AT, &sum, 8);
    }
    double t = 0.1 * (double)(steps > 0 ? steps - 1 : 0);
    if (!version3) {
        F2 f = {0};
        f.me = me;
        f.c = new2(me); /* a fresh instance: restored into before it did anything */
        if (fmi2DeSerializeFMUstate(f.c, (const fmi2Byte *)bytes, n, &f.states[0]) == fmi2OK)
            fmi2SetFMUstate(f.c, f.states[0]);
        free(bytes);
        f.t = t;
        for (int k = 0; k < 8 && in.n > 0; k++) fmi2_op(&f, &in);
        /* what a host reads and does next */
        if (me) {
#ifdef ME_N_STATES
            double x[ME_N_STATES], z[ME_N_INDICATORS];
            check_finite("fmi2GetContinuousStates", OK2(fmi2GetContinuousStates(f.c, x, ME_N_STATES)), x, ME_N_STATES);
            check_finite("fmi2GetDerivatives", OK2(fmi2GetDerivatives(f.c, x, ME_N_STATES)), x, ME_N_STATES);
            check_finite("fmi2GetEventIndicators", OK2(fmi2GetEventIndicators(f.c, z, ME_N_INDICATORS)), z,
                         ME_N_INDICATORS);
#endif
        } else {
            fmi2DoStep(f.c, f.t, 0.1, 1);
        }
        read_reals2(f.c);
        fmi2_free_all(&f);
    } else {
        F3 f = {0};
        f.c = new3(me, (how & 8) != 0, (how & 16) != 0);
        if (fmi3DeserializeFMUState(f.c, (const fmi3Byte *)bytes, n, &f.states[0]) == fmi3OK)
            fmi3SetFMUState(f.c, f.states[0]);
        free(bytes);
        f.t = t;
        for (int k = 0; k < 8 && in.n > 0; k++) fmi3_op(&f, &in);
        double last = NAN;
        if (me) {
#ifdef ME_N_STATES
            double x[ME_N_STATES], z[ME_N_INDICATORS];
            check_finite("fmi3GetContinuousStates", OK3(fmi3GetContinuousStates(f.c, x, ME_N_STATES)), x, ME_N_STATES);
            check_finite("fmi3GetContinuousStateDerivatives",
                         OK3(fmi3GetContinuousStateDerivatives(f.c, x, ME_N_STATES)), x, ME_N_STATES);
            check_finite("fmi3GetEventIndicators", OK3(fmi3GetEventIndicators(f.c, z, ME_N_INDICATORS)), z,
                         ME_N_INDICATORS);
#endif
        } else {
            fmi3Boolean a, b, e;
            if (OK3(fmi3DoStep(f.c, f.t, 0.1, 1, &a, &b, &e, &last)) && !isfinite(last))
                FUZZ_FAIL("fmi3DoStep answered OK with lastSuccessfulTime = %g", last);
        }
        read_reals3(f.c);
        fmi3_free_all(&f);
    }
    return 0;
}
#endif
