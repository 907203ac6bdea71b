/* A rig driver in C for `zwidth agent --driver ./rig_driver_c`: the toy
 * device of examples/rig_driver.py, its velocity estimator the trial's own
 * through zwidth's C ABI (include/zwidth.h), so the rig runs the
 * simulator's estimator to the bit.
 *
 * Build (docs/rigs.md, "A driver in C"):
 *   cargo build --release -p zwidth-ffi
 *   cc -std=c11 -O2 -I crates/zwidth-ffi/include examples/rig_driver_c/driver.c \
 *      target/release/libzwidth_ffi.a -lm -lpthread -ldl -o rig_driver_c
 *
 * The agent writes one JSON object per line on our stdin and reads one per
 * line from our stdout (docs/rigs.md, "the driver protocol"):
 *   {"type":"capabilities"}                 -> {"type":"capabilities", …, "dsp":{…}}
 *   {"type":"trial","request":…,"limits":…} -> {"type":"result",…} or {"type":"error",…}
 *   {"type":"abort"}                        -> the running trial stops, answered
 *                                              {"type":"error","message":"aborted"}
 *                                              (between trials: ignored)
 *
 * The device: a mass with viscous and Coulomb friction, an encoder of the
 * scene's quantization, one sample of computation delay, the wall
 * F = -K y - B v̂ for y > 0 (2011 paper §2.4: push into the wall, settle
 * 4 s, then stable if the last 2 s stay within two encoder counts), the
 * force clamped to the trial's limit. Replace `wall_hit` with your
 * controller's loop; keep `zw_init_json` and `zw_step`.
 *
 * During a trial the driver polls stdin every 10 ms of the device's time
 * for an abort, as a real controller must (ramp the force down, answer).
 * `--realtime` paces the toy like hardware: each sample waits for its
 * time, so a trial takes its 6 s (what the abort test uses).
 *
 * `--trace FILE`: after each trial that ran to its end, FILE holds its
 * positions and the velocities the estimator gave, one "y v" pair a line (%.17g: exact), so
 * they can be checked against `zwidth estimate`. */
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <poll.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "zwidth.h"

/* ---- a small JSON reader: enough to find values by key ---------------- */

static const char *ws(const char *p) {
    while (p && (*p == ' ' || *p == '\t' || *p == '\n' || *p == '\r')) p++;
    return p;
}

/* The end of the JSON value at p (NULL when malformed). */
static const char *skip(const char *p) {
    p = ws(p);
    if (!p || !*p) return NULL;
    if (*p == '"') {
        for (p++; *p && *p != '"'; p++)
            if (*p == '\\' && !*++p) return NULL;
        return *p ? p + 1 : NULL;
    }
    if (*p == '{' || *p == '[') {
        char close = *p == '{' ? '}' : ']';
        p = ws(p + 1);
        if (*p == close) return p + 1;
        for (;;) {
            if (close == '}') {
                p = skip(p); /* the key */
                p = ws(p);
                if (!p || *p != ':') return NULL;
                p++;
            }
            p = ws(skip(p));
            if (!p) return NULL;
            if (*p == close) return p + 1;
            if (*p != ',') return NULL;
            p++;
        }
    }
    while (*p && !strchr(",}] \t\r\n", *p)) p++; /* a number or literal */
    return p;
}

/* The value of `key` in the object at p, or NULL. */
static const char *member(const char *p, const char *key) {
    p = ws(p);
    if (!p || *p != '{') return NULL;
    p = ws(p + 1);
    size_t n = strlen(key);
    while (p && *p == '"') {
        const char *k = p + 1, *end = skip(p);
        if (!end) return NULL;
        p = ws(end);
        if (*p != ':') return NULL;
        const char *value = ws(p + 1);
        if ((size_t)(end - 1 - k) == n && strncmp(k, key, n) == 0) return value;
        p = ws(skip(value));
        if (!p || *p != ',') return NULL;
        p = ws(p + 1);
    }
    return NULL;
}

/* The value at a path of keys (NULL-terminated), or NULL. */
static const char *at(const char *p, const char *const *path) {
    for (; p && *path; path++) p = member(p, *path);
    return p;
}

#define AT(p, ...) at((p), (const char *const[]){__VA_ARGS__, NULL})

/* The number at p, or `fallback` when p is not a number. */
static double number(const char *p, double fallback) {
    char *end;
    if (!p) return fallback;
    double x = strtod(p, &end);
    return end == p ? fallback : x;
}

/* The JSON value at p, copied NUL-terminated (malloc'd; NULL if absent). */
static char *copy(const char *p) {
    const char *end = p ? skip(p) : NULL;
    if (!end) return NULL;
    char *out = malloc((size_t)(end - p) + 1);
    if (!out) return NULL;
    memcpy(out, p, (size_t)(end - p));
    out[end - p] = 0;
    return out;
}

