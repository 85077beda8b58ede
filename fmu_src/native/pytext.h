/*
 * pytext.h -- the text of numbers, strings and kernel exceptions in the native FMUs' messages. The values are
 * exact (a number reads back as itself); the spelling is C's, not Python's repr.
 */
#ifndef PYTEXT_H
#define PYTEXT_H

#include <stddef.h>

/* x exactly: core/pyfloat.c's exact_number_text ("1e-05", "0.0001", "2", "inf", "nan") into out. */
void native_repr(double x, char *out, size_t size);
/* A kernel message "<Type>: <text>" as it is (the exception's type, then its text). */
void kernel_message_text(const char *message, char *out, size_t size);
/* s in single quotes. */
void quoted_text(const char *s, char *out, size_t size);

#endif
