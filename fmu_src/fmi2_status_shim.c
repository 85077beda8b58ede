/*
 * fmi2_status_shim.c -- FMI 2.0 co-simulation wrapper around a pythonfmu
 * 0.7.0 library, giving Python slaves a way to return fmi2Error.
 *
 * Layout inside the FMU (done by harness/vibrofmu/fmus/shim.py):
 *   binaries/linux64/<id>.so            this shim (with pyloader.c)
 *   binaries/linux64/<id>_pythonfmu.so  pythonfmu's original library
 *   resources/python_env.txt            the Python it needs (pythonenv.py)
 *
 * The inner library is found next to the shim's own file (dladdr), so it
 * works wherever the host extracted the FMU.  Its name is derived from the
 * shim's own file name: "<name>.so" -> "<name>_pythonfmu.so".
 *
 * Status mapping.  The Python slave exposes an Integer variable with value
 * reference STATUS_VR (given at compile time) holding 0 (ok) or 3 (error).
 * After every state-changing call (setup experiment, enter/exit
 * initialization, doStep, set*, reset, setFMUstate) that the inner library
 * answered with OK/Warning/Discard, the shim reads that flag; if it is 3 the
 * call returns fmi2Error instead.
 *
 * Interrupts.  A SIGINT (Ctrl-C) that reaches a Python host while the slave's
 * Python code runs becomes a KeyboardInterrupt there; pythonfmu would turn it
 * into fmi2Fatal and the host would go on.  The slave catches it instead
 * (slave_support._interruptible), halts, and sets the flag to 130; the call
 * returns fmi2Error and the shim re-raises SIGINT once, after the inner call
 * has returned (no Python code of the slave runs after it), so the host's own
 * handler sees the user's interrupt: a Python host gets its KeyboardInterrupt
 * as soon as the call returns.  (fmi2DeSerializeFMUstate is not mapped:
 * it does not involve the slave instance, see there.)
 *
 * Per-instance state:
 *   OK    everything is forwarded.
 *   ERROR entered when a state-changing call ends in fmi2Error.  As in the
 *         FMI 2.0 state machine (and the Modelica Reference-FMUs masks),
 *         only getters, status/FMU-state inquiries, fmi2SetDebugLogging,
 *         fmi2Reset, fmi2SetFMUstate and fmi2FreeInstance are forwarded;
 *         every other call -- including fmi2Terminate, which the standard
 *         does not allow in the error state -- returns fmi2Error without
 *         being forwarded and logs "call X not allowed after an error".
 *         fmi2Reset (or fmi2SetFMUstate) leaves ERROR when the inner call
 *         succeeds and the flag reads 0 afterwards.
 *   FATAL entered the first time the inner library returns fmi2Fatal.  For
 *         pythonfmu this means a Python exception was raised and its C++
 *         layer has already released the Python slave object (but keeps
 *         the dangling pointer).  Nothing is forwarded any more; every call
 *         returns fmi2Fatal without touching output arguments.
 *         fmi2FreeInstance does NOT forward either: pythonfmu's destructor
 *         would release the same Python objects a second time (a
 *         use-after-free).  The inner instance is leaked on purpose.
 *
 * Logging.  pythonfmu only passes messages on (even errors) when debug
 * logging is on, so the inner instance always gets loggingOn=true and a
 * logger of the shim's own (forward_log), which passes Warning/Discard/
 * Error/Fatal messages to the host unconditionally and fmi2OK messages only
 * as enabled by loggingOn / fmi2SetDebugLogging (which the shim handles
 * itself and does not forward).
 *
 * NULL component pointers give fmi2Error (fmi2FreeInstance(NULL) is a no-op).
 *
 * Logging, the error mode, the finite-value check of fmi2GetReal and the state table (which calls an instance
 * in the error state answers) are fmu_src/fmi/fmi2_layer.c's, shared with the native FMUs; the FMI 2.0 phases
 * (instantiated, initialization mode, ...) are the slave's (slave_support.StatusSlave, the same table).
 *
 * Fast path.  Python's per-call cost (pythonfmu's callbacks, ~4 us each)
 * dominates a plant step on the compiled kernel (vibrokernel.c, < 1 us).  A
 * slave whose model lives in C can hand the shim that model, during a call
 * the shim forwarded to it, with vibro_fast_path_attach (ctypes): a step
 * function, the model's address, its "enabled" flag and where its Real and
 * Boolean outputs live.  Then, while the instance is OK and the flag is set,
 *   fmi2DoStep   calls step(model, t, h); 0 means done (fmi2OK, no Python);
 *                anything else forwards the call to the slave, which reports
 *                the failure the model left pending (or re-checks the input);
 *   fmi2GetReal / fmi2GetBoolean of outputs in the table are read from the
 *                model; any other reference forwards the whole call;
 *   fmi2SetReal  of inputs given with vibro_fast_path_inputs (the controller)
 *                writes them to the model and calls inputs_set(model) (0:
 *                done); any other reference forwards the whole call.
 * The slave reads and writes the same memory for every other call, so the
 * two paths never disagree.  fmi2Reset, fmi2SetFMUstate and fmi2FreeInstance
 * detach first (the slave may free the model); the slave attaches again when
 * it builds a model.
 *
 * Process exit.  pythonfmu 0.7.0 (PySlaveInstance.cpp) keeps its interpreter
 * holder in a global std::shared_ptr<PyState> and has two exit paths for it:
 * the shared_ptr's static destructor (registered with __cxa_atexit when the
 * library is loaded) and an ELF destructor, onLibraryUnload, that runs
 * finalizePythonInterpreter() { pyState = nullptr; } on the same object.  At
 * exit() the atexit list runs before _dl_fini, so the static destructor frees
 * the PyState block first and onLibraryUnload then reads its freed reference
 * count (valgrind: "Invalid read of size 4 at finalizePythonInterpreter",
 * inside a block of size 128 freed in __run_exit_handlers).  In a host that
 * is not Python, pythonfmu also owns the interpreter, and destroying PyState
 * makes its worker thread run Py_Finalize at exit; with the slave's scipy
 * imports that reads freed memory too (a type object made by scipy's _uarray,
 * freed by its module's free function, decref'd again while the final GC
 * clears a dict) and typically kills the host with SIGSEGV after it has
 * finished its work.  RTLD_NODELETE would not help: it only keeps dlclose
 * from unmapping the library; _dl_fini still runs onLibraryUnload last.
 * So, when it loads the inner library, the shim
 *   1. (before) initializes the interpreter itself if the host has not
 *      (pyloader.c: it also loads libpython and points Python at the
 *      environment recorded at build time), then releases
 *      the GIL (Py_InitializeEx(0): unlike pythonfmu's Py_Initialize() it
 *      leaves the host's signal handling alone -- no SIGINT turned into a
 *      KeyboardInterrupt of whatever Python code runs next, no SIGPIPE
 *      ignored).  pythonfmu then finds an initialized interpreter and never
 *      finalizes it, exactly as under a Python host such as FMPy.  The shim
 *      does not finalize it either: the process's end reclaims it (Python-level
 *      atexit handlers do not run and unflushed sys.stdout output is lost; the
 *      slave reports through the FMI logger).
 *   2. registers with atexit() a call of pythonfmu's exported
 *      finalizePythonInterpreter().  Exit handlers run in reverse order of
 *      registration, so it empties the shared_ptr before the static destructor
 *      registered earlier by the inner library runs, and both that destructor
 *      and onLibraryUnload then find an empty pointer.  The handler belongs to
 *      the shim, so it runs when the host dlclose()s the shim, or at exit; with
 *      the interpreter not owned by pythonfmu it only joins PyState's finished
 *      thread.  A later fmi2Instantiate makes a new PyState as needed.
 */

