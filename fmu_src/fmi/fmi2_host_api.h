/*
 * fmi2_host_api.h -- the table of FMI 2.0 functions a C host loads from an FMU binary, written once for every C
 * host of the project (tests/c_host/fmi2_host.c, tests/c_host/instance_cycles.c, harness/vibrofmu/speed/
 * timing_host.c) and for the status shim, which loads pythonfmu's library the same way.
 *
 * Fmi2Api has one pointer per FMI 2.0 co-simulation function, typed by the standard's fmi2FunctionTypes.h;
 * fmi2_api_load fills it from a loaded library (NULL where the library lacks a function) and
 * fmi2_api_missing names the first of the functions a host needs that is NULL.  The library is opened with
 * fmi2_host_open (dlopen, or LoadLibrary on Windows: fmi2_host.c is cross-compiled with mingw-w64).
 */
#ifndef FMI2_HOST_API_H
#define FMI2_HOST_API_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "fmi2FunctionTypes.h"

#ifdef _WIN32
#include <windows.h>
static inline void *fmi2_host_open(const char *path) { return (void *)LoadLibraryA(path); }
static inline void *fmi2_host_symbol(void *lib, const char *name)
{
    return (void *)(intptr_t)GetProcAddress((HMODULE)lib, name);
}
static inline int fmi2_host_close(void *lib) { return !FreeLibrary((HMODULE)lib); }
static inline const char *fmi2_host_error(void)
{
    static char text[64];
    snprintf(text, sizeof text, "Windows error %lu", (unsigned long)GetLastError());
    return text;
}
#else
#include <dlfcn.h>
static inline void *fmi2_host_open(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static inline void *fmi2_host_symbol(void *lib, const char *name) { return dlsym(lib, name); }
static inline int fmi2_host_close(void *lib) { return dlclose(lib); }
static inline const char *fmi2_host_error(void) { return dlerror(); }
#endif

/* Every function of the FMI 2.0 co-simulation API (common and co-simulation functions), without "fmi2". */
#define FMI2_API_FUNCTIONS(X)                                                                                   \
    X(GetTypesPlatform) X(GetVersion) X(SetDebugLogging) X(Instantiate) X(FreeInstance) X(SetupExperiment)    \
    X(EnterInitializationMode) X(ExitInitializationMode) X(Terminate) X(Reset)                                 \
    X(GetReal) X(GetInteger) X(GetBoolean) X(GetString) X(SetReal) X(SetInteger) X(SetBoolean) X(SetString)   \
    X(GetFMUstate) X(SetFMUstate) X(FreeFMUstate) X(SerializedFMUstateSize) X(SerializeFMUstate)               \
    X(DeSerializeFMUstate) X(GetDirectionalDerivative) X(SetRealInputDerivatives) X(GetRealOutputDerivatives) \
    X(DoStep) X(CancelStep) X(GetStatus) X(GetRealStatus) X(GetIntegerStatus) X(GetBooleanStatus)             \
    X(GetStringStatus)

typedef struct {
#define FMI2_API_FIELD(name) fmi2##name##TYPE *name;
    FMI2_API_FUNCTIONS(FMI2_API_FIELD)
#undef FMI2_API_FIELD
} Fmi2Api;

/* Fill api from lib: each function "fmi2<name>", NULL where lib lacks it. */
static inline void fmi2_api_load(void *lib, Fmi2Api *api)
{
#define FMI2_API_LOAD(name) *(void **)(&api->name) = fmi2_host_symbol(lib, "fmi2" #name);
    FMI2_API_FUNCTIONS(FMI2_API_LOAD)
#undef FMI2_API_LOAD
}

/* The first of `needed` (names without "fmi2", NULL-terminated) that api lacks, or NULL when it has them all. */
static inline const char *fmi2_api_missing(const Fmi2Api *api, const char *const needed[])
{
    static const struct { const char *name; size_t offset; } FIELDS[] = {
#define FMI2_API_ENTRY(name) {#name, offsetof(Fmi2Api, name)},
        FMI2_API_FUNCTIONS(FMI2_API_ENTRY)
#undef FMI2_API_ENTRY
    };
    for (size_t i = 0; needed[i] != NULL; i++) {
        size_t k = 0;
        while (k < sizeof FIELDS / sizeof *FIELDS && strcmp(FIELDS[k].name, needed[i]) != 0) k++;
        if (k == sizeof FIELDS / sizeof *FIELDS) return needed[i]; /* not an FMI 2.0 function */
        void *const *field = (void *const *)(const void *)((const char *)api + FIELDS[k].offset);
        if (*field == NULL) return needed[i];
    }
    return NULL;
}

#endif
