/*
 * fmi2_me_cvode.c -- a minimal FMI 2.0 Model Exchange host in C on SUNDIALS' CVODE (Debian's libsundials-dev), for
 * the tests (compiled by them, never committed as a binary): the loop a C tool's Model Exchange runs (fmusim's
 * with CVODE, Reference-FMUs), independent of FMPy's Python loop and its bundled SUNDIALS.
 *
 *   dlopen, fmi2Instantiate(fmi2ModelExchange), fmi2SetupExperiment(0, STOP), fmi2EnterInitializationMode,
 *   fmi2SetReal of the VR=VALUE arguments, fmi2ExitInitializationMode, fmi2NewDiscreteStates until none is needed,
 *   fmi2EnterContinuousTimeMode; CVODE (BDF, Newton with a dense direct solver, rtol RTOL, atol = RTOL times each
 *   state's nominal, the step at most STOP / 50: FMPy's settings) over the right-hand side fmi2SetTime,
 *   fmi2SetContinuousStates, fmi2GetDerivatives, with the event indicators as root functions (at a root: event
 *   mode, fmi2NewDiscreteStates, continuous-time mode, CVodeReInit); CV_NORMAL to each output time n INTERVAL,
 *   where the outputs are read (fmi2GetReal after fmi2SetTime and fmi2SetContinuousStates at that time).
 *
 * Usage: fmi2_me_cvode LIBRARY RESOURCE_URI GUID NX NZ STOP INTERVAL RTOL VR[,VR...] [VR=VALUE ...]
 * (NX continuous states and NZ event indicators: the modelDescription's)
 *
 * stdout: CSV, header "time,<vr>,...", one row at 0 and one at every output time, numbers printed with %.17g.
 * stderr: the FMU's log lines, and at the end "fmi2_me_cvode: steps N rhs M events K" (CVodeGetNumSteps,
 * CVodeGetNumRhsEvals summed over the restarts, the events handled).
 * Exit code: 0 success; 1 usage or loading error; 2 an FMI call returned fmi2Error or fmi2Fatal, or CVODE failed
 * (named on stderr).
 */
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <cvode/cvode.h>
#include <nvector/nvector_serial.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunmatrix/sunmatrix_dense.h>

#include "fmi2FunctionTypes.h"

#define FUNCTIONS(X)                                                                                          \
    X(Instantiate) X(FreeInstance) X(SetupExperiment) X(EnterInitializationMode) X(ExitInitializationMode)    \
    X(Terminate) X(GetReal) X(SetReal) X(NewDiscreteStates) X(EnterContinuousTimeMode) X(EnterEventMode)      \
    X(SetTime) X(SetContinuousStates) X(GetDerivatives) X(GetEventIndicators) X(GetContinuousStates)          \
    X(GetNominalsOfContinuousStates) X(CompletedIntegratorStep)

static struct {
#define FIELD(name) fmi2##name##TYPE *name;
    FUNCTIONS(FIELD)
#undef FIELD
} fmi;

static fmi2Component C;
static size_t NX, NZ;
static long EVENTS;

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env; (void)name;
    va_list ap;
    va_start(ap, message);
    fprintf(stderr, "[%d] %s: ", (int)status, category ? category : "");
    vfprintf(stderr, message, ap);
    fputc('\n', stderr);
    va_end(ap);
}

static void fail(const char *call, fmi2Status status)
{
    fprintf(stderr, "fmi2_me_cvode: %s returned %d\n", call, (int)status);
    if (status != fmi2Fatal) fmi.FreeInstance(C);
    exit(2);
}

#define CHECK(call, expr)                          \
    do {                                           \
        fmi2Status st_ = (expr);                   \
        if (st_ > fmi2Warning) fail(call, st_);    \
    } while (0)

/* The right-hand side and the root functions: the FMU at (t, y). Nonzero (CVODE: unrecoverable) on an error. */
static int set_point(double t, N_Vector y)
{
    if (fmi.SetTime(C, t) > fmi2Warning) return -1;
    return fmi.SetContinuousStates(C, N_VGetArrayPointer(y), NX) > fmi2Warning ? -1 : 0;
}