#define _GNU_SOURCE
#include <dlfcn.h>
#include <math.h>
#include <pthread.h>
#include <signal.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <wchar.h>

#ifndef STATUS_VR
#error "compile with -DSTATUS_VR=<value reference of the Integer status flag>"
#endif

#define FLAG_ERROR 3
#define FLAG_INTERRUPTED 130 /* slave_support.STATUS_INTERRUPTED */

#include "fmi2_layer.h"    /* the FMI 2.0 headers, logging, error mode, state table (fmu_src/fmi/) */
#include "fmi2_host_api.h" /* the table of fmi2 functions of the inner library (fmu_src/fmi/) */
#include "pyloader.h"      /* finding Python */

#define EXPORT __attribute__((visibility("default")))

/* ---- inner library ---- */


static Fmi2Api inner;
static void *inner_handle = NULL;
static char load_error[8192] = "";
static pthread_once_t load_once = PTHREAD_ONCE_INIT;

/* A static function: its address cannot be interposed by another library. */
static void anchor(void) {}

static void load_inner(void)
{
    Dl_info info;
    if (!dladdr((void *)&anchor, &info) || info.dli_fname == NULL) {
        snprintf(load_error, sizeof load_error, "cannot determine the shim's own path");
        return;
    }
    const char *own = info.dli_fname;
    size_t n = strlen(own);
    if (n > 3 && strcmp(own + n - 3, ".so") == 0) n -= 3;
    char path[4096];
    if ((size_t)snprintf(path, sizeof path, "%.*s_pythonfmu.so", (int)n, own) >= sizeof path) {
        snprintf(load_error, sizeof load_error, "path of the inner library is too long");
        return;
    }
    /* libpython loaded, the interpreter started (step 1 of "Process exit"), the modules there (pyloader.c) */
    if (vibro_python_prepare(own, load_error, sizeof load_error) != 0) return;
    void *h = dlopen(path, RTLD_NOW | RTLD_LOCAL | RTLD_DEEPBIND);
    if (h == NULL) {
        snprintf(load_error, sizeof load_error, "cannot load inner library: %s", dlerror());
        return;
    }
    fmi2_api_load(h, &inner);
    static const char *const ALL[] = {
#define FMI2_API_NAME(name) #name,
        FMI2_API_FUNCTIONS(FMI2_API_NAME)
#undef FMI2_API_NAME
        NULL};
    const char *missing = fmi2_api_missing(&inner, ALL);
    if (missing != NULL) {
        snprintf(load_error, sizeof load_error, "symbol fmi2%s missing in %s", missing, path);
        dlclose(h);
        memset(&inner, 0, sizeof inner);
        return;
    }
    void (*release_py_state)(void);
    *(void **)(&release_py_state) = dlsym(h, "finalizePythonInterpreter");
    if (release_py_state != NULL) atexit(release_py_state);
    inner_handle = h; /* never dlclose'd: pythonfmu keeps a Python thread alive */
}

/* ---- shim component ---- */

#define FAST_MAX 32 /* most Real (and Boolean) outputs served; fast_path.FAST_MAX */

