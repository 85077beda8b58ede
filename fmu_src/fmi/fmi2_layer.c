/*
 * fmi2_layer.c -- the FMI 2.0 plumbing shared by the status shim and the native FMUs (see fmi2_layer.h).
 */
#include "fmi2_layer.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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

fmi2Status fmi2_layer_mode_refusal(const Fmi2Layer *L, const char *call, unsigned mask)
{
    if (L->mode == FMI2_MODE_FATAL) return fmi2Fatal; /* already reported once */
    if (L->mode == FMI2_MODE_ERROR && !(mask & FMI2_BIT(FMI2_ERROR))) {
        fmi2_layer_log(L, fmi2Error, "call %s not allowed after an error", call);
        return fmi2Error;
    }
    return fmi2OK;
}

const char *fmi2_phase_refusal(const char *call, unsigned mask, int phase, char *buf, size_t size)
{
    if (mask & FMI2_BIT(phase)) return NULL;
    int n = snprintf(buf, size, "%s is not allowed in the %s state (FMI 2.0 allows it in: ", call,
                     FMI2_STATE_NAMES[phase]);
    const char *separator = "";
    for (int s = 0; s < FMI2_N_PHASES; s++) {
        if (!(mask & FMI2_BIT(s))) continue;
        if (n >= 0 && (size_t)n < size) n += snprintf(buf + n, size - (size_t)n, "%s%s", separator, FMI2_STATE_NAMES[s]);
        separator = ", ";
    }
    if (n >= 0 && (size_t)n < size) snprintf(buf + n, size - (size_t)n, ")");
    return buf;
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
