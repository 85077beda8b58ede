/*
 * fmi2_layer.c -- the FMI 2.0 plumbing shared by the status shim and the native FMUs (see fmi2_layer.h).
 */
#include "fmi2_layer.h"

#include <math.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static void noop_logger(fmi2ComponentEnvironment e, fmi2String i, fmi2Status s, fmi2String c, fmi2String m, ...)
{
    (void)e; (void)i; (void)s; (void)c; (void)m;
}

static char *copy_text(const char *text)
{
    size_t n = strlen(text) + 1;
    char *copy = malloc(n);
    if (copy != NULL) memcpy(copy, text, n);
    return copy;
}

int fmi2_layer_init(Fmi2Layer *L, fmi2String instanceName, const fmi2CallbackFunctions *functions,
                    fmi2Boolean loggingOn)
{
    memset(L, 0, sizeof *L);
    if (functions != NULL) L->cb = *functions;
    if (L->cb.logger == NULL) L->cb.logger = noop_logger;
    L->name = copy_text(instanceName ? instanceName : "");
    if (L->name == NULL) return 0;
    L->mode = FMI2_MODE_OK;
    L->logging_on = loggingOn != 0;
    return 1;
}

void fmi2_layer_free_categories(Fmi2Layer *L)
{
    for (size_t i = 0; i < L->ncat; i++) free(L->cat[i]);
    free(L->cat);
    L->cat = NULL;
    L->ncat = 0;
}

void fmi2_layer_free(Fmi2Layer *L)
{
    fmi2_layer_free_categories(L);
    free(L->name);
    L->name = NULL;
}

void fmi2_layer_set_logging(Fmi2Layer *L, fmi2Boolean loggingOn, size_t n, const fmi2String categories[])
{
    fmi2_layer_free_categories(L);
    L->logging_on = loggingOn != 0;
    if (n == 0 || categories == NULL) return;
    L->cat = calloc(n, sizeof *L->cat);
    if (L->cat == NULL) return; /* out of memory: all categories */
    for (size_t i = 0; i < n; i++)
        if (categories[i] != NULL && (L->cat[L->ncat] = copy_text(categories[i])) != NULL) L->ncat++;
}

static int category_enabled(const Fmi2Layer *L, fmi2String category)
{
    if (!L->logging_on) return 0;
    if (L->ncat == 0) return 1;
    for (size_t i = 0; i < L->ncat; i++)
        if (strcmp(L->cat[i], "logAll") == 0 || (category && strcmp(L->cat[i], category) == 0)) return 1;
    return 0;
}

void fmi2_log_to(const fmi2CallbackFunctions *cb, fmi2String instanceName, fmi2Status status, fmi2String category,
                 fmi2String message)
{
    if (message == NULL) message = "";
    if (instanceName == NULL) instanceName = "";
    if (strchr(message, '%') == NULL) {
        cb->logger(cb->componentEnvironment, instanceName, status, category, message);
        return;
    }
    char *buf = malloc(2 * strlen(message) + 1);
    if (buf == NULL) return;
    char *o = buf;
    for (const char *p = message; *p; p++) {
        if (*p == '%') *o++ = '%';
        *o++ = *p;
    }
    *o = '\0';
    cb->logger(cb->componentEnvironment, instanceName, status, category, buf);
    free(buf);
}

void fmi2_layer_emit(const Fmi2Layer *L, fmi2String instanceName, fmi2Status status, fmi2String category,
                     fmi2String message)
{
    if (status != fmi2OK || category_enabled(L, category)) fmi2_log_to(&L->cb, instanceName, status, category, message);
}

void fmi2_layer_vlog(const Fmi2Layer *L, fmi2Status status, const char *format, va_list args)
{
    const char *category = status >= fmi2Error ? "logStatusError" : status == fmi2Warning ? "logStatusWarning"
                                                                                          : "logAll";
    if (status == fmi2OK && !category_enabled(L, category)) return;
    char message[2048];
    vsnprintf(message, sizeof message, format, args);
    fmi2_log_to(&L->cb, L->name, status, category, message);
}

void fmi2_layer_log(const Fmi2Layer *L, fmi2Status status, const char *format, ...)
{
    va_list args;
    va_start(args, format);
    fmi2_layer_vlog(L, status, format, args);
    va_end(args);
}