typedef struct {
    int (*step)(void *model, double t, double h); /* 0: the step is done */
    void *model;
    const int64_t *enabled;
    size_t n_real, n_boolean;
    fmi2ValueReference real_vr[FAST_MAX], boolean_vr[FAST_MAX];
    double *real[FAST_MAX];
    int64_t *boolean[FAST_MAX];
    /* Real inputs (vibro_fast_path_inputs): written to the model, then inputs_set(model); 0 means done */
    int (*inputs_set)(void *model);
    size_t n_input;
    fmi2ValueReference input_vr[FAST_MAX];
    double *input[FAST_MAX];
} FastPath;

typedef struct {
    Fmi2Layer fmi;                  /* the host's callbacks, name, logging, error mode (fmi2_layer.h) */
    fmi2Component inner;
    fmi2CallbackFunctions inner_cb; /* given to the inner library: logger = forward_log */
    FastPath fast;                  /* step == NULL: none attached */
    int error_logged;               /* the inner library logged an error during the current call */
    int stop_defined;               /* fmi2SetupExperiment's stop time (the fast path steps only before it) */
    double stop_time;
    unsigned long long fast_steps;  /* doSteps done by the fast path (vibro_fast_path_steps) */
    int interrupted;                /* the flag read FLAG_INTERRUPTED and SIGINT was re-raised */
} Shim;

/* The shim whose forwarded call is running on this thread (for vibro_fast_path_attach). */
static __thread Shim *calling_shim = NULL;

static fmi2Status forward_from(Shim *s, fmi2Status (*call)(fmi2Component), fmi2Component inner_instance)
{
    calling_shim = s;
    fmi2Status st = call(inner_instance);
    calling_shim = NULL;
    return st;
}

static int fast_enabled(const Shim *s)
{
    return s->fmi.mode == FMI2_MODE_OK && s->fast.step != NULL && *s->fast.enabled != 0;
}

/* Index of vr in a fast-path table, or -1. */
static int fast_index(const fmi2ValueReference *table, size_t n, fmi2ValueReference vr)
{
    for (size_t i = 0; i < n; i++)
        if (table[i] == vr) return (int)i;
    return -1;
}

/* Serve a whole getter call from the model, or return 0 (forward it). */
static int fast_get_real(const Shim *s, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    if (s->fast.step == NULL || s->fmi.mode == FMI2_MODE_FATAL) return 0;
    for (size_t i = 0; i < nvr; i++)
        if (fast_index(s->fast.real_vr, s->fast.n_real, vr[i]) < 0) return 0;
    for (size_t i = 0; i < nvr; i++)
        value[i] = *s->fast.real[fast_index(s->fast.real_vr, s->fast.n_real, vr[i])];
    return 1;
}

static int fast_get_boolean(const Shim *s, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    if (s->fast.step == NULL || s->fmi.mode == FMI2_MODE_FATAL) return 0;
    for (size_t i = 0; i < nvr; i++)
        if (fast_index(s->fast.boolean_vr, s->fast.n_boolean, vr[i]) < 0) return 0;
    for (size_t i = 0; i < nvr; i++)
        value[i] = *s->fast.boolean[fast_index(s->fast.boolean_vr, s->fast.n_boolean, vr[i])] != 0;
    return 1;
}

static void detach(Shim *s) { memset(&s->fast, 0, sizeof s->fast); }

/* How many doSteps of instance c the fast path has done (tests and benchmarks check that it is used). */
EXPORT unsigned long long vibro_fast_path_steps(fmi2Component c)
{
    return fmi2_live(c, FMI2_LIVE_INSTANCE) ? ((const Shim *)c)->fast_steps : 0;
}

/* Called by the slave (ctypes) while the shim forwards a call to it; outside such a call it does nothing.
   step == NULL detaches. Returns 1 if attached. */
EXPORT int vibro_fast_path_attach(int (*step)(void *, double, double), void *model, const int64_t *enabled,
                                  size_t n_real, const unsigned int *real_vr, double *const *real,
                                  size_t n_boolean, const unsigned int *boolean_vr, int64_t *const *boolean)
{
    Shim *s = calling_shim;
    if (s == NULL) return 0;
    detach(s);
    if (step == NULL || model == NULL || enabled == NULL || n_real > FAST_MAX || n_boolean > FAST_MAX) return 0;
    for (size_t i = 0; i < n_real; i++) {
        s->fast.real_vr[i] = real_vr[i];
        s->fast.real[i] = real[i];
    }
    for (size_t i = 0; i < n_boolean; i++) {
        s->fast.boolean_vr[i] = boolean_vr[i];
        s->fast.boolean[i] = boolean[i];
    }
    s->fast.n_real = n_real;
    s->fast.n_boolean = n_boolean;
    s->fast.model = model;
    s->fast.enabled = enabled;
    s->fast.step = step;
    return 1;
}

/* After vibro_fast_path_attach, in the same forwarded call: the model's Real inputs, set by fmi2SetReal in C while
   the fast path is enabled (then inputs_set(model) recomputes what depends on them; nonzero: the call is forwarded
   to the slave as well, which sets the same values and reports). Returns 1 if taken. */
EXPORT int vibro_fast_path_inputs(int (*inputs_set)(void *), size_t n_input, const unsigned int *input_vr,
                                  double *const *input)
{
    Shim *s = calling_shim;
    if (s == NULL || s->fast.step == NULL || inputs_set == NULL || n_input > FAST_MAX) return 0;
    for (size_t i = 0; i < n_input; i++) {
        s->fast.input_vr[i] = input_vr[i];
        s->fast.input[i] = input[i];
    }
    s->fast.n_input = n_input;
    s->fast.inputs_set = inputs_set;
    return 1;
}

