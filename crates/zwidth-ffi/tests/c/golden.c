/* The C ABI against zwidth-dsp's golden vectors, bit for bit, and every
 * bad input answered with its status (crates/zwidth-ffi/tests/c_program.rs
 * compiles this with cc -std=c11 -Wall -Wextra -Werror at -O0 and -O2).
 *
 * usage: golden VECTORS_FILE
 * prints "c: N cases equal, M refusals checked" and exits 0, or names the
 * first difference and exits 1. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "zwidth.h"

static int failures = 0;

#define CHECK(cond, ...)                       \
    do {                                       \
        if (!(cond)) {                         \
            fprintf(stderr, "FAIL %s:%d: ", __FILE__, __LINE__); \
            fprintf(stderr, __VA_ARGS__);      \
            fprintf(stderr, "\n");             \
            failures++;                        \
        }                                      \
    } while (0)

static double from_bits(uint64_t b) {
    double x;
    memcpy(&x, &b, sizeof x);
    return x;
}

static uint64_t to_bits(double x) {
    uint64_t b;
    memcpy(&b, &x, sizeof b);
    return b;
}

/* FNV-1a, 64 bit, over each value's 8 little-endian bytes. */
static uint64_t fnv(const double *v, size_t n) {
    uint64_t h = 0xcbf29ce484222325ULL;
    for (size_t i = 0; i < n; i++) {
        uint64_t b = to_bits(v[i]);
        for (int k = 0; k < 8; k++) {
            h ^= (b >> (8 * k)) & 0xff;
            h *= 0x100000001b3ULL;
        }
    }
    return h;
}

static zw_estimator est; /* 8 KiB: a static, as on a controller */

static int run_vectors(const char *path) {
    FILE *f = fopen(path, "r");
    if (!f) {
        fprintf(stderr, "cannot open %s\n", path);
        return -1;
    }
    static char line[4096];
    double *pos = NULL, *out = NULL;
    size_t n = 0, filled = 0;
    double rate = 0, quant = 0;
    char signal[64] = "";
    int cases = 0;
    /* the current estimator's expected outputs */
    char name[64] = "", spec[2048] = "";
    size_t stride = 1, expect_i = 0;
    unsigned long long hash = 0;
    int in_case = 0;
    while (fgets(line, sizeof line, f)) {
        line[strcspn(line, "\n")] = 0;
        if (line[0] == '#' || strncmp(line, "zwidth-dsp", 10) == 0) continue;
        if (strncmp(line, "signal ", 7) == 0) {
            free(pos);
            free(out);
            if (sscanf(line, "signal %63s %lf %lf %zu", signal, &rate, &quant, &n) != 4) return -1;
            pos = calloc(n, sizeof *pos);
            out = calloc(n, sizeof *out);
            filled = 0;
            in_case = 0;
        } else if (line[0] == 'p') {
            unsigned long long b;
            if (sscanf(line, "p %llx", &b) != 1 || filled >= n) return -1;
            pos[filled++] = from_bits(b);
        } else if (line[0] == 'r') {
            unsigned long long b;
            size_t count;
            if (sscanf(line, "r %zu %llx", &count, &b) != 2 || filled + count > n) return -1;
            for (size_t i = 0; i < count; i++) pos[filled++] = from_bits(b);
        } else if (strncmp(line, "estimator ", 10) == 0) {
            int off = 0;
            if (sscanf(line, "estimator %63s %zu %llx %n", name, &stride, &hash, &off) != 3) return -1;
            snprintf(spec, sizeof spec, "%s", line + off);
            zw_error err;
            zw_status s = zw_init_json(&est, spec, rate, quant, &err);
            CHECK(s == ZW_OK, "%s: init %d: %s: %s", name, (int)s, err.parameter, err.message);
            s = zw_step_n(&est, pos, out, n);
            CHECK(s == ZW_OK, "%s: step_n %d", name, (int)s);
            CHECK(fnv(out, n) == hash, "%s on %s: hash %016llx, the vectors say %016llx", name,
                  signal, (unsigned long long)fnv(out, n), hash);
            /* step one at a time after a reset: the same bits */
            CHECK(zw_reset(&est) == ZW_OK, "reset");
            for (size_t i = 0; i < n; i++) {
                double v;
                CHECK(zw_step(&est, pos[i], &v) == ZW_OK, "step");
                if (to_bits(v) != to_bits(out[i])) {
                    CHECK(0, "%s on %s: step %zu differs from step_n", name, signal, i);
                    break;
                }
            }
            expect_i = 0;
            in_case = 1;
            cases++;
        } else if (line[0] == 'v' && in_case) {
            unsigned long long b;
            if (sscanf(line, "v %llx", &b) != 1) return -1;
            size_t i = expect_i * stride;
            if (i < n && to_bits(out[i]) != b) {
                CHECK(0, "%s on %s: output %zu is %016llx, the vectors say %016llx", name, signal, i,
                      (unsigned long long)to_bits(out[i]), b);
                in_case = 0;
            }
            expect_i++;
        }
    }
    free(pos);
    free(out);
    fclose(f);
    return cases;
}