/* ---- lines from the agent, read without blocking a trial ----------------- */

static char *in_buf = NULL;
static size_t in_len = 0, in_cap = 0;
static bool in_eof = false;

/* Read what fd 0 has within `timeout_ms` (-1: wait) into the buffer. */
static void fill(int timeout_ms) {
    if (in_eof) return;
    struct pollfd pfd = {.fd = 0, .events = POLLIN};
    if (poll(&pfd, 1, timeout_ms) <= 0) return;
    if (in_cap - in_len < 65536) {
        size_t cap = in_cap * 2 + 65536;
        char *grown = realloc(in_buf, cap);
        if (!grown) { in_eof = true; return; }
        in_buf = grown;
        in_cap = cap;
    }
    ssize_t n = read(0, in_buf + in_len, in_cap - in_len - 1);
    if (n <= 0) in_eof = true;
    else in_len += (size_t)n;
    in_buf[in_len] = 0;
}

static char *newline(void) { return in_len ? memchr(in_buf, '\n', in_len) : NULL; }

/* The next line (malloc'd, NUL-terminated, without its newline), waiting
 * for it; NULL at the end of the input. */
static char *next_line(void) {
    while (!newline() && !in_eof) fill(-1);
    char *nl = newline();
    if (!nl) return NULL;
    size_t n = (size_t)(nl - in_buf);
    char *line = malloc(n + 1);
    if (!line) return NULL;
    memcpy(line, in_buf, n);
    line[n] = 0;
    memmove(in_buf, nl + 1, in_len - n - 1);
    in_len -= n + 1;
    in_buf[in_len] = 0;
    return line;
}

/* Whether an abort has arrived (taken off the input if so). */
static bool abort_waiting(void) {
    fill(0);
    char *nl = newline();
    if (!nl) return false;
    *nl = 0;
    const char *type = member(in_buf, "type");
    bool is_abort = type && strncmp(type, "\"abort\"", 7) == 0;
    *nl = '\n';
    if (is_abort) {
        size_t n = (size_t)(nl - in_buf) + 1;
        memmove(in_buf, nl + 1, in_len - n);
        in_len -= n;
        in_buf[in_len] = 0;
    }
    return is_abort;
}

static bool realtime = false;

static double now_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* ---- the toy device ----------------------------------------------------- */

static const char *trace_path = NULL;

typedef struct {
    double peak_force_n, peak_speed_m_s, penetration_m;
} measured;

/* One wall hit at (k, b). Returns 1 stable, 0 not, -1 aborted past a limit,
 * -2 the estimator refused its spec (`why` says which parameter), -3
 * aborted by the agent. */
static int wall_hit(const char *req, const char *limits, double k, double b, measured *m,
                    char *why, size_t why_len) {
    const char *dev = AT(req, "scene", "device");
    double mass = number(member(dev, "mass"), 0.1), damping = number(member(dev, "damping"), 0.0);
    double coulomb = number(member(dev, "coulomb"), 0.0), q = number(member(dev, "quantization"), 1e-6);
    double rate = number(AT(req, "scene", "loop", "sample_hz"), 1000.0), T = 1.0 / rate;
    double f_max = number(member(limits, "force_limit_n"), 1.0);
    double abort_x = number(member(limits, "abort_penetration_m"), 0.01);
    double abort_v = number(member(limits, "abort_speed_m_s"), 1.0);
    /* The trial's estimator, from the scene's JSON spec (the simulator's
     * default, FDM, when the scene names none). */
    char *spec = copy(AT(req, "scene", "estimator"));
    static zw_estimator est; /* 8 KiB, caller-owned: a static here */
    zw_error err;
    zw_status s = zw_init_json(&est, spec ? spec : "{\"kind\":\"fdm\"}", rate, q, &err);
    free(spec);
    if (s != ZW_OK) {
        snprintf(why, why_len, "estimator.%s: %s", err.parameter, err.message);
        return -2;
    }
    char part[4096];
    snprintf(part, sizeof part, "%s.part", trace_path ? trace_path : "");
    FILE *trace = trace_path ? fopen(part, "w") : NULL;
    double push = 0.36;                    /* N, toward the wall */
    double x = -0.002, v = 0.0, f_out = 0.0; /* m, m/s, N (one sample late) */
    long settle = (long)(4.0 / T), measure = (long)(2.0 / T);
    double lo = INFINITY, hi = -INFINITY;
    *m = (measured){0, 0, 0};
    long every = (long)(0.01 / T) > 0 ? (long)(0.01 / T) : 1; /* samples in 10 ms */
    double start = now_s();
    for (long n = 0; n < settle + measure; n++) {
        if (n % every == 0) {
            if (realtime) { /* hardware's pace */
                double wait = start + (double)n * T - now_s();
                if (wait > 0) {
                    struct timespec d = {(time_t)wait, (long)((wait - floor(wait)) * 1e9)};
                    nanosleep(&d, NULL);
                }
            }
            if (abort_waiting()) { /* a real driver ramps its force down here */
                if (trace) fclose(trace);
                return -3;
            }
        }
        double y = round(x / q) * q, v_hat; /* the encoder */
        zw_step(&est, y, &v_hat);           /* the trial's own estimator */
        if (trace) fprintf(trace, "%.17g %.17g\n", y, v_hat);
        double f = y > 0 ? -k * y - b * v_hat : 0.0; /* the virtual wall */
        f = fmax(-f_max, fmin(f_max, f));            /* the controller's clamp */
        double applied = f_out;
        f_out = f;                                   /* one sample of delay */
        if (fabs(x) > abort_x || fabs(v) > abort_v) {
            if (trace) fclose(trace);
            return -1;
        }
        double friction = v > 0 ? coulomb : v < 0 ? -coulomb : 0.0;
        double a = (push + applied - damping * v - friction) / mass;
        v += a * T;
        x += v * T;
        m->peak_force_n = fmax(m->peak_force_n, fabs(applied));
        m->peak_speed_m_s = fmax(m->peak_speed_m_s, fabs(v));
        m->penetration_m = fmax(m->penetration_m, x);
        if (n >= settle) {
            lo = fmin(lo, y);
            hi = fmax(hi, y);
        }
    }
    if (trace) {
        fclose(trace);
        rename(part, trace_path); /* only whole trials replace the last */
    }
    return hi - lo <= 2 * q; /* still within 2 counts */
}

