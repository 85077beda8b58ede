/*
 * pytext.h -- Python's text of numbers and exceptions, so that the native FMUs log the messages the Python
 * slaves log (which format values with repr()).
 */
#ifndef PYTEXT_H
#define PYTEXT_H

#include <stddef.h>

/* repr(x) of a Python float ("1e-05", "0.0001", "2.0", "inf", "nan"): core/pyfloat.c's py_repr into out. */
void native_repr(double x, char *out, size_t size);
/* repr of the exception a kernel message "<Type>: <text>" stands for: "Type('text')";
   "OverflowError: 34 Numerical result out of range" -> "OverflowError(34, 'Numerical result out of range')". */
void py_exception_repr(const char *message, char *out, size_t size);
/* repr(s) of a Python str (quotes chosen as Python does; \\, \n, \r, \t and the quote escaped). */
void py_str_repr(const char *s, char *out, size_t size);

#endif
