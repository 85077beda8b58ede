/*
 * pyloader.c -- a pythonfmu FMU finds the Python it was built with, in any host.
 *
 * pythonfmu's library does not link libpython: it needs the host to have loaded libpython globally and
 * Python to find its installation and the site-packages with pythonfmu, numpy and scipy.  A Python host
 * (FMPy) has all that; a C host (fmusim, Dymola, a plain C program started with an empty environment) has
 * none of it.  The status shim calls vibro_python_prepare() before it loads pythonfmu's library:
 *
 *   1. Python already in the process (a Python host, or another FMU loaded it): it is used, if its version
 *      (major.minor) is the recorded python_version; when a recorded module does not import there (a host
 *      in a venv without numpy, scipy or pythonfmu), the recorded folders (`path`) missing from sys.path are
 *      appended to it, under the GIL, and the import is tried again.  Another version cannot run pythonfmu's
 *      library (built for one Python): one line says both versions and names the native FMU
 *      (native/<id>.fmu beside it, no Python) as the working alternative.
 *   2. Otherwise the environment recorded at build time is read: the FMU's resources/python_env.txt
 *      (written by harness/vibrofmu/fmus/pythonenv.py), or the file $VIBROFMU_PYTHON_ENV names instead (for
 *      another machine; `vibrofmu doctor --env-file` writes one).  Lines "key=value":
 *        python_version  major.minor of the Python the FMU was built with (e.g. 3.11)
 *        libpython       the shared library to load
 *        home            PYTHONHOME (sys.base_prefix)
 *        stdlib          the standard library's folder (checked before Python starts: a Python that cannot
 *                        find it aborts the process instead of reporting an error)
 *        path            the folders holding the modules below, ':'-separated, in sys.path order
 *        modules         "name==version" of every module the FMU imports from outside its resources,
 *                        ' '-separated
 *      libpython is loaded with RTLD_GLOBAL (pythonfmu's library then finds its symbols); the interpreter
 *      is started with PYTHONHOME = home and PYTHONPATH = path, set for the start only (the host's
 *      environment is restored afterwards), without the site module, so that sys.path is exactly the
 *      standard library and the recorded folders (no user or system site-packages that the build did not
 *      use).  It is started like the shim did before (Py_InitializeEx(0): the host's signal handlers are
 *      left alone) and the GIL is released.
 *   3. Each recorded module is imported (under the GIL) and, in the Python the FMU started, its version
 *      compared with the recorded one (major.minor); Python's own version in either case (pythonfmu's
 *      library is built for one).
 * Anything missing gives one line naming it and `vibrofmu doctor` (the shim logs it with status fmi2Error and
 * fmi2Instantiate returns NULL), never a Python traceback.  In a Python host (step 1) the line names the native
 * FMU instead, and is also written to stderr: some hosts log an FMU's messages at their debug level only.
 *
 * All Python functions are looked up with dlsym: this file needs no Python headers and no Python at build
 * time beyond what wrote the environment file.
 */

#define _GNU_SOURCE
#include "pyloader.h"

#include <dlfcn.h>
#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include <wchar.h>

#define HINT "; run `vibrofmu doctor FMU` for the set-up this FMU needs (or set " VIBRO_PYTHON_ENV_VARIABLE \
             " to an environment file written by `vibrofmu doctor --env-file`)"
#define LINE 4096

typedef struct {
    char python_version[32];
    char libpython[LINE];
    char home[LINE];
    char stdlib[LINE];
    char path[4 * LINE];
    char modules[LINE];
    char source[LINE]; /* the file these came from */
} PyEnv;

typedef void PyObject;

static void say(char *message, size_t size, const char *format, ...)
{
    va_list args;
    va_start(args, format);
    vsnprintf(message, size, format, args);
    va_end(args);
    for (char *p = message; *p; p++) /* one line */
        if (*p == '\n' || *p == '\r') *p = ' ';
}

/* dirname applied `levels` times, in place */
static void strip_components(char *path, int levels)
{
    for (int i = 0; i < levels; i++) {
        char *slash = strrchr(path, '/');
        if (slash == NULL) { strcpy(path, "."); return; }
        *slash = '\0';
    }
}