static int rhs(sunrealtype t, N_Vector y, N_Vector ydot, void *user)
{
    (void)user;
    if (set_point(t, y)) return -1;
    return fmi.GetDerivatives(C, N_VGetArrayPointer(ydot), NX) > fmi2Warning ? -1 : 0;
}

static int roots(sunrealtype t, N_Vector y, sunrealtype *g, void *user)
{
    (void)user;
    if (set_point(t, y)) return -1;
    return fmi.GetEventIndicators(C, g, NZ) > fmi2Warning ? -1 : 0;
}

/* Event mode until the discrete states settle; 1 when the FMU asks to terminate. */
static int event_iteration(void)
{
    fmi2EventInfo info;
    do {
        CHECK("fmi2NewDiscreteStates", fmi.NewDiscreteStates(C, &info));
    } while (info.newDiscreteStatesNeeded);
    if (info.terminateSimulation) return 1;
    CHECK("fmi2EnterContinuousTimeMode", fmi.EnterContinuousTimeMode(C));
    return 0;
}

int main(int argc, char **argv)
{
    if (argc < 10) {
        fprintf(stderr, "usage: %s LIBRARY RESOURCE_URI GUID NX NZ STOP INTERVAL RTOL VR[,VR...] [VR=VALUE ...]\n",
                argv[0]);
        return 1;
    }
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (lib == NULL) {
        fprintf(stderr, "fmi2_me_cvode: %s\n", dlerror());
        return 1;
    }
#define LOAD(name)                                                                    \
    *(void **)(&fmi.name) = dlsym(lib, "fmi2" #name);                                 \
    if (fmi.name == NULL) {                                                           \
        fprintf(stderr, "fmi2_me_cvode: the library has no fmi2" #name "\n");        \
        return 1;                                                                     \
    }
    FUNCTIONS(LOAD)
#undef LOAD
    NX = (size_t)atoi(argv[4]);
    NZ = (size_t)atoi(argv[5]);
    const double stop = atof(argv[6]), interval = atof(argv[7]), rtol = atof(argv[8]);
    unsigned outputs[64];
    size_t n_out = 0;
    for (char *p = strtok(argv[9], ","); p != NULL && n_out < 64; p = strtok(NULL, ",")) outputs[n_out++] = atoi(p);

    static const fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    C = fmi.Instantiate("me", fmi2ModelExchange, argv[3], argv[2], &callbacks, fmi2False, fmi2False);
    if (C == NULL) {
        fprintf(stderr, "fmi2_me_cvode: fmi2Instantiate returned NULL\n");
        return 2;
    }
    CHECK("fmi2SetupExperiment", fmi.SetupExperiment(C, fmi2False, 0.0, 0.0, fmi2True, stop));
    CHECK("fmi2EnterInitializationMode", fmi.EnterInitializationMode(C));
    for (int i = 10; i < argc; i++) {
        fmi2ValueReference vr = (fmi2ValueReference)atoi(argv[i]);
        const char *eq = strchr(argv[i], '=');
        if (eq == NULL) {
            fprintf(stderr, "fmi2_me_cvode: %s is not VR=VALUE\n", argv[i]);
            return 1;
        }
        double value = atof(eq + 1);
        CHECK("fmi2SetReal", fmi.SetReal(C, &vr, 1, &value));
    }
    CHECK("fmi2ExitInitializationMode", fmi.ExitInitializationMode(C));
    if (event_iteration()) return 0;

    SUNContext ctx;
    if (SUNContext_Create(NULL, &ctx)) return 2;
    N_Vector y = N_VNew_Serial((sunindextype)NX, ctx), atol = N_VNew_Serial((sunindextype)NX, ctx);
    CHECK("fmi2GetContinuousStates", fmi.GetContinuousStates(C, N_VGetArrayPointer(y), NX));
    CHECK("fmi2GetNominalsOfContinuousStates", fmi.GetNominalsOfContinuousStates(C, N_VGetArrayPointer(atol), NX));
    for (size_t i = 0; i < NX; i++) N_VGetArrayPointer(atol)[i] *= rtol;
    void *mem = CVodeCreate(CV_BDF, ctx);
    SUNMatrix A = SUNDenseMatrix((sunindextype)NX, (sunindextype)NX, ctx);
    SUNLinearSolver LS = SUNLinSol_Dense(y, A, ctx);
    int flag = CVodeInit(mem, rhs, 0.0, y);
    if (!flag) flag = CVodeSVtolerances(mem, rtol, atol);
    if (!flag) flag = CVodeSetLinearSolver(mem, LS, A);
    if (!flag) flag = CVodeSetMaxStep(mem, stop / 50.0);
    if (!flag) flag = CVodeSetMaxNumSteps(mem, 1000000);
    if (!flag && NZ > 0) flag = CVodeRootInit(mem, (int)NZ, roots);
    if (flag) {
        fprintf(stderr, "fmi2_me_cvode: CVODE set-up failed (%d)\n", flag);
        return 2;
    }
    long steps = 0, evaluations = 0;
    double row[64];
    printf("time");
    for (size_t j = 0; j < n_out; j++) printf(",%u", outputs[j]);
    printf("\n");
    CHECK("fmi2GetReal", fmi.GetReal(C, outputs, n_out, row));
    printf("%.17g", 0.0);
    for (size_t j = 0; j < n_out; j++) printf(",%.17g", row[j]);
    printf("\n");
    const long n_rows = lround(stop / interval);
    for (long n = 1; n <= n_rows; n++) {
        const double t_out = n == n_rows ? stop : n * interval;
        double t = 0.0;
        for (;;) {
            flag = CVode(mem, t_out, y, &t, CV_NORMAL);
            if (flag < 0) {
                fprintf(stderr, "fmi2_me_cvode: CVode failed (%d) at t = %.17g\n", flag, t);
                fmi.FreeInstance(C);
                return 2;
            }
            if (flag != CV_ROOT_RETURN) break;
            /* an event at t: the FMU at the root, event mode, then on from there with a fresh history */
            long s = 0, e = 0;
            CVodeGetNumSteps(mem, &s);
            CVodeGetNumRhsEvals(mem, &e);
            steps += s;
            evaluations += e;
            EVENTS++;
            if (set_point(t, y)) fail("fmi2SetContinuousStates", fmi2Error);
            CHECK("fmi2EnterEventMode", fmi.EnterEventMode(C));
            if (event_iteration()) {
                fprintf(stderr, "fmi2_me_cvode: terminateSimulation at t = %.17g\n", t);
                n = n_rows;
                break;
            }
            CHECK("fmi2GetContinuousStates", fmi.GetContinuousStates(C, N_VGetArrayPointer(y), NX));
            CVodeReInit(mem, t, y);
        }
        if (set_point(t, y)) fail("fmi2SetContinuousStates", fmi2Error);
        fmi2Boolean enter = fmi2False, terminate = fmi2False;
        CHECK("fmi2CompletedIntegratorStep", fmi.CompletedIntegratorStep(C, fmi2True, &enter, &terminate));
        CHECK("fmi2GetReal", fmi.GetReal(C, outputs, n_out, row));
        printf("%.17g", t);
        for (size_t j = 0; j < n_out; j++) printf(",%.17g", row[j]);
        printf("\n");
        if (terminate) break;
    }
    long s = 0, e = 0;
    CVodeGetNumSteps(mem, &s);
    CVodeGetNumRhsEvals(mem, &e);
    fprintf(stderr, "fmi2_me_cvode: steps %ld rhs %ld events %ld\n", steps + s, evaluations + e, EVENTS);
    CVodeFree(&mem);
    SUNLinSolFree(LS);
    SUNMatDestroy(A);
    N_VDestroy(y);
    N_VDestroy(atol);
    SUNContext_Free(&ctx);
    CHECK("fmi2Terminate", fmi.Terminate(C));
    fmi.FreeInstance(C);
    dlclose(lib);
    return 0;
}
