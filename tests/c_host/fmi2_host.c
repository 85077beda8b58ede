/*
 * fmi2_host.c -- minimal FMI 2.0 co-simulation host for tests (compiled by the
 * tests and by `vibrofmu doctor`, never committed as a binary).
 *
 * Drives one FMU binary through the C API the way system-simulation tools do:
 *   dlopen, fmi2Instantiate (logger prints to stderr), fmi2SetupExperiment,
 *   fmi2EnterInitializationMode, fmi2SetReal of the VR=VALUE arguments,
 *   fmi2ExitInitializationMode, fmi2DoStep loop with fmi2GetReal of the output
 *   value references after each step, fmi2Terminate, fmi2FreeInstance, dlclose.
 *
 * The same file compiles for Windows (x86_64-w64-mingw32-gcc, LoadLibrary instead of dlopen).
 *
 * Usage: fmi2_host LIBRARY RESOURCE_URI GUID START STOP STEP VR[,VR...] [VR=VALUE ...]
 *
 * stdout: CSV, header "time,<vr>,...", one row at START and one after every
 * step, numbers printed with %.17g (round-trips doubles exactly).
 * Communication points are computed as FMPy's simulate_fmu does
 * (START + n*STEP, the last one clipped to STOP), so both hosts make the same calls.
 *
 * With FMI2_HOST_LIST_LIBRARIES set (Linux), the host lists the files mapped into
 * its process (/proc/self/maps) on stderr before it exits, one "fmi2_host: mapped
 * PATH" line each: the tests check that a native FMU brings no Python along.
 *
 * With FMI2_HOST_TIMING set, the host reports on stderr the wall time of loading the
 * library + fmi2Instantiate + initialization, and of the doStep + fmi2GetReal loop
 * per output row ("fmi2_host: timing instantiate_s=... per_output_s=... rows=...");
 * with FMI2_HOST_QUIET set it prints no CSV rows (so that printing is not timed).
 *
 * Exit code: 0 success; 1 usage or loading error; 2 an FMI call returned
 * fmi2Error or fmi2Fatal (named on stderr).  After fmi2Error the instance is
 * still freed (fmi2Terminate is not allowed in the error state); after
 * fmi2Fatal nothing more is called, as the standard requires.
 */

#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* fmu_src/fmi/: the table of fmi2 functions (Fmi2Api) and loading a library -- dlopen, or on Windows
   (cross-compiled with mingw-w64, run under wine) LoadLibrary -- on the FMI standard's headers */
#include "fmi2_host_api.h"

static double now(void)
{
#ifdef _WIN32
    LARGE_INTEGER count, frequency;
    QueryPerformanceCounter(&count);
    QueryPerformanceFrequency(&frequency);
    return (double)count.QuadPart / (double)frequency.QuadPart;
#else
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
#endif
}

static int quiet = 0;
static double t_loaded, t_initialised, t_done;
static long rows_done = 0;

typedef Fmi2Api Api;

#define MAX_VRS 64

static const char *const STATUS_NAMES[] = {"fmi2OK", "fmi2Warning", "fmi2Discard",
                                           "fmi2Error", "fmi2Fatal", "fmi2Pending"};

static const char *status_name(fmi2Status s)
{
    return (unsigned)s < sizeof STATUS_NAMES / sizeof *STATUS_NAMES ? STATUS_NAMES[s] : "unknown status";
}

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    (void)env;
    va_list args;
    fprintf(stderr, "[%s] %s (%s): ", status_name(status), instance ? instance : "",
            category ? category : "");
    va_start(args, message);
    vfprintf(stderr, message ? message : "", args);
    va_end(args);
    fputc('\n', stderr);
}

static int die(const char *what, const char *detail)
{
    fprintf(stderr, "fmi2_host: %s%s%s\n", what, detail ? ": " : "", detail ? detail : "");
    return 1;
}

/* The functions this host calls: the name of the first the library lacks, or NULL. */
static const char *load_api(void *lib, Api *api)
{
    static const char *const NEEDED[] = {"Instantiate", "FreeInstance", "SetupExperiment", "EnterInitializationMode",
                                         "ExitInitializationMode", "Terminate", "GetReal", "SetReal", "DoStep", NULL};
    fmi2_api_load(lib, api);
    return fmi2_api_missing(api, NEEDED);
}

/* "15,16" -> vrs; returns the count, 0 on a malformed list */
static size_t parse_vrs(char *text, fmi2ValueReference vrs[MAX_VRS])
{
    size_t n = 0;
    for (char *tok = strtok(text, ","); tok != NULL; tok = strtok(NULL, ",")) {
        char *end;
        unsigned long v = strtoul(tok, &end, 10);
        if (*end != '\0' || end == tok || n == MAX_VRS) return 0;
        vrs[n++] = (fmi2ValueReference)v;
    }
    return n;
}

static int parse_real(const char *text, double *out)
{
    char *end;
    *out = strtod(text, &end);
    return end != text && *end == '\0';
}

/* "7=-1" -> (7, -1.0); 0 when malformed */
static int parse_param(const char *text, fmi2ValueReference *vr, fmi2Real *value)
{
    char *end;
    unsigned long v = strtoul(text, &end, 10);
    if (end == text || *end != '=' || !parse_real(end + 1, value)) return 0;
    *vr = (fmi2ValueReference)v;
    return 1;
}

/* math.isclose(a, b) with its default rel_tol = 1e-9, as used by FMPy's simulate_fmu */
static int isclose(double a, double b)
{
    return fabs(a - b) <= 1e-9 * fmax(fabs(a), fabs(b));
}