fmi2Status fmi2_layer_debug_logging(Fmi2Layer *L, fmi2Boolean loggingOn, size_t n, const fmi2String cats[])
{
    if (FMI2_NULL_ARRAY(L, "fmi2SetDebugLogging", cats, n) != fmi2OK) return fmi2Error; /* "cats = NULL with n = 2" */
    fmi2_layer_set_logging(L, loggingOn, n, cats);
    return fmi2OK;
}

int fmi2_layer_foreign_state(const Fmi2Layer *L, const char *call, const void *state)
{
    if (fmi2_live(state, FMI2_LIVE_STATE)) return 0;
    fmi2_layer_log(L, fmi2Error, "%s refused: FMUstate = %p is not a state of this FMU (freed, or another FMU's)",
                   call, state);
    return 1;
}

fmi2Status fmi2_layer_mode_refusal(const Fmi2Layer *L, const char *call, unsigned mask)
{
    if (L->mode == FMI2_MODE_FATAL) return fmi2Fatal; /* already reported once */
    if (L->mode == FMI2_MODE_ERROR && !(mask & FMI2_BIT(FMI2_ERROR))) {
        fmi2_layer_log(L, fmi2Error, "call %s not allowed after an error", call);
        return fmi2Error;
    }
    return fmi2OK;
}

const char *fmi_call_refusal(const char *label, const char *interface, const char *call, unsigned mask, int state,
                             char *buf, size_t size)
{
    if (state >= 0 && state < FMI2_N_STATES && (mask & FMI2_BIT(state))) return NULL;
    const char *name = state >= 0 && state < FMI2_N_STATES ? FMI2_STATE_NAMES[state] : "unknown";
    if ((mask & ~FMI2_BIT(FMI2_ERROR)) == 0) {
        snprintf(buf, size, "%s is not allowed in the %s state: this instance was instantiated for %s, where %s allows "
                 "it in no state of this FMU", call, name, interface, label);
        return buf;
    }
    int n = snprintf(buf, size, "%s is not allowed in the %s state (%s allows it in: ", call, name, label);
    const char *separator = "";
    for (int s = 0; s < FMI2_N_STATES; s++) {
        if (s == FMI2_ERROR || !(mask & FMI2_BIT(s))) continue;
        if (n >= 0 && (size_t)n < size) n += snprintf(buf + n, size - (size_t)n, "%s%s", separator, FMI2_STATE_NAMES[s]);
        separator = ", ";
    }
    if (n >= 0 && (size_t)n < size) snprintf(buf + n, size - (size_t)n, ")");
    return buf;
}

const char *fmi2_phase_refusal(const char *call, unsigned mask, int phase, char *buf, size_t size)
{
    return fmi_call_refusal(FMI2_LABEL, FMI2_INTERFACE, call, mask, phase, buf, size);
}

fmi2Status fmi2_layer_refuse_nonfinite(Fmi2Layer *L, fmi2Status st, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Real value[])
{
    if (st > fmi2Warning) return st;
    for (size_t i = 0; i < nvr; i++) {
        if (isfinite(value[i])) continue;
        fmi2_layer_log(L, fmi2Error, "fmi2GetReal: variable with valueReference %u is %g (not finite): refused",
                       (unsigned)vr[i], value[i]);
        L->mode = FMI2_MODE_ERROR;
        return fmi2Error;
    }
    return st;
}

/* ---- pointer arguments ---- */

fmi2Status fmi2_layer_null_refusal(const Fmi2Layer *L, const char *call, const char *argument, const char *count,
                                   size_t n)
{
    if (count != NULL) fmi2_layer_log(L, fmi2Error, "%s refused: %s = NULL with %s = %zu", call, argument, count, n);
    else fmi2_layer_log(L, fmi2Error, "%s refused: %s = NULL", call, argument);
    return fmi2Error;
}

/* ---- live instances: an open-addressing hash set (linear probing, deletion by backward shift) ---- */

typedef struct {
    const void *instance;
    int kind;
} LiveEntry;

static atomic_flag live_lock = ATOMIC_FLAG_INIT;
static LiveEntry *live_table = NULL;
static size_t live_capacity = 0, live_count = 0; /* capacity: 0 or a power of 2, at most half full */

static void live_acquire(void)
{
    while (atomic_flag_test_and_set_explicit(&live_lock, memory_order_acquire)) {
    }
}