/* Serve a whole fmi2SetReal call in C, or return 0 (forward it). */
static int fast_set_real(Shim *s, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    if (!fast_enabled(s) || s->fast.inputs_set == NULL) return 0;
    for (size_t i = 0; i < nvr; i++)
        if (fast_index(s->fast.input_vr, s->fast.n_input, vr[i]) < 0) return 0;
    /* Issue 15: every input's valid range (vibromodel/parameters.py, RULES) contains [-1e6, 1e6]; a value
       outside it, or not finite, goes to the slave, which checks the input's own rule and names it. */
    for (size_t i = 0; i < nvr; i++)
        if (!(fabs(value[i]) <= 1e6)) return 0;
    for (size_t i = 0; i < nvr; i++) *s->fast.input[fast_index(s->fast.input_vr, s->fast.n_input, vr[i])] = value[i];
    return s->fast.inputs_set(s->fast.model) == 0;
}

/* Logger handed to the inner library.  pythonfmu 0.7.0 drops *every* message
   (even errors and its "Fatal py exception" report) unless debug logging is
   on, so the inner instance always runs with logging on and the filtering is
   done here (fmi2_layer_emit): warnings, discards, errors and fatals always
   reach the host; fmi2OK messages only when the host enabled logging for their
   category. */
static void forward_log(fmi2ComponentEnvironment env, fmi2String instanceName, fmi2Status status,
                        fmi2String category, fmi2String message, ...)
{
    Shim *s = (Shim *)env;
    if (status >= fmi2Error) s->error_logged = 1;
    fmi2_layer_emit(&s->fmi, instanceName, status, category, message);
}

/* Record fatal results (never forward again after one). */
static fmi2Status note(Shim *s, fmi2Status st)
{
    if (st == fmi2Fatal) s->fmi.mode = FMI2_MODE_FATAL;
    return st;
}

/* The slave caught a KeyboardInterrupt (its flag reads FLAG_INTERRUPTED): raise SIGINT again, once per interrupt,
   now that no Python code of the slave runs any more; the host's handler takes it (a Python host: its
   KeyboardInterrupt on return; the default handler: the process ends as on Ctrl-C). */
static void redeliver_interrupt(Shim *s, int interrupted)
{
    if (interrupted && !s->interrupted) raise(SIGINT);
    s->interrupted = interrupted;
}

/* After a state-changing call: map the Python status flag onto the result. */
static fmi2Status settle(Shim *s, fmi2Status st, int may_clear_error)
{
    if (st == fmi2OK || st == fmi2Warning || st == fmi2Discard) {
        const fmi2ValueReference vr = STATUS_VR;
        fmi2Integer flag = 0;
        fmi2Status rs = inner.GetInteger(s->inner, &vr, 1, &flag);
        if (rs > fmi2Warning) st = rs;
        else if (flag == FLAG_ERROR || flag == FLAG_INTERRUPTED) st = fmi2Error;
        redeliver_interrupt(s, rs <= fmi2Warning && flag == FLAG_INTERRUPTED);
    }
    if (st == fmi2Fatal) s->fmi.mode = FMI2_MODE_FATAL;
    else if (st == fmi2Error) s->fmi.mode = FMI2_MODE_ERROR;
    else if (may_clear_error) s->fmi.mode = FMI2_MODE_OK;
    return st;
}

/* ---- state machine and outputs (issue 15) ----
   The slave (slave_support.StatusSlave) keeps the FMI 2.0 state and refuses calls made in the wrong one by
   logging an error.  Getters are not followed by settle(): an error the slave logged during one (an unknown
   value reference, a wrong type, a getter before initialisation) makes it fmi2Error here.  No Real is ever
   returned non-finite with fmi2OK: such a value gives fmi2Error naming it (fmi2_layer_finite_reals). */
static fmi2Status checked_getter(Shim *s, fmi2Status st)
{
    if (st <= fmi2Warning && s->error_logged) {
        const fmi2ValueReference vr = STATUS_VR;
        fmi2Integer flag = 0;
        st = fmi2Error;
        if (s->fmi.mode != FMI2_MODE_FATAL) s->fmi.mode = FMI2_MODE_ERROR;
        if (inner.GetInteger(s->inner, &vr, 1, &flag) <= fmi2Warning) /* interrupted during the getter? */
            redeliver_interrupt(s, flag == FLAG_INTERRUPTED);
    }
    s->error_logged = 0;
    return st;
}

/* After a fast-path step: every output it publishes is finite, or fmi2Error naming the first that is not. */
static fmi2Status fast_outputs_checked(Shim *s, fmi2Real t)
{
    for (size_t i = 0; i < s->fast.n_real; i++) {
        if (isfinite(*s->fast.real[i])) continue;
        fmi2_layer_log(&s->fmi, fmi2Error, "simulation stopped: output with valueReference %u is %g (not finite) "
                       "after the step from tau = %.17g; the parameters are beyond the model's numerical range",
                       (unsigned)s->fast.real_vr[i], *s->fast.real[i], t);
        s->fmi.mode = FMI2_MODE_ERROR;
        return fmi2Error;
    }
    return fmi2OK;
}

/* The fast path steps only up to the declared stop time (with slave_support.STOP_TIME_TOLERANCE, relative:
   hosts compute the last point as start + n h); a step beyond goes to the slave, which refuses it. */
static int before_stop(const Shim *s, fmi2Real t, fmi2Real h)
{
    double scale = s->stop_time < 0 ? -s->stop_time : s->stop_time;
    return !s->stop_defined || t + h <= s->stop_time + 1e-9 * (scale > 1.0 ? scale : 1.0);
}

