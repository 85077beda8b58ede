/*
 * timing_host.c -- the plain C FMI 2.0 host of `vibrofmu bench`'s ladder: the cost per output of an FMU as a
 * system-simulation tool pays it, without any Python host around the calls (compiled by vibrofmu.speed.bench).
 *
 * Usage: timing_host LIBRARY RESOURCE_URI GUID STOP STEP REPEATS XVR [rVR=VALUE | iVR=VALUE ...]
 *                    [then STEP [rVR=VALUE | iVR=VALUE ...] ...]
 *
 * Each of REPEATS runs: fmi2Instantiate, fmi2SetupExperiment(0, STOP), enter initialisation, the parameters
 * (r: fmi2SetReal, i: fmi2SetInteger), exit initialisation -- timed together as "init" -- then the output loop
 * -- timed as "loop" -- of fmi2DoStep(t, STEP) + fmi2GetReal(XVR) from 0 to STOP (communication points n*STEP,
 * the last clipped to STOP, as FMPy's simulate_fmu makes them), then fmi2Terminate, fmi2FreeInstance.
 *
 * The loop calls fmi2DoStep and fmi2GetReal through timing_do_step and timing_get_real (below), the functions
 * the ladder's instruction count (callgrind) toggles its collection on.
 *
 * Each "then STEP [parameters]" adds a run specification (another output interval and start values) that runs
 * REPEATS times after the previous one, in the same process: the ladder's instruction count runs all of an FMU's
 * rungs in one valgrind process, so that the embedded Python starts once under valgrind.
 *
 * stdout, per specification in order: "init SECONDS" and "loop SECONDS STEPS CPU_SECONDS" (wall clock, outputs,
 * the thread's CPU time) for every run, then "x T VALUE"
 * for every output of its last run (%.17g).  Exit code 0, or 1 (usage, loading) or 2 (an FMI call failed; named on stderr).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2_host_api.h" /* fmu_src/fmi/: Fmi2Api, the table of fmi2 functions, on the FMI standard's headers */

#define MAX_PARAMETERS 64