static void live_release(void) { atomic_flag_clear_explicit(&live_lock, memory_order_release); }

static size_t live_home(const void *instance, size_t capacity)
{
    uint64_t h = (uint64_t)(uintptr_t)instance * 0x9E3779B97F4A7C15ULL;
    return (size_t)(h >> 32) & (capacity - 1);
}

/* The slot of instance, or of the empty slot where it would go. */
static size_t live_slot(const LiveEntry *table, size_t capacity, const void *instance)
{
    size_t i = live_home(instance, capacity);
    while (table[i].instance != NULL && table[i].instance != instance) i = (i + 1) & (capacity - 1);
    return i;
}

static int live_grow(void)
{
    size_t capacity = live_capacity == 0 ? 64 : 2 * live_capacity;
    LiveEntry *table = calloc(capacity, sizeof *table);
    if (table == NULL) return 0;
    for (size_t i = 0; i < live_capacity; i++)
        if (live_table[i].instance != NULL) table[live_slot(table, capacity, live_table[i].instance)] = live_table[i];
    free(live_table);
    live_table = table;
    live_capacity = capacity;
    return 1;
}

int fmi2_live_add(const void *instance, int kind)
{
    if (instance == NULL) return 0;
    live_acquire();
    int ok = 2 * (live_count + 1) <= live_capacity || live_grow();
    if (ok) {
        size_t i = live_slot(live_table, live_capacity, instance);
        if (live_table[i].instance == NULL) live_count++;
        live_table[i].instance = instance;
        live_table[i].kind = kind;
    }
    live_release();
    return ok;
}

int fmi2_live(const void *instance, int kind)
{
    if (instance == NULL) return 0;
    live_acquire();
    int found = 0;
    if (live_capacity > 0) {  /* the slot looked up once */
        const LiveEntry *entry = &live_table[live_slot(live_table, live_capacity, instance)];
        found = entry->instance == instance && entry->kind == kind;
    }
    live_release();
    return found;
}

int fmi2_live_remove(const void *instance, int kind)
{
    if (instance == NULL) return 0;
    live_acquire();
    int found = 0;
    if (live_capacity > 0) {
        const size_t mask = live_capacity - 1;
        size_t i = live_slot(live_table, live_capacity, instance);
        if (live_table[i].instance == instance && live_table[i].kind == kind) {
            found = 1;
            live_count--;
            for (size_t j = (i + 1) & mask; live_table[j].instance != NULL; j = (j + 1) & mask) {
                size_t home = live_home(live_table[j].instance, live_capacity);
                /* the entry at j may move to the hole at i when its home is not in (i, j] (cyclically) */
                if (((j - home) & mask) >= ((j - i) & mask)) {
                    live_table[i] = live_table[j];
                    i = j;
                }
            }
            live_table[i].instance = NULL;
            live_table[i].kind = 0;
        }
    }
    live_release();
    return found;
}

/* ---- fmi2Instantiate's arguments ---- */