static int read_env(const char *binary_path, PyEnv *env, char *message, size_t size)
{
    const char *override = getenv(VIBRO_PYTHON_ENV_VARIABLE);
    memset(env, 0, sizeof *env);
    if (override != NULL && *override != '\0') {
        snprintf(env->source, sizeof env->source, "%s", override);
    } else {
        char dir[LINE];
        snprintf(dir, sizeof dir, "%s", binary_path);
        strip_components(dir, 3); /* <fmu>/binaries/linux64/<id>.so -> <fmu> */
        snprintf(env->source, sizeof env->source, "%s/resources/" VIBRO_PYTHON_ENV_FILE, dir);
    }
    FILE *f = fopen(env->source, "r");
    if (f == NULL) {
        say(message, size, "vibrofmu: cannot read the FMU's Python environment file %s (%s)" HINT, env->source,
            strerror(errno));
        return 1;
    }
    static char line[4 * LINE + 64];
    while (fgets(line, sizeof line, f) != NULL) {
        line[strcspn(line, "\r\n")] = '\0';
        char *eq = strchr(line, '=');
        if (line[0] == '#' || eq == NULL) continue;
        *eq = '\0';
        const char *key = line, *value = eq + 1;
#define FIELD(name) if (strcmp(key, #name) == 0) snprintf(env->name, sizeof env->name, "%s", value)
        FIELD(python_version); FIELD(libpython); FIELD(home); FIELD(stdlib); FIELD(path); FIELD(modules);
#undef FIELD
    }
    fclose(f);
    if (!env->python_version[0] || !env->libpython[0] || !env->home[0] || !env->stdlib[0]) {
        say(message, size, "vibrofmu: the Python environment file %s lacks python_version, libpython, home or "
            "stdlib" HINT, env->source);
        return 1;
    }
    return 0;
}

/* ---- the Python C API, looked up at run time ---- */

typedef struct {
    int (*IsInitialized)(void);
    void (*InitializeEx)(int);
    void *(*SaveThread)(void);
    int (*GILState_Ensure)(void);
    void (*GILState_Release)(int);
    void (*SetProgramName)(const wchar_t *);
    const char *(*GetVersion)(void);
    PyObject *(*ImportModule)(const char *);
    void (*ErrFetch)(PyObject **, PyObject **, PyObject **);
    void (*ErrNormalize)(PyObject **, PyObject **, PyObject **);
    void (*ErrClear)(void);
    PyObject *(*Str)(PyObject *);
    PyObject *(*GetAttrString)(PyObject *, const char *);
    const char *(*AsUTF8)(PyObject *);
    void (*DecRef)(PyObject *);
    PyObject *(*SysGetObject)(const char *);
    PyObject *(*UnicodeFromString)(const char *);
    int (*ListAppend)(PyObject *, PyObject *);
    int (*SequenceContains)(PyObject *, PyObject *);
    int *NoSiteFlag, *NoUserSiteDirectory;
} PyApi;

static int python_api(void *scope, PyApi *api)
{
#define GET(field, symbol) *(void **)(&api->field) = dlsym(scope, symbol)
    GET(IsInitialized, "Py_IsInitialized"); GET(InitializeEx, "Py_InitializeEx");
    GET(SaveThread, "PyEval_SaveThread"); GET(GILState_Ensure, "PyGILState_Ensure");
    GET(GILState_Release, "PyGILState_Release"); GET(SetProgramName, "Py_SetProgramName");
    GET(GetVersion, "Py_GetVersion"); GET(ImportModule, "PyImport_ImportModule");
    GET(ErrFetch, "PyErr_Fetch"); GET(ErrNormalize, "PyErr_NormalizeException"); GET(ErrClear, "PyErr_Clear");
    GET(Str, "PyObject_Str"); GET(GetAttrString, "PyObject_GetAttrString"); GET(AsUTF8, "PyUnicode_AsUTF8");
    GET(DecRef, "Py_DecRef"); GET(SysGetObject, "PySys_GetObject"); GET(UnicodeFromString, "PyUnicode_FromString");
    GET(ListAppend, "PyList_Append"); GET(SequenceContains, "PySequence_Contains");
    api->NoSiteFlag = dlsym(scope, "Py_NoSiteFlag");
    api->NoUserSiteDirectory = dlsym(scope, "Py_NoUserSiteDirectory");
#undef GET
    return api->IsInitialized && api->InitializeEx && api->SaveThread && api->GILState_Ensure
           && api->GILState_Release && api->GetVersion && api->ImportModule && api->ErrFetch && api->ErrNormalize
           && api->ErrClear && api->Str && api->GetAttrString && api->AsUTF8 && api->DecRef && api->SysGetObject
           && api->UnicodeFromString && api->ListAppend && api->SequenceContains;
}

/* str(obj), first line, into out; "" when it cannot be had.  Needs the GIL. */
static void text_of(const PyApi *api, PyObject *obj, char *out, size_t size)
{
    out[0] = '\0';
    if (obj == NULL) return;
    PyObject *s = api->Str(obj);
    const char *u = s ? api->AsUTF8(s) : NULL;
    if (u != NULL) snprintf(out, size, "%.*s", (int)strcspn(u, "\r\n"), u);
    if (s) api->DecRef(s);
    api->ErrClear();
}