/* Guards.  S: the shim pointer; a pointer that is not a live instance of this binary (NULL, freed, another FMU's)
   gives fmi2Error and is never dereferenced (fmi2_live). */
#define SHIM(c) Shim *S = (Shim *)(c); if (!fmi2_live(S, FMI2_LIVE_INSTANCE)) return fmi2Error
/* The pointer arguments of call F: an array of n values (or a result pointer) that is NULL is refused (logged),
   before pythonfmu would dereference it. */
#define ARRAYS(F, n, a, b) FMI2_ARRAYS(&S->fmi, #F, n, a, b)
#define POINTER(F, p) do { if (FMI2_NULL_POINTER(&S->fmi, #F, p) != fmi2OK) return fmi2Error; } while (0)
/* The error mode's guard of call F (the state table, fmi2_calls.h): after a fatal fmi2Fatal; in the error state
   fmi2Error and "call F not allowed after an error" unless the table allows F there. */
#define ALLOWED(F)                                                                           \
    do {                                                                                     \
        fmi2Status guard_ = fmi2_layer_mode_check(&S->fmi, #F, FMI2_MASK_##F);               \
        if (guard_ != fmi2OK) return guard_;                                                 \
    } while (0)

/* ---- fmi2Instantiate's arguments (issue 25) ----
   pythonfmu 0.7.0 (CppfmuInstantiateSlave) turns fmuResourceLocation into a path by replacing "%20" with a space
   and deleting the first "file://"; any other form FMI 2.0 allows (file:/path, file://localhost/path, other
   escapes) left a path that is no folder, and the slave's import then failed inside its constructor: the host
   died (SIGSEGV), and NULL threw a C++ exception (std::string(NULL)) that aborted it (so did a NULL instanceName).
   The shim checks the arguments (fmi2_instantiate_check: the name, the type, the GUID, the location as a folder),
   then hands pythonfmu the one form it reads, "file://" + the decoded path, after checking that the folder holds
   the slave (slavemodule.txt, pythonfmu's pointer to the slave's module) and that the path has no "%20" pythonfmu
   would turn into a space. */
#ifndef FMU_GUID
#error "compile with -DFMU_GUID=<the guid of modelDescription.xml, as a C string>"
#endif

/* 1 when text is valid UTF-8 (pythonfmu makes a Python str of the path: invalid bytes crashed the host). */
static int valid_utf8(const unsigned char *p)
{
    while (*p) {
        int n = *p < 0x80 ? 0 : (*p & 0xE0) == 0xC0 ? 1 : (*p & 0xF0) == 0xE0 ? 2 : (*p & 0xF8) == 0xF0 ? 3 : -1;
        if (n < 0 || (n == 1 && *p < 0xC2) || (n == 3 && *p > 0xF4)) return 0;
        p++;
        for (int k = 0; k < n; k++, p++)
            if ((*p & 0xC0) != 0x80) return 0;
    }
    return 1;
}

static int is_file(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (f == NULL) return 0;
    fclose(f);
    return 1;
}

/* The slave pythonfmu will import, checked before it does (a failure inside its import crashed the host): the folder
   named in valid UTF-8, slavemodule.txt (open: f) naming a module (a Python name, alone on its line) whose file is
   there, and resources/vibrofmu_identity.txt (harness/vibrofmu/fmus/shim.py) giving this binary's GUID (resources of
   another FMU are refused) and the Python files that must be there (a partial extraction is refused).  1 when all
   hold, else 0 and why. */
static int slave_files(const char *path, FILE *f, char *why, size_t size)
{
    if (!valid_utf8((const unsigned char *)path)) {
        snprintf(why, size, "its path is not valid UTF-8 (the Python slave cannot be imported from it)");
        return 0;
    }
    char module[256] = "", line[4096 + 64], file[4096 + 320];
    if (fgets(module, sizeof module, f) != NULL) module[strcspn(module, "\r\n")] = '\0';
    int name = module[0] != '\0' && !(module[0] >= '0' && module[0] <= '9');
    for (const char *p = module; *p && name; p++)
        name = (*p >= 'a' && *p <= 'z') || (*p >= 'A' && *p <= 'Z') || (*p >= '0' && *p <= '9') || *p == '_';
    if (!name) {
        snprintf(why, size, "slavemodule.txt names no module ('%.100s'): the FMU's resources are damaged", module);
        return 0;
    }
    snprintf(file, sizeof file, "%s/%s.py", path, module);
    if (!is_file(file)) {
        snprintf(why, size, "slavemodule.txt names the module %s, whose file %s.py is missing (a partial "
                 "extraction?)", module, module);
        return 0;
    }
    snprintf(file, sizeof file, "%s/vibrofmu_identity.txt", path);
    FILE *id = fopen(file, "r");
    if (id == NULL) {
        snprintf(why, size, "vibrofmu_identity.txt is missing: these are not the resources of this FMU (GUID %s)",
                 FMU_GUID);
        return 0;
    }
    int ok = 1;
    line[0] = '\0';
    if (fgets(line, sizeof line, id) == NULL || (line[strcspn(line, "\r\n")] = '\0', strcmp(line, FMU_GUID) != 0)) {
        snprintf(why, size, "these resources are another model's (GUID %.100s, this FMU's is %s): the binary runs "
                 "only its own model", line, FMU_GUID);
        ok = 0;
    }
    line[0] = '\0';
    if (ok && fgets(line, sizeof line, id) != NULL) line[strcspn(line, "\r\n")] = '\0';
    if (ok && strcmp(line, module) != 0) {
        snprintf(why, size, "slavemodule.txt names the module %s, but this FMU's slave is %.100s", module, line);
        ok = 0;
    }
    while (ok && fgets(line, sizeof line, id) != NULL) {
        line[strcspn(line, "\r\n")] = '\0';
        if (line[0] == '\0') continue;
        snprintf(file, sizeof file, "%s/%s", path, line);
        if (!is_file(file)) {
            snprintf(why, size, "the slave's file %.300s is missing (a partial extraction?)", line);
            ok = 0;
        }
    }
    fclose(id);
    return ok;
}

static int resource_location(Shim *s, fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                             fmi2String fmuResourceLocation, char *location, size_t size)
{
    static const char scheme[] = "file://";
    char path[4096];
    if (!fmi2_instantiate_check(&s->fmi, instanceName, "this FMU", fmuType, FMI2_TYPE_BIT(fmi2CoSimulation), fmuGUID,
                                FMU_GUID, fmuResourceLocation, path, sizeof path))
        return 0;
    if (strstr(path, "%20") != NULL) {
        fmi2_layer_log(&s->fmi, fmi2Error, "fmi2Instantiate refused: fmuResourceLocation = '%.900s': its path %.900s "
                       "holds '%%20', which pythonfmu would read as a space", fmuResourceLocation, path);
        return 0;
    }
    char slave[4096 + 32];
    snprintf(slave, sizeof slave, "%s/slavemodule.txt", path);
    FILE *f = fopen(slave, "r");
    if (f == NULL) {
        fmi2_layer_log(&s->fmi, fmi2Error, "fmi2Instantiate refused: fmuResourceLocation = '%.900s': %.900s has no "
                       "slavemodule.txt (it is not this FMU's resources folder, which holds the Python slave)",
                       fmuResourceLocation, path);
        return 0;
    }
    char why[1200];
    int ok = slave_files(path, f, why, sizeof why);
    fclose(f);
    if (!ok) {
        fmi2_layer_log(&s->fmi, fmi2Error, "fmi2Instantiate refused: fmuResourceLocation = '%.900s': %s",
                       fmuResourceLocation, why);
        return 0;
    }
    snprintf(location, size, "%s%s", scheme, path);
    return 1;
}

/* ---- exported FMI 2.0 API ---- */

EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char *fmi2GetVersion(void) { return "2.0"; }

EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                     fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                                     fmi2Boolean visible, fmi2Boolean loggingOn)
{
    pthread_once(&load_once, load_inner);
    if (inner_handle == NULL) {
        if (functions != NULL && functions->logger != NULL)
            fmi2_log_to(functions, instanceName, fmi2Error, "logStatusError", load_error); /* shown by default */
        return NULL;
    }
    Shim *s = calloc(1, sizeof *s);
    if (s == NULL) return NULL;
    if (!fmi2_layer_init(&s->fmi, instanceName, functions, loggingOn)) {
        free(s);
        return NULL;
    }
    char location[4096 + 8];
    if (!resource_location(s, instanceName, fmuType, fmuGUID, fmuResourceLocation, location, sizeof location)) {
        fmi2_layer_free(&s->fmi);
        free(s);
        return NULL;
    }
    s->inner_cb = s->fmi.cb;
    s->inner_cb.logger = forward_log;
    s->inner_cb.stepFinished = NULL;
    s->inner_cb.componentEnvironment = s;
    s->inner = inner.Instantiate(instanceName, fmuType, fmuGUID, location, &s->inner_cb,
                                 visible, 1 /* filtering is done by forward_log */);
    if (s->inner == NULL) {
        fmi2_layer_free(&s->fmi);
        free(s);
        return NULL;
    }
    if (!fmi2_live_add(s, FMI2_LIVE_INSTANCE)) {
        fmi2_layer_log(&s->fmi, fmi2Error, "fmi2Instantiate: out of memory");
        inner.FreeInstance(s->inner);
        fmi2_layer_free(&s->fmi);
        free(s);
        return NULL;
    }
    return s;
}

