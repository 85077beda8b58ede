/*
 * fuzz_layer.c -- libFuzzer target of the FMI 2.0 layer the pythonfmu FMUs' status shim and the native FMUs
 * share (fmu_src/fmi/fmi2_layer.c): the part of the shim that runs without Python.  (The rest of the shim
 * forwards calls to pythonfmu's library and the Python slave: not drivable without an interpreter; the native
 * targets drive the same layer through their FMI calls.)
 *
 * An input chooses one of:
 *   fmi2_resource_path     on a URI from the input (and a few prefixes that reach deep: file:, file://host/ ...):
 *                          when accepted, the path must be NUL-terminated inside its buffer and name a folder;
 *   fmi2_instantiate_check on instance name, GUID, fmuType and resource location from the input;
 *   logging                fmi2_layer_init / set_logging with categories from the input, then messages with
 *                          '%' and categories from the input through fmi2_layer_log / emit / fmi2_log_to, the
 *                          error mode's and the state table's refusals, the non-finite refusal;
 * findings: sanitizer reports, a message reaching the logger with an unescaped '%', an accepted path that is not
 * a folder.
 */
#include <stdint.h>
#include <string.h>
#include <sys/stat.h>

#include "fmi2_layer.h"
#include "fuzz_input.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env; (void)status;
    check_logged(name, category, message);
}

static const char *const PREFIXES[] = {"", "file:", "file://", "file:///", "file://localhost/", "file:/tmp",
                                       "file:///tmp/", "FILE://LOCALHOST/tmp/%2", "file:///tmp%2F", "http://x/"};

static const char *in_uri(In *in, char *buf, size_t size)
{
    uint8_t k = in_u8(in);
    if (k == 255) return NULL;
    const char *prefix = PREFIXES[k % (sizeof PREFIXES / sizeof PREFIXES[0])];
    size_t p = strlen(prefix);
    memcpy(buf, prefix, p);
    char *rest = buf + p;
    size_t len = in_u8(in) % (size - p);
    for (size_t i = 0; i < len; i++) rest[i] = (char)in_u8(in);
    rest[len] = '\0';
    return buf;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    In in = {data, size};
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    Fmi2Layer L;
    char uri[300], name[40], guid[48], why[256];
    switch (in_u8(&in) % 3) {
    case 0: {
        size_t psize = 1 + in_u8(&in) % 300;
        char path[300];
        memset(path, 'x', sizeof path);
        const char *u = in_uri(&in, uri, sizeof uri);
        if (fmi2_resource_path(u, path, psize, why, 1 + in_u8(&in) % sizeof why)) {
            if (memchr(path, '\0', psize) == NULL) FUZZ_FAIL("fmi2_resource_path: the path is not terminated");
            struct stat st;
            if (stat(path, &st) != 0 || !S_ISDIR(st.st_mode))
                FUZZ_FAIL("fmi2_resource_path accepted %s as %s, not a folder", u, path);
        }
        break;
    }
    case 1: {
        const char *nm = in_string(&in, name, sizeof name);
        if (!fmi2_layer_init(&L, nm, (in_u8(&in) & 7) == 0 ? NULL : &cb, in_u8(&in) & 1)) break;
        const char *g = in_string(&in, guid, sizeof guid);
        const char *u = in_uri(&in, uri, sizeof uri);
        char path[300];
        unsigned types = in_u8(&in) % 4;
        fmi2Type type = (fmi2Type)(in_u8(&in) < 250 ? in_u8(&in) % 2 : in_i32(&in));
        fmi2_instantiate_check(&L, nm, "FuzzModel", type, types, g, "{guid}", u, path, 1 + in_u8(&in) % sizeof path);
        fmi2_layer_free(&L);
        break;
    }
    default: {
        const char *nm = in_string(&in, name, sizeof name);
        if (!fmi2_layer_init(&L, nm, &cb, in_u8(&in) & 1)) break;
        for (int k = 0; k < 16 && in.n > 0; k++) {
            char text[64], cat[24];
            fmi2Status status = (fmi2Status)(in_u8(&in) % 6);
            switch (in_u8(&in) % 8) {
            case 0: {
                size_t n = in_u8(&in) % 5;
                char cats[4][24];
                fmi2String list[4];
                for (size_t i = 0; i < n; i++) list[i] = in_string(&in, cats[i], sizeof cats[i]);
                fmi2_layer_set_logging(&L, in_u8(&in) & 1, n, (in_u8(&in) & 7) ? list : NULL);
                break;
            }
            case 1: fmi2_layer_log(&L, status, "%s", in_string(&in, text, sizeof text) ?: "(null)"); break;
            case 2: fmi2_layer_emit(&L, in_string(&in, name, sizeof name), status, in_string(&in, cat, sizeof cat),
                                    in_string(&in, text, sizeof text)); break;
            case 3: fmi2_log_to(&cb, in_string(&in, name, sizeof name), status, in_string(&in, cat, sizeof cat),
                                in_string(&in, text, sizeof text)); break;
            case 4: L.mode = (Fmi2Mode)(in_u8(&in) % 3);
                fmi2_layer_mode_check(&L, in_string(&in, text, sizeof text) ?: "call", in_u8(&in)); break;
            case 5: {
                char buf[256];
                const char *r = fmi2_phase_refusal(in_string(&in, text, sizeof text) ?: "call", in_u8(&in),
                                                   in_u8(&in) % FMI2_N_PHASES, buf, 1 + in_u8(&in) % sizeof buf);
                if (r != NULL && memchr(r, '\0', sizeof buf) == NULL) FUZZ_FAIL("fmi2_phase_refusal: unterminated");
                break;
            }
            case 6: {
                fmi2ValueReference vr[4];
                fmi2Real v[4];
                size_t n = in_u8(&in) % 5;
                for (size_t i = 0; i < n; i++) { vr[i] = (fmi2ValueReference)in_i32(&in); v[i] = in_double(&in); }
                fmi2Status st = fmi2_layer_finite_reals(&L, status, vr, n, v);
                if (st <= fmi2Warning)
                    for (size_t i = 0; i < n; i++)
                        if (!isfinite(v[i])) FUZZ_FAIL("fmi2_layer_finite_reals let %g through", v[i]);
                break;
            }
            default: {
                const char *t = in_string(&in, text, sizeof text);
                fmi2_layer_log(&L, status, "value %g of %s: %d%%", in_double(&in), t ? t : "?", in_i32(&in));
                break;
            }
            }
        }
        fmi2_layer_free(&L);
        break;
    }
    }
    return 0;
}