int main(int argc, char **argv) {
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--trace") == 0 && i + 1 < argc) {
            trace_path = argv[++i];
        } else if (strcmp(argv[i], "--realtime") == 0) {
            realtime = true;
        } else {
            fprintf(stderr, "usage: %s [--trace FILE] [--realtime]\n", argv[0]);
            return 2;
        }
    }
    char identity[512];
    if (zw_dsp_identity(identity, sizeof identity, NULL) != ZW_OK) {
        fprintf(stderr, "zw_dsp_identity: 512 bytes were not enough\n");
        return 1;
    }
    char *line;
    while ((line = next_line()) != NULL) {
        const char *type = member(line, "type");
        if (type && strncmp(type, "\"capabilities\"", 14) == 0) {
            printf("{\"type\":\"capabilities\",\"peak_force_n\":10.0,\"continuous_force_n\":4.0,"
                   "\"k_max\":1e6,\"b_max\":1e4,\"travel_m\":0.1,\"speed_m_s\":1.0,"
                   "\"encoder_m\":1e-6,\"sample_hz\":[1000.0,2000.0,5000.0,10000.0],"
                   "\"estimators\":[\"fdm\",\"butterworth\",\"kalman\",\"adaptive_kalman\","
                   "\"foaw\",\"levant\"],\"probes\":[\"wall_hit\"],\"dsp\":%s}\n",
                   identity);
        } else if (type && strncmp(type, "\"trial\"", 7) == 0) {
            const char *req = member(line, "request"), *limits = member(line, "limits");
            double k = number(member(req, "k"), NAN), b = number(member(req, "b"), NAN);
            if (!req || !limits || isnan(k) || isnan(b)) {
                printf("{\"type\":\"error\",\"message\":\"a trial without request.k, request.b or limits\"}\n");
            } else {
                measured m;
                char why[300] = "";
                int stable = wall_hit(req, limits, k, b, &m, why, sizeof why);
                if (stable == -2) {
                    /* The message names the parameter; quotes and
                     * backslashes would break the line: drop them. */
                    for (char *c = why; *c; c++)
                        if (*c == '"' || *c == '\\') *c = '\'';
                    printf("{\"type\":\"error\",\"message\":\"%s\"}\n", why);
                } else if (stable == -3) {
                    printf("{\"type\":\"error\",\"message\":\"aborted\"}\n");
                } else if (stable < 0) {
                    printf("{\"type\":\"error\",\"message\":\"aborted: past the speed or travel limit\"}\n");
                } else {
                    /* K and B go back with every bit (%.17g round-trips). */
                    printf("{\"type\":\"result\",\"point\":{\"k\":%.17g,\"b\":%.17g,\"stable\":%s},"
                           "\"measured\":{\"peak_force_n\":%.17g,\"peak_speed_m_s\":%.17g,"
                           "\"penetration_m\":%.17g}}\n",
                           k, b, stable ? "true" : "false", m.peak_force_n, m.peak_speed_m_s,
                           m.penetration_m);
                }
            }
        }
        /* An abort between trials: nothing is running. */
        fflush(stdout);
        free(line);
    }
    free(in_buf);
    return 0;
}
