/*
 * pytext.c -- Python's repr of floats (core/pyfloat.c's), strings and exceptions (see pytext.h).
 */
#include "pytext.h"

#include "pyfloat.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void native_repr(double x, char *out, size_t size)
{
    number_text text;
    snprintf(out, size, "%s", py_repr(text, x)); /* core/pyfloat.c: the one implementation of repr(float) */
}

void py_str_repr(const char *s, char *out, size_t size)
{
    char quote = (strchr(s, '\'') != NULL && strchr(s, '"') == NULL) ? '"' : '\'';
    size_t k = 0;
    if (size < 3) { if (size) out[0] = '\0'; return; }
    out[k++] = quote;
    for (; *s && k + 3 < size; s++) {
        char c = *s;
        if (c == quote || c == '\\') { out[k++] = '\\'; out[k++] = c; }
        else if (c == '\n') { out[k++] = '\\'; out[k++] = 'n'; }
        else if (c == '\r') { out[k++] = '\\'; out[k++] = 'r'; }
        else if (c == '\t') { out[k++] = '\\'; out[k++] = 't'; }
        else out[k++] = c;
    }
    out[k++] = quote;
    out[k] = '\0';
}

void py_exception_repr(const char *message, char *out, size_t size)
{
    const char *colon = strstr(message, ": ");
    if (colon == NULL) { snprintf(out, size, "RuntimeError(%s)", message); return; }
    int type_length = (int)(colon - message);
    const char *text = colon + 2;
    char quoted[600];
    if (strncmp(message, "OverflowError", (size_t)type_length) == 0 && type_length == 13) {
        char *end;
        long number = strtol(text, &end, 10);
        if (end != text && *end == ' ') {
            py_str_repr(end + 1, quoted, sizeof quoted);
            snprintf(out, size, "OverflowError(%ld, %s)", number, quoted);
            return;
        }
    }
    py_str_repr(text, quoted, sizeof quoted);
    snprintf(out, size, "%.*s(%s)", type_length, message, quoted);
}