/* Non-zero when st is worse than fmi2Warning; says which call failed. */
static int failed(const char *call, fmi2Status st, double t)
{
    if (st <= fmi2Warning) return 0;
    fprintf(stderr, "fmi2_host: %s returned %s (%d) at t = %.17g\n", call, status_name(st), (int)st, t);
    return 1;
}

static void print_row(double t, const fmi2Real *values, size_t n)
{
    rows_done++;
    if (quiet) return;
    printf("%.17g", t);
    for (size_t i = 0; i < n; i++) printf(",%.17g", values[i]);
    putchar('\n');
}

typedef struct {
    double start, stop, step;
    fmi2ValueReference out[MAX_VRS];
    size_t nout;
    fmi2ValueReference param_vr[MAX_VRS];
    fmi2Real param_value[MAX_VRS];
    size_t nparams;
} Experiment;

/* Initialise with the parameters, step to the stop time, print the outputs.
   Returns the first status worse than fmi2Warning, or fmi2OK. */
static fmi2Status simulate(const Api *api, fmi2Component c, const Experiment *e)
{
    fmi2Status st;
    fmi2Real values[MAX_VRS];
    double t = e->start;

    if (failed("fmi2SetupExperiment", st = api->SetupExperiment(c, 0, 0.0, t, 1, e->stop), t)) return st;
    if (failed("fmi2EnterInitializationMode", st = api->EnterInitializationMode(c), t)) return st;
    if (e->nparams > 0
        && failed("fmi2SetReal", st = api->SetReal(c, e->param_vr, e->nparams, e->param_value), t))
        return st;
    if (failed("fmi2ExitInitializationMode", st = api->ExitInitializationMode(c), t)) return st;
    t_initialised = now();

    printf("time");
    for (size_t i = 0; i < e->nout; i++) printf(",%u", e->out[i]);
    putchar('\n');
    if (failed("fmi2GetReal", st = api->GetReal(c, e->out, e->nout, values), t)) return st;
    print_row(t, values, e->nout);
    for (long n = 1; !(t > e->stop || isclose(t, e->stop)); n++) {
        double next = e->start + n * e->step;
        if (next > e->stop && !isclose(next, e->stop)) next = e->stop;
        if (failed("fmi2DoStep", st = api->DoStep(c, t, next - t, 1), t)) return st;
        t = next;
        if (failed("fmi2GetReal", st = api->GetReal(c, e->out, e->nout, values), t)) return st;
        print_row(t, values, e->nout);
    }
    t_done = now();
    if (failed("fmi2Terminate", st = api->Terminate(c), t)) return st;
    return fmi2OK;
}

/* The files mapped into this process (FMI2_HOST_LIST_LIBRARIES), each once. */
static void list_libraries(void)
{
#ifndef _WIN32
    FILE *maps = fopen("/proc/self/maps", "r");
    char line[4096], last[4096] = "";
    if (maps == NULL) return;
    while (fgets(line, sizeof line, maps) != NULL) {
        char *path = strchr(line, '/');
        if (path == NULL) continue;
        path[strcspn(path, "\n")] = '\0';
        if (strcmp(path, last) == 0) continue;
        fprintf(stderr, "fmi2_host: mapped %s\n", path);
        snprintf(last, sizeof last, "%s", path);
    }
    fclose(maps);
#endif
}

int main(int argc, char **argv)
{
    Experiment e;
    if (argc < 8)
        return die("usage", "fmi2_host LIBRARY RESOURCE_URI GUID START STOP STEP VR[,VR...] [VR=VALUE ...]");
    if (!parse_real(argv[4], &e.start) || !parse_real(argv[5], &e.stop) || !parse_real(argv[6], &e.step)
        || !(e.step > 0))
        return die("START STOP STEP must be numbers, STEP > 0", NULL);
    if ((e.nout = parse_vrs(argv[7], e.out)) == 0) return die("bad value reference list", argv[7]);
    if (argc - 8 > MAX_VRS) return die("too many parameters", NULL);
    for (e.nparams = 0; e.nparams < (size_t)(argc - 8); e.nparams++)
        if (!parse_param(argv[8 + e.nparams], &e.param_vr[e.nparams], &e.param_value[e.nparams]))
            return die("expected VR=VALUE, got", argv[8 + e.nparams]);

    quiet = getenv("FMI2_HOST_QUIET") != NULL;
    t_loaded = now();
    void *lib = fmi2_host_open(argv[1]);
    if (lib == NULL) return die("cannot load the FMU binary", fmi2_host_error());
    Api api;
    const char *missing = load_api(lib, &api);
    if (missing != NULL) return die("missing FMI function", missing);

    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = api.Instantiate("c_host", fmi2CoSimulation, argv[3], argv[2], &callbacks, 0, 0);
    if (c == NULL) return die("fmi2Instantiate failed", NULL);

    fmi2Status st = simulate(&api, c, &e);
    fflush(stdout);
    if (getenv("FMI2_HOST_LIST_LIBRARIES") != NULL) list_libraries();
    if (getenv("FMI2_HOST_TIMING") != NULL && st == fmi2OK)
        fprintf(stderr, "fmi2_host: timing instantiate_s=%.9g per_output_s=%.9g rows=%ld\n", t_initialised - t_loaded,
                (t_done - t_initialised) / (double)(rows_done > 1 ? rows_done - 1 : 1), rows_done);
    if (st != fmi2Fatal) api.FreeInstance(c);
    fmi2_host_close(lib);
    return st == fmi2OK ? 0 : 2;
}
