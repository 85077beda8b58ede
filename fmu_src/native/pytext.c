/*
 * pytext.c -- the text of numbers, strings and kernel exceptions in the native FMUs' messages (see pytext.h).
 */
#include "pytext.h"

#include "pyfloat.h"

#include <stdio.h>

void native_repr(double x, char *out, size_t size)
{
    number_text text;
    snprintf(out, size, "%s", exact_number_text(text, x)); /* core/pyfloat.c: x exactly, in C's %g */
}

void quoted_text(const char *s, char *out, size_t size)
{
    snprintf(out, size, "'%s'", s);
}

void kernel_message_text(const char *message, char *out, size_t size)
{
    snprintf(out, size, "%s", message);
}