EXPORT void fmi2FreeInstance(fmi2Component c)
{
    Shim *S = (Shim *)c;
    if (!fmi2_live_remove(S, FMI2_LIVE_INSTANCE)) return; /* NULL, freed already, or not this binary's */
    if (S->fmi.mode == FMI2_MODE_FATAL) {
        /* pythonfmu's destructor would DECREF already-released Python objects
           again (use-after-free): leak the inner instance, and keep this
           struct too since the leaked instance still points at inner_cb. */
        fmi2_layer_free_categories(&S->fmi);
        return;
    }
    detach(S);
    inner.FreeInstance(S->inner);
    fmi2_layer_free(&S->fmi);
    free(S);
}

/* Not forwarded: the inner instance always logs, forward_log filters. */
EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n, const fmi2String cats[])
{
    SHIM(c); ALLOWED(fmi2SetDebugLogging);
    return fmi2_layer_debug_logging(&S->fmi, loggingOn, n, cats);
}

EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real tStart,
                                      fmi2Boolean stopDef, fmi2Real tStop)
{
    SHIM(c); ALLOWED(fmi2SetupExperiment);
    fmi2Status st = settle(S, inner.SetupExperiment(S->inner, tolDef, tol, tStart, stopDef, tStop), 0);
    if (st <= fmi2Warning) {
        S->stop_defined = stopDef != 0;
        S->stop_time = tStop;
    }
    return st;
}

EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    SHIM(c); ALLOWED(fmi2EnterInitializationMode);
    return settle(S, inner.EnterInitializationMode(S->inner), 0);
}

EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    SHIM(c); ALLOWED(fmi2ExitInitializationMode);
    return settle(S, forward_from(S, inner.ExitInitializationMode, S->inner), 0);
}

