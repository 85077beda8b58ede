/*
 * instance_cycles.c -- instantiate/free cycles of one FMU binary from C, measuring the resident set size
 * (issue 15: instances must not leak).  Compiled by tests/fmus/test_instance_leaks.py; run in the environment
 * `vibrofmu doctor` works out (libpython preloaded, PYTHONHOME, PYTHONPATH) for pythonfmu FMUs.
 *
 * Usage: instance_cycles LIBRARY RESOURCE_URI GUID CYCLES WARMUP [run]
 *   Each cycle: fmi2Instantiate, with "run" also fmi2SetupExperiment, fmi2EnterInitializationMode,
 *   fmi2ExitInitializationMode, 3 fmi2DoStep of 0.1, fmi2Terminate; then fmi2FreeInstance.
 *   The RSS is taken after WARMUP cycles (interpreter, imports and caches settled) and after CYCLES.
 * stdout: "cycles=<n> rss_after_warmup_kb=<kb> rss_end_kb=<kb> growth_kb=<kb>"
 * Exit code: 0 success, 1 usage or loading error, 2 an FMI call failed (named on stderr).
 */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmi2_types.h"

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env; (void)category;
    if (status < fmi2Warning) return;
    va_list args;
    fprintf(stderr, "[%d] %s: ", (int)status, instance ? instance : "");
    va_start(args, message);
    vfprintf(stderr, message ? message : "", args);
    va_end(args);
    fputc('\n', stderr);
}

static long rss_kb(void)
{
    long pages = 0, resident = 0;
    FILE *f = fopen("/proc/self/statm", "r");
    if (f == NULL) return -1;
    if (fscanf(f, "%ld %ld", &pages, &resident) != 2) resident = -1;
    fclose(f);
    return resident * (sysconf(_SC_PAGESIZE) / 1024);
}

#define LOAD(var, name)                                                               \
    *(void **)(&var) = dlsym(lib, name);                                              \
    if (var == NULL) { fprintf(stderr, "missing %s\n", name); return 1; }

#define CHECK(call, name)                                                             \
    if ((call) > fmi2Warning) { fprintf(stderr, "%s failed in cycle %ld\n", name, i); return 2; }

int main(int argc, char **argv)
{
    if (argc < 6) {
        fprintf(stderr, "usage: %s LIBRARY RESOURCE_URI GUID CYCLES WARMUP [run]\n", argv[0]);
        return 1;
    }
    long cycles = atol(argv[4]), warmup = atol(argv[5]);
    int run = argc > 6 && strcmp(argv[6], "run") == 0;
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (lib == NULL) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 1; }
    fmi2Component (*instantiate)(fmi2String, fmi2Type, fmi2String, fmi2String, const fmi2CallbackFunctions *,
                                 fmi2Boolean, fmi2Boolean);
    void (*free_instance)(fmi2Component);
    fmi2Status (*setup)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real);
    fmi2Status (*enter)(fmi2Component), (*exit_init)(fmi2Component), (*terminate)(fmi2Component);
    fmi2Status (*do_step)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);
    LOAD(instantiate, "fmi2Instantiate"); LOAD(free_instance, "fmi2FreeInstance");
    LOAD(setup, "fmi2SetupExperiment"); LOAD(enter, "fmi2EnterInitializationMode");
    LOAD(exit_init, "fmi2ExitInitializationMode"); LOAD(terminate, "fmi2Terminate"); LOAD(do_step, "fmi2DoStep");
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    long rss_warm = -1;
    for (long i = 0; i < cycles + warmup; i++) {
        if (i == warmup) rss_warm = rss_kb();
        fmi2Component c = instantiate("cycle", fmi2CoSimulation, argv[3], argv[2], &callbacks, 0, 0);
        if (c == NULL) { fprintf(stderr, "fmi2Instantiate failed in cycle %ld\n", i); return 2; }
        if (run) {
            CHECK(setup(c, 0, 0.0, 0.0, 0, 0.0), "fmi2SetupExperiment");
            CHECK(enter(c), "fmi2EnterInitializationMode");
            CHECK(exit_init(c), "fmi2ExitInitializationMode");
            for (int k = 0; k < 3; k++) CHECK(do_step(c, 0.1 * k, 0.1, 1), "fmi2DoStep");
            CHECK(terminate(c), "fmi2Terminate");
        }
        free_instance(c);
    }
    long rss_end = rss_kb();
    printf("cycles=%ld rss_after_warmup_kb=%ld rss_end_kb=%ld growth_kb=%ld\n", cycles, rss_warm, rss_end,
           rss_end - rss_warm);
    return 0;
}