/* Every bad input gets its status; nothing crashes. */
static int refusals(void) {
    int checked = 0;
    zw_error err;
    zw_estimator zeroed;
    memset(&zeroed, 0, sizeof zeroed);
    double v = 0, y[2] = {0.0, 1e-6};
    uint64_t fp;
#define REFUSE(expr, status)                                                       \
    do {                                                                           \
        zw_status s_ = (expr);                                                     \
        CHECK(s_ == (status), "%s gave %d, expected %d", #expr, (int)s_, (int)(status)); \
        checked++;                                                                 \
    } while (0)
    REFUSE(zw_init_json(NULL, "{\"kind\":\"fdm\"}", 1e3, 1e-6, &err), ZW_NULL);
    REFUSE(zw_init_json(&est, NULL, 1e3, 1e-6, &err), ZW_NULL);
    REFUSE(zw_init_json(&est, "{\"kind\":", 1e3, 1e-6, &err), ZW_PARSE);
    CHECK(strcmp(err.parameter, "spec_json") == 0, "parse names %s", err.parameter);
    REFUSE(zw_init_json(&est, "{\"kind\":\"fdm\"}", NAN, 1e-6, &err), ZW_BAD_PARAMETER);
    CHECK(strcmp(err.parameter, "rate") == 0, "NaN rate names %s", err.parameter);
    CHECK(strstr(err.message, "NaN") == NULL, "no NaN in the message: %s", err.message);
    REFUSE(zw_init_json(&est, "{\"kind\":\"butterworth\",\"cutoff_hz\":600}", 1e3, 1e-6, &err),
           ZW_BAD_PARAMETER);
    CHECK(strcmp(err.parameter, "cutoff_hz") == 0, "cutoff names %s", err.parameter);
    REFUSE(zw_init_json(&est, "{\"kind\":\"foaw\",\"fit\":\"end\",\"max_window\":100}", 1e3, 1e-6, &err),
           ZW_CAPACITY);
    CHECK(strcmp(err.parameter, "max_window") == 0 && strstr(err.message, "64") != NULL,
          "capacity names %s: %s", err.parameter, err.message);
    REFUSE(zw_init_json(&est, "{\"kind\":\"fdm\",\"median_velocity\":200}", 1e3, 1e-6, &err), ZW_CAPACITY);
    REFUSE(zw_init_json(&est, "{\"kind\":\"kalman\",\"q\":-1}", 1e3, 1e-6, &err), ZW_BAD_PARAMETER);
    CHECK(strcmp(err.parameter, "q") == 0, "q names %s", err.parameter);
    /* A key written twice is refused, not read as the last one (issue 45). */
    REFUSE(zw_init_json(&est, "{\"kind\":\"kalman\",\"q\":1e4,\"q\":-1}", 1e3, 1e-6, &err),
           ZW_BAD_PARAMETER);
    CHECK(strcmp(err.parameter, "q") == 0 && strstr(err.message, "twice") != NULL,
          "a duplicate key names %s: %s", err.parameter, err.message);
    REFUSE(zw_init_json(&est, "{\"kind\":\"nope\"}", 1e3, 1e-6, NULL), ZW_BAD_PARAMETER);
    REFUSE(zw_init_fdm(&est, 0.0, &err), ZW_BAD_PARAMETER);
    REFUSE(zw_init_fdm(&est, INFINITY, &err), ZW_BAD_PARAMETER);
    REFUSE(zw_init_butterworth(&est, 1e3, 100.0, 11, &err), ZW_CAPACITY);
    CHECK(strcmp(err.parameter, "order") == 0, "order names %s", err.parameter);
    /* Order 0 is a bad parameter, not beyond the capacity (issue 45). */
    REFUSE(zw_init_butterworth(&est, 1e3, 100.0, 0, &err), ZW_BAD_PARAMETER);
    CHECK(strcmp(err.parameter, "order") == 0, "order 0 names %s", err.parameter);
    /* One limit, one code: a window past this build's 64 through JSON is
     * ZW_CAPACITY, as through zw_init_foaw, though the service's own limit
     * (4096) refuses it as well. */
    REFUSE(zw_init_json(&est, "{\"kind\":\"foaw\",\"fit\":\"end\",\"max_window\":5000}", 1e3, 1e-6, &err),
           ZW_CAPACITY);
    CHECK(strcmp(err.parameter, "max_window") == 0 && strstr(err.message, "64") != NULL,
          "capacity through JSON names %s: %s", err.parameter, err.message);
    REFUSE(zw_init_kalman(&est, 1e3, 1e-6, 1e4, 7, 0.0, &err), ZW_BAD_PARAMETER);
    CHECK(strcmp(err.parameter, "model") == 0, "model names %s", err.parameter);
    REFUSE(zw_init_kalman(&est, 1e3, 1e-6, 1e4, ZW_WHITE_JERK, 1.5, &err), ZW_BAD_PARAMETER);
    CHECK(strcmp(err.parameter, "rho") == 0, "rho names %s", err.parameter);
    REFUSE(zw_init_foaw(&est, 1e3, ZW_FOAW_BEST, -1e-6, 16, false, &err), ZW_BAD_PARAMETER);
    REFUSE(zw_init_foaw(&est, 1e3, ZW_FOAW_BEST, 1e-6, ZW_FOAW_MAX_WINDOW + 1, false, &err), ZW_CAPACITY);
    REFUSE(zw_init_foaw(&est, 1e3, 9, 1e-6, 16, false, &err), ZW_BAD_PARAMETER);
    REFUSE(zw_init_levant(&est, 1e3, 0.0, 3.0, ZW_LEVANT_EXPLICIT, &err), ZW_BAD_PARAMETER);
    CHECK(strcmp(err.parameter, "alpha") == 0, "alpha names %s", err.parameter);
    REFUSE(zw_init_levant(&est, 1e3, 13.2, 3.46, -1, &err), ZW_BAD_PARAMETER);
    REFUSE(zw_step(&zeroed, 0.0, &v), ZW_NOT_INITIALIZED);
    REFUSE(zw_step(NULL, 0.0, &v), ZW_NULL);
    REFUSE(zw_reset(&zeroed), ZW_NOT_INITIALIZED);
    REFUSE(zw_fingerprint(&zeroed, &fp), ZW_NOT_INITIALIZED);
    /* A filled estimator: NaN and inf positions refused, the state unchanged. */
    REFUSE(zw_init_fdm(&est, 1e3, &err), ZW_OK);
    REFUSE(zw_step(&est, 1e-3, NULL), ZW_NULL);
    REFUSE(zw_step(&est, 1e-3, &v), ZW_OK);
    REFUSE(zw_step(&est, NAN, &v), ZW_BAD_PARAMETER);
    REFUSE(zw_step(&est, -INFINITY, &v), ZW_BAD_PARAMETER);
    REFUSE(zw_step(&est, 2e-3, &v), ZW_OK);
    CHECK(v == 1.0, "after the refusals FDM gives (2e-3 - 1e-3)*1e3 = 1, got %g", v);
    y[1] = NAN;
    REFUSE(zw_step_n(&est, y, y, 2), ZW_BAD_PARAMETER);
    CHECK(y[0] == 0.0, "a refused block writes nothing");
    REFUSE(zw_step_n(&est, NULL, y, 2), ZW_NULL);
    REFUSE(zw_step_n(&est, NULL, NULL, 0), ZW_OK);
    REFUSE(zw_step_n(NULL, NULL, NULL, 0), ZW_NULL);
    REFUSE(zw_step_n(&zeroed, NULL, NULL, 0), ZW_NOT_INITIALIZED);
    /* A position that overflows the estimate (2e308 m/ms) is refused and
     * resets the state: never ZW_OK with a non-finite estimate. */
    REFUSE(zw_init_fdm(&est, 1e3, &err), ZW_OK);
    REFUSE(zw_step(&est, 1e308, &v), ZW_OK);
    CHECK(isfinite(v), "the first step is finite: %g", v);
    v = 7.0;
    REFUSE(zw_step(&est, -1e308, &v), ZW_BAD_PARAMETER);
    CHECK(v == 7.0, "a refused step writes nothing");
    REFUSE(zw_step(&est, 1e-3, &v), ZW_OK);
    REFUSE(zw_step(&est, 2e-3, &v), ZW_OK);
    CHECK(v == 1.0, "after the reset FDM gives (2e-3 - 1e-3)*1e3 = 1, got %g", v);
    y[0] = 1e308;
    y[1] = -1e308;
    REFUSE(zw_step_n(&est, y, y, 2), ZW_BAD_PARAMETER);
    REFUSE(zw_step(&est, 0.0, &v), ZW_OK);
    CHECK(isfinite(v), "finite after a refused block: %g", v);
    /* A failed re-init leaves the struct refusing, not the old filter
     * running: by a bad value, bad JSON and a bad enumerator. */
    REFUSE(zw_init_fdm(&est, 0.0, &err), ZW_BAD_PARAMETER);
    REFUSE(zw_step(&est, 0.0, &v), ZW_NOT_INITIALIZED);
    REFUSE(zw_init_fdm(&est, 1e3, &err), ZW_OK);
    REFUSE(zw_init_json(&est, "{", 1e3, 1e-6, &err), ZW_PARSE);
    REFUSE(zw_reset(&est), ZW_NOT_INITIALIZED);
    REFUSE(zw_init_fdm(&est, 1e3, &err), ZW_OK);
    REFUSE(zw_init_kalman(&est, 1e3, 1e-6, 1e4, 7, 0.0, &err), ZW_BAD_PARAMETER);
    REFUSE(zw_fingerprint(&est, &fp), ZW_NOT_INITIALIZED);
    REFUSE(zw_init_fdm(&est, 1e3, &err), ZW_OK);
    REFUSE(zw_step(&est, 0.0, &v), ZW_OK);
    REFUSE(zw_fingerprint(&est, NULL), ZW_NULL);
    REFUSE(zw_fingerprint(&est, &fp), ZW_OK);
    CHECK(zw_abi_version() == ZW_ABI_VERSION, "abi version");
    CHECK(zw_estimator_size() == sizeof(zw_estimator), "sizeof");
    CHECK(strlen(zw_version()) > 0, "version");
    /* The identity a driver advertises: too small a buffer writes nothing
     * and says what it needs; 512 bytes suffice (the header says so). */
    char small[8] = "unset", identity[512];
    size_t needed = 0;
    REFUSE(zw_dsp_identity(small, sizeof small, &needed), ZW_CAPACITY);
    CHECK(strcmp(small, "unset") == 0 && needed > sizeof small && needed <= sizeof identity,
          "a short buffer untouched, %zu bytes needed", needed);
    REFUSE(zw_dsp_identity(NULL, 0, NULL), ZW_NULL);
    REFUSE(zw_dsp_identity(identity, sizeof identity, NULL), ZW_OK);
    CHECK(strlen(identity) + 1 == needed, "identity of %zu bytes", strlen(identity));
    CHECK(strncmp(identity, "{\"version\":\"", 12) == 0 && strstr(identity, "\"levant\":\"") != NULL,
          "identity %s", identity);
    return checked;
}

int main(int argc, char **argv) {
    if (argc != 2) {
        fprintf(stderr, "usage: %s VECTORS_FILE\n", argv[0]);
        return 2;
    }
    int cases = run_vectors(argv[1]);
    CHECK(cases == 90, "read %d cases of 90", cases);
    int checked = refusals();
    if (failures) {
        fprintf(stderr, "%d failures\n", failures);
        return 1;
    }
    printf("c: %d cases equal, %d refusals checked\n", cases, checked);
    return 0;
}
