/*
 * test_estimator.c - command-line driver and self-test of the C estimator core.
 *
 * Build (the core linked statically, see fmus/estimator/Makefile):
 *     cc -std=c99 -O2 -Wall -Wextra -Werror -pedantic -I fmus/estimator \
 *        tests/c/test_estimator.c fmus/estimator/duffid_estimator.c fmus/estimator/duffid_linalg.c -lm
 *
 * Usage:
 *     test_estimator run MODEL METHOD RECORD.csv [KEY=VALUE ...]
 *         MODEL duffing1|duffing2, METHOD robust|paper; RECORD: duffid's CSV (header line,
 *         then t, f, x or t, f1, x1, x2). Prints one line per sample:
 *         n,t,identified,condition,uncertainty,window,<parameters...> (%.17g), and the
 *         mean update time on stderr. KEY: any duffid_config field (window, window_periods,
 *         max_window, forgetting, rows=integrals|bernstein|paper, n_rows, max_condition,
 *         max_uncertainty, min_time, settle, gamma, quadrature=adams3|trapezoid,
 *         sign_in_numerator, offset, deadband), repeat=N (timing repetitions).
 *     test_estimator selftest
 *         API checks (caller memory, error codes, independence of instances, reset).
 */
#include "duffid_estimator.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define MAX_SAMPLES 2000000L

static int fail(const char *what)
{
    fprintf(stderr, "test_estimator: %s\n", what);
    return 2;
}

static int parse_model(const char *s)
{
    return strcmp(s, "duffing1") == 0 ? DUFFID_DUFFING1 : (strcmp(s, "duffing2") == 0 ? DUFFID_DUFFING2 : 0);
}