static int hex_digit(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

static int prefix_nocase(const char *text, const char *prefix)
{
    for (; *prefix; text++, prefix++) {
        char c = *text >= 'A' && *text <= 'Z' ? (char)(*text - 'A' + 'a') : *text;
        if (c != *prefix) return 0;
    }
    return 1;
}

int fmi2_resource_path(fmi2String uri, char *path, size_t size, char *why, size_t why_size)
{
    const char *rule = "FMI 2.0 needs a file URI of an existing folder: file:/path, file:///path or "
                       "file://localhost/path";
    if (uri == NULL) {
        snprintf(why, why_size, "fmuResourceLocation = NULL: %s", rule);
        return 0;
    }
    if (uri[0] == '\0') {
        snprintf(why, why_size, "fmuResourceLocation = '' (empty): %s", rule);
        return 0;
    }
    const char *p = uri;
    if (!prefix_nocase(p, "file:")) {
        snprintf(why, why_size, "fmuResourceLocation = '%.900s': not a file URI; %s", uri, rule);
        return 0;
    }
    p += 5;
    if (p[0] == '/' && p[1] == '/') { /* an authority: empty or localhost */
        p += 2;
        if (prefix_nocase(p, "localhost") && (p[9] == '/' || p[9] == '\0')) p += 9;
        if (*p != '/') {
            snprintf(why, why_size, "fmuResourceLocation = '%.900s': the host is not the local one; %s", uri, rule);
            return 0;
        }
    }
    if (*p != '/') {
        snprintf(why, why_size, "fmuResourceLocation = '%.900s': the path is not absolute; %s", uri, rule);
        return 0;
    }
    size_t n = 0;
    for (; *p; p++) {
        char c = *p;
        if (c == '?' || c == '#') {
            snprintf(why, why_size, "fmuResourceLocation = '%.900s': a query or fragment ('%c') in a file URI; %s",
                     uri, c, rule);
            return 0;
        }
        if (c == '%') {
            int hi = hex_digit(p[1]), lo = hi < 0 ? -1 : hex_digit(p[2]);
            if (hi < 0 || lo < 0 || (hi == 0 && lo == 0)) {
                snprintf(why, why_size, "fmuResourceLocation = '%.900s': '%%' is not followed by two hexadecimal "
                         "digits of a byte other than 0; %s", uri, rule);
                return 0;
            }
            c = (char)(hi * 16 + lo);
            p += 2;
        }
        if (n + 1 >= size) {
            snprintf(why, why_size, "fmuResourceLocation = '%.900s': the path is longer than %zu bytes", uri,
                     size - 1);
            return 0;
        }
        path[n++] = c;
    }
    while (n > 1 && path[n - 1] == '/') n--; /* with or without a trailing '/' */
    path[n] = '\0';
#ifdef _WIN32
    if (n >= 3 && path[0] == '/' && path[2] == ':') memmove(path, path + 1, n); /* file:///C:/dir -> C:/dir */
#endif
    struct stat info;
    if (stat(path, &info) != 0 || !S_ISDIR(info.st_mode)) {
        snprintf(why, why_size, "fmuResourceLocation = '%.900s': %.900s is not an existing folder; %s", uri, path,
                 rule);
        return 0;
    }
    return 1;
}

int fmi2_instantiate_check(const Fmi2Layer *L, fmi2String instanceName, const char *model, fmi2Type fmuType,
                           unsigned types, fmi2String fmuGUID, const char *guid, fmi2String fmuResourceLocation,
                           char *path, size_t size)
{
    int blank = 1;
    for (const char *p = instanceName; p != NULL && *p && blank; p++) blank = strchr(" \t\r\n\v\f", *p) != NULL;
    if (blank) {
        fmi2_layer_log(L, fmi2Error, "fmi2Instantiate refused: instanceName = %s%.200s%s: FMI 2.0 needs a name with "
                       "a character other than white space", instanceName ? "'" : "",
                       instanceName ? instanceName : "NULL", instanceName ? "'" : "");
        return 0;
    }
    /* fmuType is the host's int: only 0 and 1 may be shifted (a shift by 32 or more, or by a negative, is undefined
       behaviour in C -- found by tests/fuzz/fuzz_layer.c) */
    int known = fmuType == fmi2ModelExchange || fmuType == fmi2CoSimulation;
    if (!known || !(types & FMI2_TYPE_BIT(fmuType))) {
        const char *type = fmuType == fmi2ModelExchange ? "fmi2ModelExchange"
                           : fmuType == fmi2CoSimulation ? "fmi2CoSimulation" : "unknown";
        fmi2_layer_log(L, fmi2Error, "fmi2Instantiate refused: fmuType = %d (%s): %s offers only %s", (int)fmuType,
                       type, model, types & FMI2_TYPE_BIT(fmi2ModelExchange) ? "Model Exchange" : "Co-Simulation");
        return 0;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, guid) != 0) {
        fmi2_layer_log(L, fmi2Error, "fmi2Instantiate refused: fmuGUID = %s%.200s%s is not %s's guid %s from its "
                       "modelDescription.xml (FMI 2.0: a wrong GUID means another FMU or version)",
                       fmuGUID ? "'" : "", fmuGUID ? fmuGUID : "NULL", fmuGUID ? "'" : "", model, guid);
        return 0;
    }
    char why[2048];
    if (!fmi2_resource_path(fmuResourceLocation, path, size, why, sizeof why)) {
        fmi2_layer_log(L, fmi2Error, "fmi2Instantiate refused: %s", why);
        return 0;
    }
    return 1;
}