typedef Fmi2Api Api;

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env; (void)instance; (void)category;
    if (status > fmi2Warning) fprintf(stderr, "timing_host: FMU says (status %d): %s\n", (int)status, message);
}

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* CPU time of the calling thread (the FMU's fast path runs in it): unlike the wall clock, it does not advance
 * while the thread waits for a CPU held by other processes. */
static double thread_cpu(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int isclose(double a, double b) { return fabs(a - b) <= 1e-9 * fmax(fabs(a), fabs(b)); }

/* The loop's two FMI calls go through these out-of-line functions so that `valgrind --tool=callgrind
 * --toggle-collect=timing_do_step --toggle-collect=timing_get_real` counts exactly the instructions of
 * doStep + getReal(x), everything they call included.  Toggling on fmi2DoStep itself would not: the status
 * shim's fmi2DoStep forwards to the inner pythonfmu library's function of the same name, whose entry would
 * toggle collection off again while the slave's Python runs. */
Api api;
fmi2Status timing_do_step(fmi2Component c, double t, double h) __attribute__((noinline));
fmi2Status timing_get_real(fmi2Component c, const fmi2ValueReference *vr, double *x) __attribute__((noinline));
/* (the empty asm after each call keeps the compiler from turning it into a tail jump, which callgrind would
 * not see as a call made from inside the toggled function) */
fmi2Status timing_do_step(fmi2Component c, double t, double h)
{
    fmi2Status status = api.DoStep(c, t, h, 1);
    __asm__ volatile("" ::: "memory");
    return status;
}
fmi2Status timing_get_real(fmi2Component c, const fmi2ValueReference *vr, double *x)
{
    fmi2Status status = api.GetReal(c, vr, 1, x);
    __asm__ volatile("" ::: "memory");
    return status;
}

static int failed(const char *call, fmi2Status st)
{
    if (st <= fmi2Warning) return 0;
    fprintf(stderr, "timing_host: %s returned status %d\n", call, (int)st);
    return 1;
}

/* One run specification: the output interval and the start values. */
typedef struct {
    double step;
    size_t n_real, n_int;
    fmi2ValueReference real_vr[MAX_PARAMETERS], int_vr[MAX_PARAMETERS];
    fmi2Real real_value[MAX_PARAMETERS];
    fmi2Integer int_value[MAX_PARAMETERS];
} Spec;

#define MAX_SPECS 32

/* Called after each run's loop, outside the collected functions: `callgrind --dump-after=timing_run_done` writes
 * one profile per run (the instruction count of that run's doStep + getReal calls). */
void timing_run_done(int spec, int run) __attribute__((noinline));
void timing_run_done(int spec, int run)
{
    __asm__ volatile("" : : "r"(spec), "r"(run) : "memory");
}

int main(int argc, char **argv)
{
    static Spec specs[MAX_SPECS];
    int n_specs = 0;
    if (argc < 8) {
        fprintf(stderr, "usage: timing_host LIBRARY RESOURCE_URI GUID STOP STEP REPEATS XVR [rVR=VALUE|iVR=VALUE ...] "
                        "[then STEP [rVR=VALUE|iVR=VALUE ...] ...]\n");
        return 1;
    }
    double stop = strtod(argv[4], NULL);
    int repeats = atoi(argv[6]);
    fmi2ValueReference xvr = (fmi2ValueReference)strtoul(argv[7], NULL, 10);
    specs[n_specs++].step = strtod(argv[5], NULL);
    for (int i = 8; i < argc; i++) {
        Spec *spec = &specs[n_specs - 1];
        if (strcmp(argv[i], "then") == 0) {
            if (i + 1 >= argc || n_specs == MAX_SPECS) {
                fprintf(stderr, "timing_host: 'then' needs a STEP (at most %d specifications)\n", MAX_SPECS);
                return 1;
            }
            specs[n_specs++].step = strtod(argv[++i], NULL);
            continue;
        }
        char *end, *text = argv[i] + 1;
        unsigned long vr = strtoul(text, &end, 10);
        if ((argv[i][0] != 'r' && argv[i][0] != 'i') || *end != '=') {
            fprintf(stderr, "timing_host: expected rVR=VALUE or iVR=VALUE, got %s\n", argv[i]);
            return 1;
        }
        if (spec->n_real + spec->n_int >= MAX_PARAMETERS) {
            fprintf(stderr, "timing_host: more than %d parameters in one specification\n", MAX_PARAMETERS);
            return 1;
        }
        if (argv[i][0] == 'r') {
            spec->real_vr[spec->n_real] = (fmi2ValueReference)vr;
            spec->real_value[spec->n_real++] = strtod(end + 1, NULL);
        } else {
            spec->int_vr[spec->n_int] = (fmi2ValueReference)vr;
            spec->int_value[spec->n_int++] = atoi(end + 1);
        }
    }
    double min_step = specs[0].step;
    for (int k = 0; k < n_specs; k++) min_step = fmin(min_step, specs[k].step);
    if (!(min_step > 0.0 && stop > 0.0 && repeats > 0)) {
        fprintf(stderr, "timing_host: STOP, STEP and REPEATS must be > 0\n");
        return 1;
    }
    void *lib = fmi2_host_open(argv[1]);
    if (lib == NULL) {
        fprintf(stderr, "timing_host: cannot load %s: %s\n", argv[1], fmi2_host_error());
        return 1;
    }
    static const char *const NEEDED[] = {"Instantiate", "FreeInstance", "SetupExperiment", "EnterInitializationMode",
                                         "ExitInitializationMode", "Terminate", "GetReal", "SetReal", "SetInteger",
                                         "DoStep", NULL};
    fmi2_api_load(lib, &api);
    const char *missing = fmi2_api_missing(&api, NEEDED);
    if (missing != NULL) {
        fprintf(stderr, "timing_host: no fmi2%s\n", missing);
        return 1;
    }
    size_t capacity = (size_t)(stop / min_step) + 2;
    double *times = malloc(capacity * sizeof *times), *xs = malloc(capacity * sizeof *xs);
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    for (int k = 0; k < n_specs; k++) {
        const Spec *spec = &specs[k];
        double step = spec->step;
        size_t count = 0;
        for (int r = 0; r < repeats; r++) {
            double started = now();
            fmi2Component c = api.Instantiate("timing", fmi2CoSimulation, argv[3], argv[2], &callbacks, 0, 0);
            if (c == NULL) {
                fprintf(stderr, "timing_host: fmi2Instantiate failed\n");
                return 2;
            }
            if (failed("fmi2SetupExperiment", api.SetupExperiment(c, 0, 0.0, 0.0, 1, stop))
                || failed("fmi2EnterInitializationMode", api.EnterInitializationMode(c))
                || (spec->n_real && failed("fmi2SetReal", api.SetReal(c, spec->real_vr, spec->n_real, spec->real_value)))
                || (spec->n_int && failed("fmi2SetInteger", api.SetInteger(c, spec->int_vr, spec->n_int, spec->int_value)))
                || failed("fmi2ExitInitializationMode", api.ExitInitializationMode(c)))
                return 2;
            printf("init %.9g\n", now() - started);
            double t = 0.0, x;
            count = 0;
            double cpu_started = thread_cpu();
            started = now();
            for (long n = 1; !(t > stop || isclose(t, stop)); n++) {
                double next = n * step;
                if (next > stop && !isclose(next, stop)) next = stop;
                if (failed("fmi2DoStep", timing_do_step(c, t, next - t)) || failed("fmi2GetReal", timing_get_real(c, &xvr, &x)))
                    return 2;
                t = next;
                if (count < capacity) {
                    times[count] = t;
                    xs[count++] = x;
                }
            }
            double seconds = now() - started, cpu = thread_cpu() - cpu_started;
            timing_run_done(k, r);
            printf("loop %.9g %zu %.9g\n", seconds, count, cpu);
            if (failed("fmi2Terminate", api.Terminate(c))) return 2;
            api.FreeInstance(c);
        }
        for (size_t i = 0; i < count; i++) printf("x %.17g %.17g\n", times[i], xs[i]);
    }
    free(times);
    free(xs);
    return 0;
}
