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
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmi2_host_api.h" /* fmu_src/fmi/: Fmi2Api, the table of fmi2 functions, on the FMI standard's headers */

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
    void *lib = fmi2_host_open(argv[1]);
    if (lib == NULL) { fprintf(stderr, "dlopen: %s\n", fmi2_host_error()); return 1; }
    static const char *const NEEDED[] = {"Instantiate", "FreeInstance", "SetupExperiment", "EnterInitializationMode",
                                         "ExitInitializationMode", "Terminate", "DoStep", NULL};
    Fmi2Api api;
    fmi2_api_load(lib, &api);
    const char *missing = fmi2_api_missing(&api, NEEDED);
    if (missing != NULL) { fprintf(stderr, "missing fmi2%s\n", missing); return 1; }
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    long rss_warm = -1;
    for (long i = 0; i < cycles + warmup; i++) {
        if (i == warmup) rss_warm = rss_kb();
        fmi2Component c = api.Instantiate("cycle", fmi2CoSimulation, argv[3], argv[2], &callbacks, 0, 0);
        if (c == NULL) { fprintf(stderr, "fmi2Instantiate failed in cycle %ld\n", i); return 2; }
        if (run) {
            CHECK(api.SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0), "fmi2SetupExperiment");
            CHECK(api.EnterInitializationMode(c), "fmi2EnterInitializationMode");
            CHECK(api.ExitInitializationMode(c), "fmi2ExitInitializationMode");
            for (int k = 0; k < 3; k++) CHECK(api.DoStep(c, 0.1 * k, 0.1, 1), "fmi2DoStep");
            CHECK(api.Terminate(c), "fmi2Terminate");
        }
        api.FreeInstance(c);
    }
    long rss_end = rss_kb();
    printf("cycles=%ld rss_after_warmup_kb=%ld rss_end_kb=%ld growth_kb=%ld\n", cycles, rss_warm, rss_end,
           rss_end - rss_warm);
    return 0;
}
