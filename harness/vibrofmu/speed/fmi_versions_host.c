/*
 * fmi_versions_host.c -- the cost per output of one native FMU as FMI 2.0 and as FMI 3.0 Co-Simulation, measured
 * side by side in one plain C process (compiled by vibrofmu.speed.native_timing; no Python around the calls).
 *
 * Usage: fmi_versions_host LIB2 LIB3 GUID STOP STEP REPEATS XVR
 *
 * REPEATS rounds, each running in turn: FMI 2.0 (fmi2DoStep + fmi2GetReal of XVR), FMI 3.0 (fmi3DoStep +
 * fmi3GetFloat64), FMI 3.0 with event mode and early return (the same, and at an early return the event mode
 * round: fmi3EnterEventMode, fmi3UpdateDiscreteStates, fmi3EnterStepMode, then on to the same communication
 * point).  Each run instantiates, initialises from 0 to STOP with the default parameters, times the output loop
 * over the points n*STEP (the last clipped to STOP), frees.  stdout: "fmi2|fmi3|fmi3er SECONDS OUTPUTS EVENTS"
 * per run.  Exit code 0, 1 (usage, loading), 2 (an FMI call failed).
 */
#include <dlfcn.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"
#include "fmi3Functions.h"

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void *symbol(void *lib, const char *name)
{
    void *f = dlsym(lib, name);
    if (f == NULL) {
        fprintf(stderr, "fmi_versions_host: %s not found\n", name);
        exit(1);
    }
    return f;
}

static void logger2(fmi2ComponentEnvironment e, fmi2String i, fmi2Status s, fmi2String c, fmi2String m, ...)
{
    (void)e; (void)i; (void)c;
    if (s > fmi2Warning) fprintf(stderr, "fmi_versions_host: FMI 2 FMU says: %s\n", m);
}

static void logger3(fmi3InstanceEnvironment e, fmi3Status s, fmi3String c, fmi3String m)
{
    (void)e; (void)c;
    if (s > fmi3Warning) fprintf(stderr, "fmi_versions_host: FMI 3 FMU says: %s\n", m);
}

#define CHECK(call)                                                                                            \
    do {                                                                                                       \
        if ((call) > 1) {                                                                                      \
            fprintf(stderr, "fmi_versions_host: %s failed\n", #call);                                          \
            exit(2);                                                                                           \
        }                                                                                                      \
    } while (0)

static double point(long n, double step, double stop) { return fmin((double)n * step, stop); }

/* The FMI calls each run uses, loaded by name into a table of function pointers (one list per version) */
#define FMI2_CALLS(X)                                                                                          \
    X(fmi2Instantiate) X(fmi2SetupExperiment) X(fmi2EnterInitializationMode) X(fmi2ExitInitializationMode)    \
    X(fmi2DoStep) X(fmi2GetReal) X(fmi2FreeInstance)
#define FMI3_CALLS(X)                                                                                          \
    X(fmi3InstantiateCoSimulation) X(fmi3EnterInitializationMode) X(fmi3ExitInitializationMode)               \
    X(fmi3EnterEventMode) X(fmi3UpdateDiscreteStates) X(fmi3EnterStepMode) X(fmi3DoStep) X(fmi3GetFloat64)    \
    X(fmi3FreeInstance)
#define DECLARE(name) name##TYPE *name;
#define LOAD(name) api.name = (name##TYPE *)symbol(lib, #name);
typedef struct { FMI2_CALLS(DECLARE) } Fmi2;
typedef struct { FMI3_CALLS(DECLARE) } Fmi3;

static Fmi2 load2(void *lib)
{
    Fmi2 api;
    FMI2_CALLS(LOAD)
    return api;
}

static Fmi3 load3(void *lib)
{
    Fmi3 api;
    FMI3_CALLS(LOAD)
    return api;
}

static double run2(void *lib, const char *guid, double stop, double step, unsigned xvr, long *outputs)
{
    const Fmi2 f = load2(lib);
    fmi2CallbackFunctions cb = {logger2, calloc, free, NULL, NULL};
    fmi2Component c = f.fmi2Instantiate("timing", fmi2CoSimulation, guid, "file:///tmp", &cb, fmi2False, fmi2False);
    if (c == NULL) exit(2);
    CHECK(f.fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, stop));
    CHECK(f.fmi2EnterInitializationMode(c));
    CHECK(f.fmi2ExitInitializationMode(c));
    double x, t = 0.0, sum = 0.0, started = now();
    long n = 0;
    while (t < stop && fabs(t - stop) > 1e-9 * stop) {
        double next = point(n + 1, step, stop);
        CHECK(f.fmi2DoStep(c, t, next - t, fmi2True));
        CHECK(f.fmi2GetReal(c, &xvr, 1, &x));
        sum += x;
        t = next;
        n++;
    }
    double seconds = now() - started;
    f.fmi2FreeInstance(c);
    *outputs = n;
    return isfinite(sum) ? seconds : NAN;
}