/* "1.26.4" vs "1.26.0": same major.minor */
static int same_minor(const char *a, const char *b)
{
    const char *da = strchr(a, '.'), *db = strchr(b, '.');
    if (da == NULL || db == NULL) return strcmp(a, b) == 0;
    size_t na = strcspn(da + 1, ".+-abrc"), nb = strcspn(db + 1, ".+-abrc");
    return (da - a) == (db - b) && strncmp(a, b, (size_t)(da - a)) == 0 && na == nb
           && strncmp(da + 1, db + 1, na) == 0;
}

/* Length of "3.12" in "3.12.1 (main, ...)" */
static int minor_length(const char *version)
{
    const char *dot = strchr(version, '.');
    if (dot == NULL) return (int)strcspn(version, " ");
    return (int)(dot + 1 - version) + (int)strcspn(dot + 1, ". +abrc");
}

/* The FMU's model identifier, from its binary's file name (binaries/<platform>/<id>.so). */
static void model_identifier(const char *binary_path, char *out, size_t size)
{
    const char *base = strrchr(binary_path, '/');
    base = base ? base + 1 : binary_path;
    size_t n = strcspn(base, ".");
    snprintf(out, size, "%.*s", (int)n, base);
}

/* Append each folder of the ':'-separated list to sys.path that is not in it; the number appended.  Needs the
   GIL. */
static int append_to_sys_path(const PyApi *api, const char *folders)
{
    PyObject *sys_path = api->SysGetObject("path"); /* borrowed */
    if (sys_path == NULL) return 0;
    char list[4 * LINE];
    snprintf(list, sizeof list, "%s", folders);
    int added = 0;
    char *save = NULL;
    for (char *dir = strtok_r(list, ":", &save); dir != NULL; dir = strtok_r(NULL, ":", &save)) {
        PyObject *item = api->UnicodeFromString(dir);
        if (item == NULL) { api->ErrClear(); continue; }
        if (api->SequenceContains(sys_path, item) == 0 && api->ListAppend(sys_path, item) == 0) added++;
        api->DecRef(item);
        api->ErrClear();
    }
    return added;
}

/* Import module `name`: NULL with the reason in why (one line) when it fails.  Needs the GIL. */
static PyObject *import_module(const PyApi *api, const char *name, char *why, size_t size)
{
    PyObject *module = api->ImportModule(name);
    if (module != NULL) return module;
    PyObject *type = NULL, *value = NULL, *tb = NULL;
    api->ErrFetch(&type, &value, &tb);
    api->ErrNormalize(&type, &value, &tb);
    text_of(api, value, why, size);
    if (!why[0]) snprintf(why, size, "no reason given");
    if (type) api->DecRef(type);
    if (value) api->DecRef(value);
    if (tb) api->DecRef(tb);
    api->ErrClear();
    return NULL;
}

/* Import every recorded module and compare its version.  host: the host's own Python (step 1).  Needs the GIL. */
static int check_modules(const PyApi *api, const PyEnv *env, const char *binary_path, int host, char *message,
                         size_t size)
{
    const char *version = api->GetVersion();
    int vlen = (int)strcspn(version, " ");
    char where[2 * LINE], id[256];
    model_identifier(binary_path, id, sizeof id);
    if (host)
        snprintf(where, sizeof where, "the host's Python %.*s", vlen, version);
    else
        snprintf(where, sizeof where, "the Python %.*s of this FMU (environment %s)", vlen, version, env->source);
    if (!same_minor(version, env->python_version)) {
        if (host) /* pythonfmu's library runs in the Python it was built for only: no file or variable helps */
            say(message, size, "vibrofmu: this FMU (%s, pythonfmu) needs Python %s but the host runs Python %.*s, "
                "and a pythonfmu FMU runs only in a Python host of the version it was built with: use the native "
                "FMU %s.fmu from the native/ folder `vibrofmu build` wrote beside this FMU (no Python at run time), "
                "or rebuild this one with Python %.*s "
                "(`vibrofmu build`)", id, env->python_version, vlen, version, id, minor_length(version), version);
        else
            say(message, size, "vibrofmu: version mismatch: %s is loaded but this FMU needs Python %s" HINT, where,
                env->python_version);
        return 1;
    }
    int path_added = 0;
    char list[LINE];
    snprintf(list, sizeof list, "%s", env->modules);
    char *save = NULL;
    for (char *item = strtok_r(list, " ", &save); item != NULL; item = strtok_r(NULL, " ", &save)) {
        char *wanted = strstr(item, "==");
        if (wanted != NULL) { *wanted = '\0'; wanted += 2; }
        char why[512];
        PyObject *module = import_module(api, item, why, sizeof why);
        if (module == NULL && host && !path_added && env->path[0]) {
            /* the host's Python is the FMU's version but lacks the module: the site-packages the FMU was built
               with are added (once) */
            path_added = 1;
            if (append_to_sys_path(api, env->path) > 0) module = import_module(api, item, why, sizeof why);
        }
        if (module == NULL) {
            if (host)
                say(message, size, "vibrofmu: %s is missing, or broken: %s cannot import %s (%s), not even from "
                    "the folders this FMU was built with (%s); install it into the Python that runs the host (pip "
                    "install %s), or use the native FMU %s.fmu from the native/ folder `vibrofmu build` wrote beside "
                    "this FMU (no Python at run time)", item, where,
                    item, why, env->path[0] ? env->path : "none recorded", item, id);
            else
                say(message, size, "vibrofmu: %s is missing, or broken: %s cannot import %s (%s)" HINT, item, where,
                    item, why);
            return 1;
        }
        PyObject *v = api->GetAttrString(module, "__version__");
        char found[128];
        text_of(api, v, found, sizeof found);
        if (v) api->DecRef(v);
        api->DecRef(module);
        /* a Python host brings its own modules: their versions are the host's business */
        if (!host && wanted != NULL && found[0] && !same_minor(found, wanted)) {
            say(message, size, "vibrofmu: version mismatch: %s has %s %s, this FMU was built with %s %s" HINT,
                where, item, found, item, wanted);
            return 1;
        }
    }
    return 0;
}