static int set_option(duffid_config *cfg, const char *arg, long *repeat)
{
    char key[64];
    const char *eq = strchr(arg, '=');
    const char *val;
    double v;
    size_t len;
    if (eq == NULL || (len = (size_t)(eq - arg)) >= sizeof key) {
        return -1;
    }
    memcpy(key, arg, len);
    key[len] = '\0';
    val = eq + 1;
    v = strtod(val, NULL);
    /* every option of the table, by its C code (duffid.identification.options.to_c) */
#define TEST_SET_REAL(name) cfg->name = v;
#define TEST_SET_CODE(name) cfg->name = atoi(val);
#define TEST_SET_OPTION(kind, name, default_value, minimum, maximum, methods, valid) \
    if (strcmp(key, #name) == 0) {                                                  \
        TEST_SET_##kind(name) return 0;                                             \
    }
    DUFFID_OPTIONS(TEST_SET_OPTION)
#undef TEST_SET_OPTION
    if (strcmp(key, "offset") == 0) {
        cfg->offset = atoi(val);
    } else if (strcmp(key, "repeat") == 0) {
        *repeat = atol(val);
    } else {
        return -1;
    }
    return 0;
}

/* Reads duffid's CSV: one header line, then t, forces, displacements per line. */
static long read_record(const char *path, int n_cols, double **data)
{
    FILE *fp = fopen(path, "r");
    char line[4096];
    long n = 0, cap = 4096;
    if (fp == NULL) {
        return -1;
    }
    *data = (double *)malloc((size_t)cap * (size_t)n_cols * sizeof(double));
    if (*data == NULL || fgets(line, sizeof line, fp) == NULL) { /* header */
        fclose(fp);
        return -1;
    }
    while (fgets(line, sizeof line, fp) != NULL && n < MAX_SAMPLES) {
        char *p = line, *end;
        int c;
        if (line[0] == '\n' || line[0] == '#') {
            continue;
        }
        if (n == cap) {
            double *bigger;
            cap *= 2;
            bigger = (double *)realloc(*data, (size_t)cap * (size_t)n_cols * sizeof(double));
            if (bigger == NULL) {
                fclose(fp);
                return -1;
            }
            *data = bigger;
        }
        for (c = 0; c < n_cols; c++) {
            (*data)[n * n_cols + c] = strtod(p, &end);
            if (end == p) {
                fclose(fp);
                return -1;
            }
            p = end;
            while (*p == ',' || *p == ' ' || *p == '\t') {
                p++;
            }
        }
        n++;
    }
    fclose(fp);
    return n;
}

static void print_output(long n, const duffid_output *out)
{
    int i;
    printf("%ld,%.17g,%d,%.17g,%.17g,%.17g", n, out->t, out->identified, out->condition, out->uncertainty,
           out->window);
    for (i = 0; i < out->n_parameters; i++) {
        printf(",%.17g", out->parameters[i]);
    }
    printf("\n");
}

static int run(int argc, char **argv)
{
    duffid_config cfg;
    duffid_estimator *est;
    duffid_output out;
    char msg[256];
    double *data = NULL;
    long n_samples, k, repeat = 1, r;
    int model, method, n_dof, n_cols, i, rc;
    clock_t t0, t1;
    if (argc < 5) {
        return fail("usage: test_estimator run MODEL METHOD RECORD.csv [KEY=VALUE ...]");
    }
    model = parse_model(argv[2]);
    method = strcmp(argv[3], "robust") == 0 ? DUFFID_ROBUST : (strcmp(argv[3], "paper") == 0 ? DUFFID_PAPER : -1);
    if (model == 0 || method < 0) {
        return fail("unknown model or method");
    }
    n_dof = model == DUFFID_DUFFING1 ? 1 : 2;
    n_cols = 1 + 1 + n_dof;
    n_samples = read_record(argv[4], n_cols, &data);
    if (n_samples < 2) {
        free(data);
        return fail("cannot read the record");
    }
    duffid_default_config(&cfg, model, method, data[n_cols] - data[0]);
    /* the sampling period as Record.dt: the median step; records here are uniform */
    cfg.dt = (data[(n_samples - 1) * n_cols] - data[0]) / (double)(n_samples - 1);
    for (i = 5; i < argc; i++) {
        if (strncmp(argv[i], "dt=", 3) == 0) {
            cfg.dt = strtod(argv[i] + 3, NULL);
        } else if (set_option(&cfg, argv[i], &repeat) != 0) {
            free(data);
            return fail(argv[i]);
        }
    }
    rc = duffid_create(&est, &cfg, msg, sizeof msg);
    if (rc != DUFFID_OK) {
        free(data);
        fprintf(stderr, "test_estimator: configuration error %d: %s\n", rc, msg);
        return 3;
    }
    for (k = 0; k < n_samples; k++) {
        const double *row = data + k * n_cols;
        if (duffid_update(est, row + 2, row + 1, &out) != DUFFID_OK) {
            fprintf(stderr, "test_estimator: sample %ld rejected\n", k);
            return 4;
        }
        print_output(k, &out);
    }
    t0 = clock();
    for (r = 0; r < repeat; r++) {
        duffid_reset(est);
        for (k = 0; k < n_samples; k++) {
            const double *row = data + k * n_cols;
            duffid_update(est, row + 2, row + 1, &out);
        }
    }
    t1 = clock();
    fprintf(stderr, "mean update time: %.3f us over %ld samples x %ld\n",
            1e6 * (double)(t1 - t0) / CLOCKS_PER_SEC / (double)(n_samples * repeat), n_samples, repeat);
    duffid_destroy(est);
    free(data);
    return 0;
}

/* ------------------------------------------------------------------ self-test */
static int failures = 0;

static void check(int ok, const char *what)
{
    if (!ok) {
        fprintf(stderr, "FAIL: %s\n", what);
        failures++;
    }
}

static int same(double a, double b)
{
    return (a != a && b != b) || a == b;
}

static int same_output(const duffid_output *a, const duffid_output *b)
{
    int i, ok = a->identified == b->identified && same(a->condition, b->condition) &&
                same(a->uncertainty, b->uncertainty) && same(a->window, b->window) && same(a->t, b->t);
    for (i = 0; i < a->n_parameters; i++) {
        ok = ok && same(a->parameters[i], b->parameters[i]) && same(a->current[i], b->current[i]) &&
             a->status[i] == b->status[i];
    }
    return ok;
}

/* A synthetic Duffing response (semi-implicit Euler at a finer step). */
static void synth(int model, long n, double dt, double *x, double *f)
{
    double x1 = 0.0, v1 = 0.0, x2 = 0.0, v2 = 0.0, h = dt / 20.0;
    long k;
    int s;
    for (k = 0; k < n; k++) {
        double force = 10.0;
        f[k] = force;
        x[2 * k] = x1;
        x[2 * k + 1] = x2;
        for (s = 0; s < 20; s++) {
            double a1, a2, y = x2 - x1, w = v2 - v1;
            if (model == DUFFID_DUFFING1) {
                a1 = (force - 12.47 * v1 - 1272.1 * x1 + 1.237e6 * x1 * x1 * x1) / 2.53;
                a2 = 0.0;
            } else {
                double f2 = 4.0 * w + 1570.0 * y - 1.35e6 * y * y * y;
                a1 = (force - 5.0 * v1 - 1272.1 * x1 + 1.237e6 * x1 * x1 * x1 + f2) / 2.53;
                a2 = -f2 / 2.754;
            }
            v1 += h * a1;
            v2 += h * a2;
            x1 += h * v1;
            x2 += h * v2;
        }
    }
}

static void selftest_model(int model, int method)
{
    enum { N = 600 };
    static double x[2 * N], f[N];
    static double memory[200000];
    duffid_config cfg;
    duffid_estimator *a, *b, *c;
    duffid_output oa, ob, oc, first[N];
    char msg[256];
    double bad[2];
    long k;
    int all_same = 1, identified = 0, rc, i;

    synth(model, N, 1e-3, x, f);
    check(duffid_default_config(&cfg, model, method, 1e-3) == DUFFID_OK, "default config");
    check(duffid_check_config(&cfg, msg, sizeof msg) == DUFFID_OK, "defaults are valid");
    check(duffid_memory_size(&cfg) > 0 && duffid_memory_size(&cfg) <= sizeof memory, "memory size");

    /* caller memory, misaligned on purpose; too small a block is refused */
    rc = duffid_init(&a, (char *)memory + 4, duffid_memory_size(&cfg) - 1, &cfg, msg, sizeof msg);
    check(rc == DUFFID_ERR_ARGUMENT && a == NULL, "too small a memory block is refused");
    rc = duffid_init(&a, (char *)memory + 4, sizeof memory - 4, &cfg, msg, sizeof msg);
    check(rc == DUFFID_OK && a != NULL, "init in caller memory");
    check(duffid_create(&b, &cfg, msg, sizeof msg) == DUFFID_OK, "create");
    check(duffid_create(&c, &cfg, msg, sizeof msg) == DUFFID_OK, "create a second");
    check(duffid_n_parameters(a) == (model == DUFFID_DUFFING1 ? 4 : 8), "parameter count");
    check(strcmp(duffid_parameter_name(a, 0), model == DUFFID_DUFFING1 ? "m" : "m1") == 0, "parameter name");
    check(duffid_parameter_name(a, 8) == NULL, "parameter name out of range");

    bad[0] = NAN;
    bad[1] = 0.0;
    for (k = 0; k < N; k++) {
        /* a and b run interleaved (independent instances), b also sees rejected samples */
        check(duffid_update(a, x + 2 * k, f + k, &oa) == DUFFID_OK, "update");
        if (k % 50 == 7) {
            double inf_force = INFINITY;
            check(duffid_update(b, bad, f + k, &ob) == DUFFID_ERR_SAMPLE, "NaN displacement rejected");
            check(duffid_update(b, x + 2 * k, &inf_force, &ob) == DUFFID_ERR_SAMPLE, "infinite force rejected");
        }
        check(duffid_update(b, x + 2 * k, f + k, &ob) == DUFFID_OK, "update b");
        all_same = all_same && same_output(&oa, &ob);
        for (i = 0; i < oa.n_parameters; i++) {
            identified |= oa.status[i] == DUFFID_STATUS_PUBLISHED;
        }
        first[k] = oa;
    }
    check(all_same, "instances are independent and rejected samples change nothing");
    check(identified, "the synthetic record publishes parameters");
    if (method == DUFFID_ROBUST && model == DUFFID_DUFFING1) {
        check(fabs(oa.parameters[0] / 2.53 - 1.0) < 0.05 && fabs(oa.parameters[2] / 1272.1 - 1.0) < 0.05,
              "estimates near the simulated values");
    }
    /* reset reproduces the run exactly */
    duffid_reset(a);
    all_same = 1;
    for (k = 0; k < N; k++) {
        duffid_update(a, x + 2 * k, f + k, &oa);
        duffid_update(c, x + 2 * k, f + k, &oc);
        all_same = all_same && same_output(&oa, &first[k]) && same_output(&oc, &first[k]);
    }
    check(all_same, "reset reproduces the run; a fresh instance gives the same");
    check(duffid_update(NULL, x, f, &oa) == DUFFID_ERR_ARGUMENT, "NULL estimator");
    check(duffid_update(a, x, f, NULL) == DUFFID_OK, "NULL output allowed");
    duffid_destroy(b);
    duffid_destroy(c);
    duffid_destroy(a); /* caller memory: a no-op */
}

static void selftest_config(void)
{
    duffid_config cfg;
    duffid_estimator *est = NULL;
    char msg[256];
    check(duffid_default_config(&cfg, 7, DUFFID_ROBUST, 1e-3) == DUFFID_ERR_ARGUMENT, "unknown model default");
    duffid_default_config(&cfg, DUFFID_DUFFING1, DUFFID_ROBUST, 1e-3);
    cfg.dt = -1.0;
    check(duffid_create(&est, &cfg, msg, sizeof msg) == DUFFID_ERR_CONFIG && est == NULL &&
          strstr(msg, "dt") != NULL, "negative dt");
    duffid_default_config(&cfg, DUFFID_DUFFING1, DUFFID_ROBUST, 1e-3);
    cfg.max_uncertainty = NAN;
    check(duffid_create(&est, &cfg, msg, sizeof msg) == DUFFID_ERR_CONFIG && strstr(msg, "max_uncertainty") != NULL,
          "NaN max_uncertainty");
    duffid_default_config(&cfg, DUFFID_DUFFING1, DUFFID_ROBUST, 1e-3);
    cfg.n_rows = DUFFID_MAX_ROWS + 1;
    check(duffid_create(&est, &cfg, msg, sizeof msg) == DUFFID_ERR_CONFIG && strstr(msg, "n_rows") != NULL,
          "too many rows");
    duffid_default_config(&cfg, DUFFID_DUFFING1, DUFFID_ROBUST, 1e-3);
    cfg.window = -0.5;
    check(duffid_create(&est, &cfg, msg, sizeof msg) == DUFFID_ERR_CONFIG && strstr(msg, "window") != NULL,
          "negative window");
    duffid_default_config(&cfg, DUFFID_DUFFING1, DUFFID_ROBUST, 1e-3);
    cfg.nominal[0] = INFINITY;
    check(duffid_create(&est, &cfg, msg, sizeof msg) == DUFFID_ERR_CONFIG && strstr(msg, "m_nominal") != NULL,
          "infinite prior size");
    duffid_default_config(&cfg, DUFFID_DUFFING2, DUFFID_PAPER, 1e-3);
    cfg.quadrature = 5;
    check(duffid_create(&est, &cfg, msg, sizeof msg) == DUFFID_ERR_CONFIG && strstr(msg, "quadrature") != NULL,
          "bad quadrature");
    duffid_default_config(&cfg, DUFFID_DUFFING2, DUFFID_PAPER, 1e-3);
    cfg.method = 9;
    check(duffid_check_config(&cfg, msg, sizeof msg) == DUFFID_ERR_CONFIG && duffid_memory_size(&cfg) == 0,
          "bad method");
    check(duffid_create(&est, NULL, msg, sizeof msg) == DUFFID_ERR_ARGUMENT, "NULL configuration");
}

static int selftest(void)
{
    selftest_config();
    selftest_model(DUFFID_DUFFING1, DUFFID_ROBUST);
    selftest_model(DUFFID_DUFFING1, DUFFID_PAPER);
    selftest_model(DUFFID_DUFFING2, DUFFID_ROBUST);
    selftest_model(DUFFID_DUFFING2, DUFFID_PAPER);
    if (failures) {
        fprintf(stderr, "%d self-test failure(s)\n", failures);
        return 1;
    }
    printf("selftest ok\n");
    return 0;
}

int main(int argc, char **argv)
{
    if (argc >= 2 && strcmp(argv[1], "run") == 0) {
        return run(argc, argv);
    }
    if (argc >= 2 && strcmp(argv[1], "selftest") == 0) {
        return selftest();
    }
    return fail("usage: test_estimator run MODEL METHOD RECORD.csv [KEY=VALUE ...] | selftest");
}