/* fmi3UpdateDiscreteStates then fmi3EnterStepMode: the event mode's round, the outputs it reports dropped */
static void update_and_step(const Fmi3 *f, fmi3Instance c)
{
    fmi3Boolean need, terminate, nominals, values, defined;
    fmi3Float64 next_event;
    CHECK(f->fmi3UpdateDiscreteStates(c, &need, &terminate, &nominals, &values, &defined, &next_event));
    CHECK(f->fmi3EnterStepMode(c));
}

static double run3(void *lib, const char *guid, double stop, double step, unsigned xvr, int early, long *outputs,
                   long *events)
{
    const Fmi3 f = load3(lib);
    fmi3Instance c = f.fmi3InstantiateCoSimulation("timing", guid, "/tmp", fmi3False, fmi3False, early, early, NULL,
                                                   0, NULL, logger3, NULL);
    if (c == NULL) exit(2);
    fmi3Boolean terminate, event, early_return;
    fmi3Float64 last;
    CHECK(f.fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3True, stop));
    CHECK(f.fmi3ExitInitializationMode(c));
    if (early) update_and_step(&f, c);
    double x, t = 0.0, sum = 0.0, started = now();
    long n = 0;
    *events = 0;
    while (t < stop && fabs(t - stop) > 1e-9 * stop) {
        double next = point(n + 1, step, stop);
        CHECK(f.fmi3DoStep(c, t, next - t, fmi3True, &event, &terminate, &early_return, &last));
        CHECK(f.fmi3GetFloat64(c, &xvr, 1, &x, 1));
        sum += x;
        if (early_return) {
            t = last;
            (*events)++;
        } else {
            t = next;
            n++;
        }
        if (event) {
            CHECK(f.fmi3EnterEventMode(c));
            update_and_step(&f, c);
        }
    }
    double seconds = now() - started;
    f.fmi3FreeInstance(c);
    *outputs = n;
    return isfinite(sum) ? seconds : NAN;
}

int main(int argc, char **argv)
{
    if (argc != 8) {
        fprintf(stderr, "usage: fmi_versions_host LIB2 LIB3 GUID STOP STEP REPEATS XVR\n");
        return 1;
    }
    void *lib2 = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL), *lib3 = dlopen(argv[2], RTLD_NOW | RTLD_LOCAL);
    if (lib2 == NULL || lib3 == NULL) {
        fprintf(stderr, "fmi_versions_host: %s\n", dlerror());
        return 1;
    }
    const double stop = atof(argv[4]), step = atof(argv[5]);
    const int repeats = atoi(argv[6]);
    const unsigned xvr = (unsigned)atoi(argv[7]);
    for (int r = 0; r < repeats; r++) {
        long outputs, events;
        double s = run2(lib2, argv[3], stop, step, xvr, &outputs);
        printf("fmi2 %.9g %ld 0\n", s, outputs);
        s = run3(lib3, argv[3], stop, step, xvr, 0, &outputs, &events);
        printf("fmi3 %.9g %ld %ld\n", s, outputs, events);
        s = run3(lib3, argv[3], stop, step, xvr, 1, &outputs, &events);
        printf("fmi3er %.9g %ld %ld\n", s, outputs, events);
    }
    return 0;
}
