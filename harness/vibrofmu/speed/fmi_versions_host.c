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

static double run2(void *lib, const char *guid, double stop, double step, unsigned xvr, long *outputs)
{
    fmi2InstantiateTYPE *instantiate = symbol(lib, "fmi2Instantiate");
    fmi2SetupExperimentTYPE *setup = symbol(lib, "fmi2SetupExperiment");
    fmi2EnterInitializationModeTYPE *enter = symbol(lib, "fmi2EnterInitializationMode");
    fmi2ExitInitializationModeTYPE *exit_init = symbol(lib, "fmi2ExitInitializationMode");
    fmi2DoStepTYPE *do_step = symbol(lib, "fmi2DoStep");
    fmi2GetRealTYPE *get_real = symbol(lib, "fmi2GetReal");
    fmi2FreeInstanceTYPE *free_instance = symbol(lib, "fmi2FreeInstance");
    fmi2CallbackFunctions cb = {logger2, calloc, free, NULL, NULL};
    fmi2Component c = instantiate("timing", fmi2CoSimulation, guid, "file:///tmp", &cb, fmi2False, fmi2False);
    if (c == NULL) exit(2);
    CHECK(setup(c, fmi2False, 0.0, 0.0, fmi2True, stop));
    CHECK(enter(c));
    CHECK(exit_init(c));
    double x, t = 0.0, sum = 0.0, started = now();
    long n = 0;
    while (t < stop && fabs(t - stop) > 1e-9 * stop) {
        double next = point(n + 1, step, stop);
        CHECK(do_step(c, t, next - t, fmi2True));
        CHECK(get_real(c, &xvr, 1, &x));
        sum += x;
        t = next;
        n++;
    }
    double seconds = now() - started;
    free_instance(c);
    *outputs = n;
    return isfinite(sum) ? seconds : NAN;
}

static double run3(void *lib, const char *guid, double stop, double step, unsigned xvr, int early, long *outputs,
                   long *events)
{
    fmi3InstantiateCoSimulationTYPE *instantiate = symbol(lib, "fmi3InstantiateCoSimulation");
    fmi3EnterInitializationModeTYPE *enter = symbol(lib, "fmi3EnterInitializationMode");
    fmi3ExitInitializationModeTYPE *exit_init = symbol(lib, "fmi3ExitInitializationMode");
    fmi3EnterEventModeTYPE *enter_event = symbol(lib, "fmi3EnterEventMode");
    fmi3UpdateDiscreteStatesTYPE *update = symbol(lib, "fmi3UpdateDiscreteStates");
    fmi3EnterStepModeTYPE *enter_step = symbol(lib, "fmi3EnterStepMode");
    fmi3DoStepTYPE *do_step = symbol(lib, "fmi3DoStep");
    fmi3GetFloat64TYPE *get_float = symbol(lib, "fmi3GetFloat64");
    fmi3FreeInstanceTYPE *free_instance = symbol(lib, "fmi3FreeInstance");
    fmi3Instance c = instantiate("timing", guid, "/tmp", fmi3False, fmi3False, early, early, NULL, 0, NULL, logger3,
                                 NULL);
    if (c == NULL) exit(2);
    fmi3Boolean need, terminate, nominals, values, defined, event, early_return;
    fmi3Float64 next_event, last;
    CHECK(enter(c, fmi3False, 0.0, 0.0, fmi3True, stop));
    CHECK(exit_init(c));
    if (early) {
        CHECK(update(c, &need, &terminate, &nominals, &values, &defined, &next_event));
        CHECK(enter_step(c));
    }
    double x, t = 0.0, sum = 0.0, started = now();
    long n = 0;
    *events = 0;
    while (t < stop && fabs(t - stop) > 1e-9 * stop) {
        double next = point(n + 1, step, stop);
        CHECK(do_step(c, t, next - t, fmi3True, &event, &terminate, &early_return, &last));
        CHECK(get_float(c, &xvr, 1, &x, 1));
        sum += x;
        if (early_return) {
            t = last;
            (*events)++;
        } else {
            t = next;
            n++;
        }
        if (event) {
            CHECK(enter_event(c));
            CHECK(update(c, &need, &terminate, &nominals, &values, &defined, &next_event));
            CHECK(enter_step(c));
        }
    }
    double seconds = now() - started;
    free_instance(c);
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
