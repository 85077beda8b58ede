/*
 * pytext.c -- Python's repr of floats, strings and exceptions (see pytext.h).
 *
 * repr(float) is CPython's float_repr: the shortest digit string that reads back as the same double
 * (found here by trying 1..17 significant digits with printf's correctly rounded %e), written in fixed
 * notation when the decimal exponent (the position of the point, 0.d1d2... x 10^decpt) lies in
 * -4 < decpt <= 16, else as d.ddde+XX (at least two exponent digits); fixed notation gets ".0" when it
 * has no fraction.
 */
#include "pytext.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void py_repr(double x, char *out, size_t size)
{
    if (isnan(x)) { snprintf(out, size, "nan"); return; }
    if (isinf(x)) { snprintf(out, size, x > 0 ? "inf" : "-inf"); return; }
    if (x == 0.0) { snprintf(out, size, signbit(x) ? "-0.0" : "0.0"); return; }
    char buf[64];
    int p;
    for (p = 1; p <= 17; p++) {
        snprintf(buf, sizeof buf, "%.*e", p - 1, x);
        if (strtod(buf, NULL) == x) break;
    }
    /* buf: [-]d[.ddd]e[+-]XX */
    const char *s = buf;
    int negative = *s == '-';
    if (negative) s++;
    char digits[32];
    size_t n = 0;
    for (; *s && *s != 'e'; s++)
        if (*s != '.') digits[n++] = *s;
    digits[n] = '\0';
    while (n > 1 && digits[n - 1] == '0') digits[--n] = '\0';
    int exponent = atoi(s + 1);  /* x = d.ddd * 10^exponent */
    int decpt = exponent + 1;
    char text[64];
    size_t k = 0;
    if (negative) text[k++] = '-';
    if (decpt > -4 && decpt <= 16) {
        if (decpt <= 0) {
            text[k++] = '0';
            text[k++] = '.';
            for (int i = 0; i < -decpt; i++) text[k++] = '0';
            for (size_t i = 0; i < n; i++) text[k++] = digits[i];
        } else {
            for (int i = 0; i < decpt; i++) text[k++] = (size_t)i < n ? digits[i] : '0';
            text[k++] = '.';
            if ((size_t)decpt < n)
                for (size_t i = (size_t)decpt; i < n; i++) text[k++] = digits[i];
            else
                text[k++] = '0';
        }
        text[k] = '\0';
    } else {
        text[k++] = digits[0];
        if (n > 1) {
            text[k++] = '.';
            for (size_t i = 1; i < n; i++) text[k++] = digits[i];
        }
        snprintf(text + k, sizeof text - k, "e%c%02d", exponent < 0 ? '-' : '+', abs(exponent));
    }
    snprintf(out, size, "%s", text);
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