/* setenv for the interpreter's start; *saved receives the old value (NULL: unset) */
static void push_env(const char *name, const char *value, char **saved)
{
    const char *old = getenv(name);
    *saved = old ? strdup(old) : NULL;
    setenv(name, value, 1);
}

static void pop_env(const char *name, char *saved)
{
    if (saved) setenv(name, saved, 1);
    else unsetenv(name);
    free(saved);
}

int vibro_python_prepare(const char *binary_path, char *message, size_t size)
{
    PyApi api;
    PyEnv *env = calloc(1, sizeof *env);
    int failed = 1;
    if (env == NULL) { say(message, size, "vibrofmu: out of memory"); return 1; }
    message[0] = '\0';
    int present = python_api(RTLD_DEFAULT, &api);
    if (present && api.IsInitialized()) { /* 1. a Python host, or loaded before */
        if (read_env(binary_path, env, message, size) != 0) {
            /* no record: nothing to compare with, pythonfmu reports what fails */
            failed = 0;
            goto done;
        }
        int gil = api.GILState_Ensure();
        failed = check_modules(&api, env, binary_path, 1, message, size);
        api.GILState_Release(gil);
        /* A Python host may show the FMU's log at its debug level only (ecospy 0.7.2 logs every FMU message,
           fmi2Fatal included, at debug) and then run on with no instance: the line also goes to stderr, once. */
        if (failed) {
            fprintf(stderr, "%s\n", message);
            fflush(stderr);
        }
        goto done;
    }
    if (read_env(binary_path, env, message, size) != 0) goto done; /* 2. */
    if (!present) {
        void *lib = dlopen(env->libpython, RTLD_NOW | RTLD_GLOBAL);
        if (lib == NULL) {
            say(message, size, "vibrofmu: libpython is missing: cannot load %s (%s); this FMU needs Python %s "
                "(environment %s)" HINT, env->libpython, dlerror(), env->python_version, env->source);
            goto done;
        }
        if (!python_api(lib, &api)) {
            say(message, size, "vibrofmu: %s lacks functions of the Python C API (environment %s)" HINT,
                env->libpython, env->source);
            goto done;
        }
    }
    char probe[LINE + 32];
    snprintf(probe, sizeof probe, "%s/encodings/__init__.py", env->stdlib);
    if (access(probe, R_OK) != 0) {
        say(message, size, "vibrofmu: Python's standard library is missing: no %s (environment %s)" HINT, probe,
            env->source);
        goto done;
    }
    char *old_home, *old_path;
    push_env("PYTHONHOME", env->home, &old_home);
    push_env("PYTHONPATH", env->path, &old_path);
    if (api.NoSiteFlag) *api.NoSiteFlag = 1;
    if (api.NoUserSiteDirectory) *api.NoUserSiteDirectory = 1;
    if (api.SetProgramName) api.SetProgramName(L"./PythonFMU");
    api.InitializeEx(0);
    pop_env("PYTHONHOME", old_home);
    pop_env("PYTHONPATH", old_path);
    failed = check_modules(&api, env, binary_path, 0, message, size); /* 3. (Py_InitializeEx left us holding the GIL) */
    api.SaveThread();
done:
    free(env);
    return failed;
}