EXPORT fmi2Status fmi2Terminate(fmi2Component c)
{
    SHIM(c); ALLOWED(fmi2Terminate);
    return settle(S, inner.Terminate(S->inner), 0);
}

EXPORT fmi2Status fmi2Reset(fmi2Component c)
{
    SHIM(c); ALLOWED(fmi2Reset);
    detach(S);
    S->stop_defined = 0;
    return settle(S, forward_from(S, inner.Reset, S->inner), 1);
}

/* getters: allowed after an error; after a fatal the outputs are not touched */
#define GETTER(Name, T)                                                                         \
    EXPORT fmi2Status fmi2Get##Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, T value[]) \
    {                                                                                           \
        SHIM(c); ALLOWED(fmi2Get##Name); ARRAYS(fmi2Get##Name, nvr, vr, value);                       \
        FAST;                                                                                   \
        S->error_logged = 0;                                                                    \
        return CHECK(checked_getter(S, note(S, inner.Get##Name(S->inner, vr, nvr, value))));    \
    }
#define CHECK(st) (st)
#define FAST
GETTER(Integer, fmi2Integer)
GETTER(String, fmi2String)
#undef FAST
#undef CHECK
#define CHECK(st) fmi2_layer_finite_reals(&S->fmi, (st), vr, nvr, value)
#define FAST if (fast_get_real(S, vr, nvr, value)) return fmi2_layer_finite_reals(&S->fmi, fmi2OK, vr, nvr, value)
GETTER(Real, fmi2Real)
#undef FAST
#undef CHECK
#define CHECK(st) (st)
#define FAST if (fast_get_boolean(S, vr, nvr, value)) return fmi2OK
GETTER(Boolean, fmi2Boolean)
#undef FAST
#undef CHECK

#define SETTER(Name, T)                                                                         \
    EXPORT fmi2Status fmi2Set##Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const T value[]) \
    {                                                                                           \
        SHIM(c); ALLOWED(fmi2Set##Name); ARRAYS(fmi2Set##Name, nvr, vr, value);                 \
        FAST;                                                                                   \
        return settle(S, inner.Set##Name(S->inner, vr, nvr, value), 0);                         \
    }
#define FAST if (fast_set_real(S, vr, nvr, value)) return fmi2OK
SETTER(Real, fmi2Real)
#undef FAST
#define FAST
SETTER(Integer, fmi2Integer)
SETTER(Boolean, fmi2Boolean)
#undef FAST
/* pythonfmu makes a std::string of each value: a NULL one threw a C++ exception that aborted the host */
#define FAST                                                                                    \
    for (size_t i = 0; i < nvr; i++)                                                            \
        if (value[i] == NULL) {                                                                 \
            fmi2_layer_log(&S->fmi, fmi2Error, "fmi2SetString refused: value[%zu] = NULL", i);   \
            return fmi2Error;                                                                   \
        }
SETTER(String, fmi2String)
#undef FAST

/* FMU states (issue 25).  pythonfmu dereferences what it is given: a NULL state (a Python exception: fmi2Fatal,
   the instance lost) or a NULL pointer argument (a crash).  The shim refuses those with fmi2Error and a log line,
   before forwarding, and leaves the instance as it was (not in the error state: nothing was changed).
   fmi2FreeFMUstate sets the caller's pointer to NULL, as FMI 2.0 asks (pythonfmu leaves it). */
#define refuse_null(s, call, argument) fmi2_layer_null_refusal(&(s)->fmi, (call), (argument), NULL, 0)
/* A state pointer that is not a live state of this binary (freed, another FMU's, made up): pythonfmu would use it
   as its own; refused instead (fmi2_layer_foreign_state).  The states pythonfmu hands out are recorded (fmi2_live,
   kind FMI2_LIVE_STATE). */
#define foreign_state(s, call, state) fmi2_layer_foreign_state(&(s)->fmi, (call), (state))

/* After pythonfmu stored a state in *state (old: what was there before): the new one recorded as live. */
static fmi2Status record_state(Shim *s, fmi2Status st, fmi2FMUstate old, fmi2FMUstate *state)
{
    if (st > fmi2Warning || *state == NULL || *state == old) return st;
    if (old != NULL) fmi2_live_remove(old, FMI2_LIVE_STATE); /* replaced: no longer a handle of the host's */
    if (!fmi2_live_add(*state, FMI2_LIVE_STATE)) {
        inner.FreeFMUstate(s->inner, state);
        *state = NULL;
        fmi2_layer_log(&s->fmi, fmi2Error, "out of memory while recording an FMU state");
        return fmi2Error;
    }
    return st;
}

EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    SHIM(c); ALLOWED(fmi2GetFMUstate);
    if (state == NULL) return refuse_null(S, "fmi2GetFMUstate", "FMUstate (the pointer to store it in)");
    if (*state != NULL && foreign_state(S, "fmi2GetFMUstate", *state)) return fmi2Error;
    fmi2FMUstate old = *state;
    return record_state(S, note(S, inner.GetFMUstate(S->inner, state)), old, state);
}

EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    SHIM(c); ALLOWED(fmi2SetFMUstate);
    if (state == NULL) return refuse_null(S, "fmi2SetFMUstate", "FMUstate (no state given)");
    if (foreign_state(S, "fmi2SetFMUstate", state)) return fmi2Error;
    detach(S);
    calling_shim = S;
    fmi2Status st = inner.SetFMUstate(S->inner, state);
    calling_shim = NULL;
    return settle(S, st, 1);
}

EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    SHIM(c); ALLOWED(fmi2FreeFMUstate);
    if (state == NULL || *state == NULL) return fmi2OK; /* nothing to free (FMI 2.0: a no-op) */
    if (foreign_state(S, "fmi2FreeFMUstate", *state)) return fmi2Error;
    fmi2_live_remove(*state, FMI2_LIVE_STATE);
    fmi2Status st = note(S, inner.FreeFMUstate(S->inner, state));
    if (st <= fmi2Warning) *state = NULL;
    return st;
}

EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    SHIM(c); ALLOWED(fmi2SerializedFMUstateSize);
    if (state == NULL) return refuse_null(S, "fmi2SerializedFMUstateSize", "FMUstate");
    if (size == NULL) return refuse_null(S, "fmi2SerializedFMUstateSize", "size (the pointer to store it in)");
    if (foreign_state(S, "fmi2SerializedFMUstateSize", state)) return fmi2Error;
    return note(S, inner.SerializedFMUstateSize(S->inner, state, size));
}

EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    SHIM(c); ALLOWED(fmi2SerializeFMUstate);
    if (state == NULL) return refuse_null(S, "fmi2SerializeFMUstate", "FMUstate");
    if (bytes == NULL) return refuse_null(S, "fmi2SerializeFMUstate", "serializedState (the buffer)");
    if (foreign_state(S, "fmi2SerializeFMUstate", state)) return fmi2Error;
    size_t needed = 0;
    fmi2Status st = note(S, inner.SerializedFMUstateSize(S->inner, state, &needed));
    if (st > fmi2Warning) return st;
    if (size < needed) { /* pythonfmu copies `size` bytes from a buffer of `needed` */
        fmi2_layer_log(&S->fmi, fmi2Error, "fmi2SerializeFMUstate refused: size = %zu, the state needs %zu bytes "
                       "(fmi2SerializedFMUstateSize)", size, needed);
        return fmi2Error;
    }
    return note(S, inner.SerializeFMUstate(S->inner, state, bytes, needed));
}

/* Allowed after an error.  It only builds a state object (pythonfmu calls a
   static method, the slave instance is not involved), so the status flag is
   not consulted: in the error state it would still hold 3 and turn every
   successful deserialization into an fmi2Error. */
EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state)
{
    SHIM(c); ALLOWED(fmi2DeSerializeFMUstate);
    if (bytes == NULL) return refuse_null(S, "fmi2DeSerializeFMUstate", "serializedState (the bytes)");
    if (state == NULL) return refuse_null(S, "fmi2DeSerializeFMUstate", "FMUstate (the pointer to store it in)");
    if (*state != NULL && foreign_state(S, "fmi2DeSerializeFMUstate", *state)) return fmi2Error;
    fmi2FMUstate old = *state;
    return record_state(S, note(S, inner.DeSerializeFMUstate(S->inner, bytes, size, state)), old, state);
}

EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vU[], size_t nU,
                                               const fmi2ValueReference vK[], size_t nK,
                                               const fmi2Real dvK[], fmi2Real dvU[])
{
    SHIM(c); ALLOWED(fmi2GetDirectionalDerivative);
    ARRAYS(fmi2GetDirectionalDerivative, nU, vU, dvU);
    ARRAYS(fmi2GetDirectionalDerivative, nK, vK, dvK);
    return note(S, inner.GetDirectionalDerivative(S->inner, vU, nU, vK, nK, dvK, dvU));
}

EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                              const fmi2Integer order[], const fmi2Real value[])
{
    SHIM(c); ALLOWED(fmi2SetRealInputDerivatives);
    ARRAYS(fmi2SetRealInputDerivatives, nvr, vr, value);
    ARRAYS(fmi2SetRealInputDerivatives, nvr, order, value);
    return note(S, inner.SetRealInputDerivatives(S->inner, vr, nvr, order, value));
}

EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                               const fmi2Integer order[], fmi2Real value[])
{
    SHIM(c); ALLOWED(fmi2GetRealOutputDerivatives);
    ARRAYS(fmi2GetRealOutputDerivatives, nvr, vr, value);
    ARRAYS(fmi2GetRealOutputDerivatives, nvr, order, value);
    return note(S, inner.GetRealOutputDerivatives(S->inner, vr, nvr, order, value));
}

EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior)
{
    SHIM(c); ALLOWED(fmi2DoStep);
    if (fast_enabled(S) && before_stop(S, t, h) && S->fast.step(S->fast.model, t, h) == 0) {
        S->fast_steps++;
        return fast_outputs_checked(S, t);
    }
    return settle(S, inner.DoStep(S->inner, t, h, noSetPrior), 0);
}

EXPORT fmi2Status fmi2CancelStep(fmi2Component c)
{
    SHIM(c); ALLOWED(fmi2CancelStep);
    return note(S, inner.CancelStep(S->inner));
}

#define STATUS_GETTER(Name, T)                                                                  \
    EXPORT fmi2Status fmi2Get##Name(fmi2Component c, const fmi2StatusKind k, T *value)          \
    {                                                                                           \
        SHIM(c); ALLOWED(fmi2Get##Name); POINTER(fmi2Get##Name, value);                               \
        return note(S, inner.Get##Name(S->inner, k, value));                                    \
    }
STATUS_GETTER(Status, fmi2Status)
STATUS_GETTER(RealStatus, fmi2Real)
STATUS_GETTER(IntegerStatus, fmi2Integer)
STATUS_GETTER(BooleanStatus, fmi2Boolean)
STATUS_GETTER(StringStatus, fmi2String)
