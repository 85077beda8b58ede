/*
 * fuzz_input.h -- reading a libFuzzer input as a stream of arguments (the fuzz targets of tests/fuzz/).
 * An exhausted input reads as zeros, so every prefix of an input is a valid program.
 */
#ifndef FUZZ_INPUT_H
#define FUZZ_INPUT_H

#include <float.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    const uint8_t *p;
    size_t n;
} In;

static inline uint8_t in_u8(In *in)
{
    if (in->n == 0) return 0;
    in->n--;
    return *in->p++;
}

static inline uint16_t in_u16(In *in) { return (uint16_t)(in_u8(in) | (unsigned)in_u8(in) << 8); }

static inline uint64_t in_u64(In *in)
{
    uint64_t v = 0;
    for (int i = 0; i < 8; i++) v |= (uint64_t)in_u8(in) << (8 * i);
    return v;
}

/* A double: mostly one of the values that break numerical code, else 8 raw bytes (any bit pattern). */
static const double INTERESTING[] = {0.0, -0.0, 1.0, -1.0, 0.5, 2.0, 1e-3, 0.1, 3.0, -1.5, 1.5, 1e-12, 1e12,
                                     1e300, -1e300, DBL_MIN, 4.9406564584124654e-324, DBL_MAX, NAN, INFINITY,
                                     -INFINITY, 0.999, 1.001, 100.0, -100.0, 2147483648.0, -2147483649.0, 0.25};
#define N_INTERESTING (sizeof INTERESTING / sizeof INTERESTING[0])

static inline double in_double(In *in)
{
    uint8_t k = in_u8(in);
    if (k < 2 * N_INTERESTING) return INTERESTING[k % N_INTERESTING];
    uint64_t bits = in_u64(in);
    double d;
    memcpy(&d, &bits, sizeof d);
    return d;
}

static inline int32_t in_i32(In *in)
{
    static const int32_t SPECIAL[] = {0, 1, -1, 2, 3, 4, 5, 6, 7, 100, INT32_MAX, INT32_MIN};
    uint8_t k = in_u8(in);
    if (k < 24) return SPECIAL[k % 12];
    return (int32_t)(in_u16(in) | (uint32_t)in_u16(in) << 16);
}

/* A communication step: small steps mostly (the work of a doStep grows with its length), the refused ones
   (negative, zero, non-finite, sub-normal) and raw bytes with finite positive values capped at 4 time units. */
static inline double in_step(In *in)
{
    static const double STEPS[] = {1e-3, 0.01, 0.1, 0.5, 1.0, 2.0, 0.0, -0.1, NAN, INFINITY, 5e-324, 1e-9};
    uint8_t k = in_u8(in);
    if (k < 240) return STEPS[k % 12];
    double h = in_double(in);
    return (isfinite(h) && h > 4.0) ? 4.0 : h;
}

/* A string from the input (NUL-terminated, at most size - 1 bytes); NULL for one selector value. */
static inline const char *in_string(In *in, char *buf, size_t size)
{
    uint8_t len = in_u8(in);
    if (len == 255) return NULL;
    size_t n = len % size;
    for (size_t i = 0; i < n; i++) buf[i] = (char)in_u8(in);
    buf[n] = '\0';
    return buf;
}

/* An oracle broke: print what and abort (libFuzzer records the input as a crash). */
#define FUZZ_FAIL(...)                                                                                          \
    do {                                                                                                        \
        fprintf(stderr, "FUZZ FINDING: " __VA_ARGS__);                                                          \
        fprintf(stderr, "\n");                                                                                  \
        abort();                                                                                                \
    } while (0)

/* The text a logger received must be a format with every '%' doubled (the FMI layers pass messages on as
   printf formats without arguments): a lone '%' would make the host read arguments that are not there. */
static inline void check_message_escaped(const char *message)
{
    if (message == NULL) FUZZ_FAIL("a log message is NULL");
    for (const char *c = message; *c; c++)
        if (*c == '%') {
            if (c[1] != '%') FUZZ_FAIL("a log message has an unescaped '%%': %s", message);
            c++;
        }
}

/* What the FMI 2.0 loggers check of a call: every byte of the instance name and category is read (ASan reports a bad
   pointer) and the message is escaped (check_message_escaped). */
static inline void check_logged(const char *name, const char *category, const char *message)
{
    volatile size_t n = (name ? strlen(name) : 0) + (category ? strlen(category) : 0);
    (void)n;
    check_message_escaped(message);
}

#endif
