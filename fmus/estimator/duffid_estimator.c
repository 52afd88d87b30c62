/*
 * duffid_estimator.c - portable C99 port of duffid.identification.engine.OnlineIdentifier.
 *
 * The engine is generic over a model description (duffid_model.h): channels, blocks of
 * equations as terms over the channels, the parameters' attributes. Duffing1 and Duffing2
 * are described here (describe_builtin, channels by a switch); any other model comes as a
 * generated description whose channel function CasADi wrote (DUFFID_GENERATED).
 *
 * Section names follow the Python modules:
 *   channels        models.Channel / identification._Channels
 *   kernel bank     regressors.row_exponents, regressors.KernelBank
 *   moments         regressors.SlidingMoments, regressors.gregory_corrections
 *   robust solve    identification._QRLeastSquares, solve_factor
 *   paper method    identification.Integrators, OnlineIdentifier._paper_step
 *   combination     Chain/EquationModel.combine_solutions, auto_window
 *   publication     OnlineIdentifier._publish, _window_ok, _after_publish
 *
 * The order of floating-point operations follows the Python code wherever it is defined
 * by the source (not by BLAS/LAPACK), so that both round alike.
 */
#include "duffid_estimator.h"
#include "duffid_linalg.h"

#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#ifndef DUFFID_NO_STDIO
#include <stdio.h>
#endif
#include <stdlib.h>
#include <string.h>

/* ------------------------------------------------------------------ maxima */
#define MAX_CH DUFFID_MAX_CHANNELS
#define MAX_UNK DUFFID_MAX_UNKNOWNS
#define MAX_AUG (MAX_UNK + 1)        /* augmented factor [A D] */
#define MAX_EQ DUFFID_MAX_BLOCKS
#define MAX_ORDER DUFFID_MAX_DERIVATIVE /* derivative orders 0..2 */
#define N_ORD (MAX_ORDER + 1)
#define MAX_DEG (DUFFID_MAX_ROWS + 4) /* highest moment power */
#define MAX_POW (MAX_DEG + 1)
#define MAX_BROWS (DUFFID_MAX_PARTS * DUFFID_MAX_ROWS) /* rows of one block per window */
#define MAX_CORR 6                   /* quadrature end corrections */
#define MIN_SAMPLES 8                /* identification._MIN_SAMPLES */
#define MAX_CAPACITY 100000000L      /* longest robust window in samples */
#define ANY_SIGN (DUFFID_ALLOW_POSITIVE | DUFFID_ALLOW_ZERO | DUFFID_ALLOW_NEGATIVE)

#define DNAN ((double)NAN)      /* NAN and INFINITY are float constants in C99 */
#define DINF ((double)INFINITY)

static const double PI = 3.141592653589793238462643383279502884;

/* channel kinds of the built-in models (a generated model computes its channels itself) */
enum { CH_X = 0, CH_DEFL = 1, CH_FORCE = 2, CH_ONE = 3 };
/* canonical parameters of the built-in chains: id = 4 * dof + kind, offsets 4 * n_dof + dof */
enum { P_M = 0, P_B = 1, P_K1 = 2, P_K3 = 3 };

typedef struct {
    int kind, index, power;
} channel_t;

typedef struct {
    int n_in, depth;   /* inputs and integrator depth (y has depth + 1 levels) */
    double *y, *p1, *p2;
    int count;         /* samples pushed, saturated at 2 */
} integrators_t;

typedef struct { /* the state of one block of the description */
    double theta[MAX_UNK], rse[MAX_UNK], cond;
    double share[MAX_UNK], rhs_share; /* shares of the terms and of the right-hand side */
    double R[MAX_AUG * MAX_AUG]; /* robust: accumulated factor of [A D] */
    double rows;
    integrators_t reg, det;      /* paper */
} equation_t;

struct duffid_estimator {
    duffid_config cfg;
    duffid_model model;                    /* the description (a copy: the state is self-contained) */
    int n_dof, n_forces, n_params, n_ch, n_eq;
    channel_t ch[MAX_CH];                  /* built-in models: what each channel is */
    equation_t eq[MAX_EQ];
    double nominal[DUFFID_MAX_PARAMS];     /* canonical order, |prior size| (0: none) */

    /* common state */
    int64_t n;                             /* index of the newest sample, -1 before any */
    int window_fixed;
    int64_t steady[DUFFID_MAX_PARAMS];     /* canonical order, saturated at settle_count */
    double anchor[DUFFID_MAX_PARAMS];      /* canonical order: value the estimate stays near */
    int64_t anchored[DUFFID_MAX_PARAMS];   /* ... since this sample */
    int64_t settled[DUFFID_MAX_PARAMS];    /* canonical order, saturated at settle_count */
    int64_t unsettled[DUFFID_MAX_PARAMS];  /* canonical order, saturated at settle_count */
    int status[DUFFID_MAX_PARAMS];         /* canonical order, DUFFID_STATUS_* */
    double held[DUFFID_MAX_PARAMS];        /* public order */
    int64_t settle_count;
    int has_last_x;                        /* signs of velocity (identification._Channels) */
    double last_x[DUFFID_MAX_DOF], sgn[DUFFID_MAX_DOF];

    /* robust */
    long capacity, target;
    int auto_window;
    int n_rows, degree;
    double lam, sqrt_lam;
    int row_a[DUFFID_MAX_ROWS], row_b[DUFFID_MAX_ROWS], raw_b[DUFFID_MAX_ROWS];
    double coef[DUFFID_MAX_ROWS * N_ORD * MAX_POW];
    double expo[DUFFID_MAX_ROWS * N_ORD * MAX_POW];
    double norm[DUFFID_MAX_ROWS], norm_power[DUFFID_MAX_ROWS];
    double d_scale[N_ORD];
    double t_ref;
    double shift[MAX_POW * MAX_POW];
    long poly_L;                            /* cache key of poly/row_scale (-1: empty) */
    double poly[DUFFID_MAX_ROWS * N_ORD * MAX_POW];
    double row_scale[DUFFID_MAX_ROWS];
    double raw_pow[DUFFID_MAX_ROWS];
    long corr_L;                            /* cache key of the corrections (-1: empty) */
    int corr_n;
    long corr_off[MAX_CORR];
    double corr_w[MAX_CORR * MAX_POW];      /* [m][k] */
    double *ring;                           /* (capacity + 2) x n_ch */
    double *chan_work;                      /* workspace of a generated channel function */
    double main_acc[MAX_POW * MAX_CH], shadow[MAX_POW * MAX_CH], mom[MAX_POW * MAX_CH];
    int64_t start, shadow_from;
    double E[DUFFID_MAX_ROWS * N_ORD * MAX_CH];

    /* workspace of one update (no allocation, no large stack frames) */
    double g[MAX_CH];
    double B[MAX_BROWS * MAX_AUG];
    double W[MAX_AUG * MAX_AUG];
    double U[MAX_UNK * MAX_UNK], V[MAX_UNK * MAX_UNK], Rinv[MAX_UNK * MAX_UNK];
    double sv[MAX_UNK], scale[MAX_UNK], tmp[MAX_UNK * MAX_UNK];
    double u_in[3 * MAX_CH];
    double Ap[MAX_UNK * MAX_UNK], Dp[MAX_UNK], Aw[MAX_UNK * MAX_UNK];
    double canon[DUFFID_MAX_PARAMS], canon_rse[DUFFID_MAX_PARAMS], canon_share[DUFFID_MAX_PARAMS];
    double lin[2 * DUFFID_MAX_DOF * DUFFID_MAX_DOF];

    /* isolated outliers (identification._OutlierGuard) */
    int64_t received;                      /* index of the newest sample received */
    double gh[3 * DUFFID_MAX_DOF];         /* accepted x at n-1, n-2, n-3: [level * n_dof + j] */
    int64_t g_count;
    double g_mean[DUFFID_MAX_DOF], g_lo[DUFFID_MAX_DOF], g_hi[DUFFID_MAX_DOF], g_step[DUFFID_MAX_DOF];
    int pending;
    int64_t p_k;
    double p_x[DUFFID_MAX_DOF], p_f[DUFFID_MAX_FORCES], p_threshold[DUFFID_MAX_DOF];
    int p_suspect[DUFFID_MAX_DOF];
    long outliers;
    double outlier_t, outlier_value, outlier_replaced_by;
    int outlier_column;
    duffid_output last;                    /* output after the latest processed sample */

    void *block; /* the malloc'ed block (duffid_create), NULL for caller memory */
};

/* ------------------------------------------------------------------ helpers */
static void set_msg(char *msg, size_t size, const char *fmt, ...)
{
    va_list ap;
    if (msg == NULL || size == 0) {
        return;
    }
    va_start(ap, fmt);
#ifdef DUFFID_NO_STDIO /* targets without vsnprintf: the message template only */
    strncpy(msg, fmt, size - 1);
    msg[size - 1] = '\0';
#else
    vsnprintf(msg, size, fmt, ap);
#endif
    va_end(ap);
}

static int is_finite(double v)
{
    return v == v && v - v == 0.0;
}

/* Python's round() of a float (half to even), as a double. */
static double round_half_even(double v)
{
    double r = floor(v);
    double diff = v - r;
    if (diff > 0.5) {
        r += 1.0;
    } else if (diff == 0.5) {
        if (fmod(r, 2.0) != 0.0) {
            r += 1.0;
        }
    }
    return r;
}

static double sign_of(double v) /* np.sign */
{
    if (v > 0.0) {
        return 1.0;
    }
    if (v < 0.0) {
        return -1.0;
    }
    return v; /* 0 or NaN */
}

static double max_builtin(double current, double candidate) /* Python max(current, candidate) */
{
    return candidate > current ? candidate : current;
}

static const char *const NAMES1[] = {"m", "b", "k", "kp", "c1"};
static const char *const NAMES2[] = {"m1", "b1", "k1", "kp1", "b2", "k2", "kp2", "m2", "c1", "c2"};

/* the generated description compiled in, NULL if none */
static const duffid_model *generated_model(void)
{
#ifdef DUFFID_GENERATED_MODEL
    return &duffid_generated_model;
#else
    return NULL;
#endif
}

static int model_dofs(int model)
{
    if (model == DUFFID_GENERATED) {
        return generated_model() != NULL ? generated_model()->n_dof : 0;
    }
    return model == DUFFID_DUFFING1 ? 1 : (model == DUFFID_DUFFING2 ? 2 : 0);
}

static int public_count(int model, int offset)
{
    int n = model_dofs(model);
    if (model == DUFFID_GENERATED) {
        return generated_model()->n_params;
    }
    return 4 * n + (offset ? n : 0);
}

/* canonical id of public parameter i of a built-in model */
static int public_to_canon(int model, int i)
{
    static const int map2[] = {0, 1, 2, 3, 5, 6, 7, 4, 8, 9};
    return model == DUFFID_DUFFING1 ? i : map2[i];
}

static const char *public_name(const duffid_config *cfg, int i)
{
    if (cfg->model == DUFFID_GENERATED) {
        return generated_model()->publics[i].name;
    }
    return cfg->model == DUFFID_DUFFING1 ? NAMES1[i] : NAMES2[i];
}

/* ------------------------------------------------------------------ configuration */
int duffid_default_config(duffid_config *cfg, int model, int method, double dt)
{
    if (cfg == NULL || model_dofs(model) == 0) {
        return DUFFID_ERR_ARGUMENT;
    }
    memset(cfg, 0, sizeof *cfg);
    cfg->model = model;
    cfg->method = method;
    cfg->offset = 0;
    cfg->dt = dt;
#define DUFFID_SET_DEFAULT(kind, name, default_value, minimum, maximum, methods, valid) \
    cfg->name = default_value;
    DUFFID_OPTIONS(DUFFID_SET_DEFAULT)
#undef DUFFID_SET_DEFAULT
    return DUFFID_OK;
}

/* The range checks of the option table (duffid_options.h): a REAL option is a finite
 * number >= its minimum, a CODE option an int in 0 .. maximum (maximum < 0: no bound);
 * only the options the configured method reads are checked. */
static int check_REAL(const char *name, int used, double v, double minimum, int maximum, const char *valid,
                      char *msg, size_t size)
{
    (void)maximum;
    if (used && !(is_finite(v) && v >= minimum)) {
        set_msg(msg, size, "option %s must be %s, got %g", name, valid, v);
        return DUFFID_ERR_CONFIG;
    }
    return DUFFID_OK;
}

static int check_CODE(const char *name, int used, int v, double minimum, int maximum, const char *valid,
                      char *msg, size_t size)
{
    (void)minimum;
    if (used && (v < 0 || (maximum >= 0 && v > maximum))) {
        set_msg(msg, size, "option %s must be %s, got %d", name, valid, v);
        return DUFFID_ERR_CONFIG;
    }
    return DUFFID_OK;
}

/* unknowns of block e */
static int block_unknowns(const duffid_config *cfg, int e)
{
    if (cfg->model == DUFFID_GENERATED) {
        return generated_model()->blocks[e].n_unknowns;
    }
    /* DOF 1: m1 b1 k1_1 k1_3 [b2 k2_1 k2_3] [c1]; DOF 2 (unforced): b2/m2 k2_1/m2 k2_3/m2 [c2/m2] */
    if (e == 0) {
        return (cfg->model == DUFFID_DUFFING2 ? 7 : 4) + (cfg->offset ? 1 : 0);
    }
    return 3 + (cfg->offset ? 1 : 0);
}

static int block_count(const duffid_config *cfg)
{
    return cfg->model == DUFFID_GENERATED ? generated_model()->n_blocks : model_dofs(cfg->model);
}

static int n_unknowns_max(const duffid_config *cfg)
{
    int e, best = 0;
    for (e = 0; e < block_count(cfg); e++) {
        if (block_unknowns(cfg, e) > best) {
            best = block_unknowns(cfg, e);
        }
    }
    return best;
}

static int effective_rows(const duffid_config *cfg)
{
    int def = n_unknowns_max(cfg) + 1;
    if (def < 8) {
        def = 8;
    }
    return cfg->n_rows ? cfg->n_rows : def;
}

static long capacity_of(const duffid_config *cfg)
{
    double seconds = cfg->window > 0.0 ? cfg->window : cfg->max_window;
    double r = round_half_even(seconds / cfg->dt);
    if (!(r <= (double)MAX_CAPACITY)) {
        return -1;
    }
    return r < 2.0 ? 2L : (long)r;
}

/* distinct channels: x1 x1 x1^3 f1 (Duffing1) or x1 x1 x1^3 (x2-x1) (x2-x1)^3 f1 x2
 * (Duffing2), x and the first deflection counted apart as in Python; + 1 with offsets */
static int channel_count(const duffid_config *cfg)
{
    if (cfg->model == DUFFID_GENERATED) {
        return generated_model()->n_channels;
    }
    return (model_dofs(cfg->model) == 1 ? 4 : 7) + (cfg->offset ? 1 : 0);
}

static int channel_work(const duffid_config *cfg)
{
    return cfg->model == DUFFID_GENERATED ? generated_model()->channel_work : 0;
}

int duffid_check_config(const duffid_config *cfg, char *msg, size_t size)
{
    int i, rc, n_pub, method_bit;
    if (cfg == NULL) {
        set_msg(msg, size, "no configuration");
        return DUFFID_ERR_ARGUMENT;
    }
    if (model_dofs(cfg->model) == 0) {
        set_msg(msg, size,
                cfg->model == DUFFID_GENERATED
                    ? "model DUFFID_GENERATED (3): no generated model was compiled in (-DDUFFID_GENERATED_MODEL)"
                    : "unknown model %d; choose DUFFID_DUFFING1 (1), DUFFID_DUFFING2 (2) or DUFFID_GENERATED (3)",
                cfg->model);
        return DUFFID_ERR_CONFIG;
    }
    if (cfg->method != DUFFID_ROBUST && cfg->method != DUFFID_PAPER) {
        set_msg(msg, size, "unknown method %d; choose DUFFID_ROBUST (0) or DUFFID_PAPER (1)", cfg->method);
        return DUFFID_ERR_CONFIG;
    }
    if (cfg->offset != 0 && cfg->offset != 1) {
        set_msg(msg, size, "offset must be 0 or 1, got %d", cfg->offset);
        return DUFFID_ERR_CONFIG;
    }
    if (cfg->offset && cfg->model == DUFFID_GENERATED) {
        set_msg(msg, size, "offset must be 0 for the generated model (its description has its offsets)");
        return DUFFID_ERR_CONFIG;
    }
    if (!(is_finite(cfg->dt) && cfg->dt > 0.0)) {
        set_msg(msg, size, "dt must be a positive number of seconds, got %g", cfg->dt);
        return DUFFID_ERR_CONFIG;
    }
    n_pub = public_count(cfg->model, cfg->offset);
    for (i = 0; i < n_pub; i++) {
        double v = cfg->nominal[i];
        if (!is_finite(v)) {
            set_msg(msg, size, "the prior size %s_nominal must be a finite number (0: none), got %g",
                    public_name(cfg, i), v);
            return DUFFID_ERR_CONFIG;
        }
    }
    method_bit = cfg->method == DUFFID_ROBUST ? DUFFID_FOR_ROBUST : DUFFID_FOR_PAPER;
#define DUFFID_CHECK_OPTION(kind, name, default_value, minimum, maximum, methods, valid) \
    if ((rc = check_##kind(#name, ((methods) & method_bit) != 0, cfg->name, minimum, maximum, valid, msg, \
                           size)) != DUFFID_OK) {                                                         \
        return rc;                                                                                        \
    }
    DUFFID_OPTIONS(DUFFID_CHECK_OPTION)
#undef DUFFID_CHECK_OPTION
    if (cfg->method == DUFFID_PAPER && cfg->model == DUFFID_GENERATED) {
        for (i = 0; i < generated_model()->n_blocks; i++) {
            if (generated_model()->blocks[i].n_parts > 1) {
                set_msg(msg, size,
                        "the paper method solves each equation alone, and block %d has %d equations solved together: "
                        "use the robust method",
                        i + 1, generated_model()->blocks[i].n_parts);
                return DUFFID_ERR_CONFIG;
            }
        }
    }
    if (cfg->method == DUFFID_ROBUST) {
        if (effective_rows(cfg) > DUFFID_MAX_ROWS) {
            set_msg(msg, size, "n_rows must be at most %d in the C core, got %d", DUFFID_MAX_ROWS,
                    effective_rows(cfg));
            return DUFFID_ERR_CONFIG;
        }
        if (capacity_of(cfg) < 0 ||
            ((double)capacity_of(cfg) + 2.0) * (double)MAX_CH * (double)sizeof(double) >
                (double)SIZE_MAX / 2.0) {
            set_msg(msg, size, "the window (%g s at dt %g s) exceeds %ld samples or the address space",
                    cfg->window > 0.0 ? cfg->window : cfg->max_window, cfg->dt, MAX_CAPACITY);
            return DUFFID_ERR_CONFIG;
        }
    }
    set_msg(msg, size, "");
    return DUFFID_OK;
}

/* ------------------------------------------------------------------ memory layout */
#define ALIGNMENT 8u /* doubles and 64-bit integers */
#define ALIGN_UP(v) (((v) + (ALIGNMENT - 1u)) & ~(size_t)(ALIGNMENT - 1u))

static size_t dynamic_doubles(const duffid_config *cfg)
{
    int n_ch = channel_count(cfg);
    size_t total = (size_t)channel_work(cfg);
    if (cfg->method == DUFFID_ROBUST) {
        return total + (size_t)(capacity_of(cfg) + 2) * (size_t)n_ch;
    } else {
        int e;
        for (e = 0; e < block_count(cfg); e++) {
            int n_unk = block_unknowns(cfg, e);
            total += 3u * (size_t)(n_unk + 2) * (size_t)(3 * n_ch); /* regressor integrators */
            total += 3u * 3u * (size_t)(n_unk + 1);                 /* determinant integrators */
        }
        return total;
    }
}

size_t duffid_memory_size(const duffid_config *cfg)
{
    if (duffid_check_config(cfg, NULL, 0) != DUFFID_OK) {
        return 0;
    }
    return ALIGN_UP(sizeof(struct duffid_estimator)) + dynamic_doubles(cfg) * sizeof(double) + ALIGNMENT;
}

/* ------------------------------------------------------------------ structure */
static int add_channel(duffid_estimator *est, int kind, int index, int power)
{
    int i;
    for (i = 0; i < est->model.n_channels; i++) {
        if (est->ch[i].kind == kind && est->ch[i].index == index && est->ch[i].power == power) {
            return i;
        }
    }
    est->ch[i].kind = kind;
    est->ch[i].index = index;
    est->ch[i].power = power;
    return est->model.n_channels++;
}

static void add_term(duffid_estimator *est, duffid_block *block, int unknown, int kind, int index, int power,
                     int order, double coef)
{
    duffid_term *t = &block->terms[block->n_terms++];
    t->part = 0;
    t->unknown = unknown;
    t->channel = add_channel(est, kind, index, power);
    t->order = order;
    t->coef = coef;
}

static void set_name(char *dst, const char *prefix, int i, const char *suffix)
{
#ifdef DUFFID_NO_STDIO
    size_t n = strlen(prefix);
    memcpy(dst, prefix, n);
    dst[n] = (char)('0' + i);
    strcpy(dst + n + 1, suffix);
#else
    snprintf(dst, DUFFID_NAME_SIZE, "%s%d%s", prefix, i, suffix);
#endif
}

static int block_unknown_of(const duffid_block *b, const int *param_of_unknown, int param)
{
    int u;
    for (u = 0; u < b->n_unknowns; u++) {
        if (param_of_unknown[u] == param) {
            return u;
        }
    }
    return -1;
}

/* The description of Duffing1/Duffing2 (models.Chain.equations() for orders (1, 3), a force on
 * DOF 1, no Coulomb friction, and what Chain answers about its parameters). Channels are
 * registered in first-use order (lhs then rhs terms, equation by equation). */
static void describe_builtin(duffid_estimator *est)
{
    duffid_model *m = &est->model;
    const int n = model_dofs(est->cfg.model), offset = est->cfg.offset;
    int param_of[MAX_EQ][MAX_UNK];
    int i, j, e, p;
    m->n_dof = n;
    m->n_forces = 1;
    m->max_order = 2;
    m->n_blocks = n;
    m->n_params = 4 * n + (offset ? n : 0);
    m->uses_sign = 0;
    for (i = 0; i < n; i++) {
        duffid_block *b = &est->model.blocks[i];
        b->n_parts = 1;
        b->forced = i == 0;
        if (b->forced) {
            param_of[i][b->n_terms] = 4 * i + P_M;
            add_term(est, b, b->n_unknowns++, CH_X, i, 1, 2, 1.0);
        }
        param_of[i][b->n_terms] = 4 * i + P_B;
        add_term(est, b, b->n_unknowns++, CH_DEFL, i, 1, 1, 1.0);
        param_of[i][b->n_terms] = 4 * i + P_K1;
        add_term(est, b, b->n_unknowns++, CH_DEFL, i, 1, 0, 1.0);
        param_of[i][b->n_terms] = 4 * i + P_K3;
        add_term(est, b, b->n_unknowns++, CH_DEFL, i, 3, 0, 1.0);
        if (i + 1 < n) {
            param_of[i][b->n_terms] = 4 * (i + 1) + P_B;
            add_term(est, b, b->n_unknowns++, CH_DEFL, i + 1, 1, 1, -1.0);
            param_of[i][b->n_terms] = 4 * (i + 1) + P_K1;
            add_term(est, b, b->n_unknowns++, CH_DEFL, i + 1, 1, 0, -1.0);
            param_of[i][b->n_terms] = 4 * (i + 1) + P_K3;
            add_term(est, b, b->n_unknowns++, CH_DEFL, i + 1, 3, 0, -1.0);
        }
        if (offset) {
            param_of[i][b->n_terms] = 4 * n + i;
            add_term(est, b, b->n_unknowns++, CH_ONE, 0, 1, 0, 1.0);
        }
        if (b->forced) {
            add_term(est, b, -1, CH_FORCE, 0, 1, 0, 1.0);
        } else {
            add_term(est, b, -1, CH_X, i, 1, 2, -1.0);
        }
    }
    for (p = 0; p < m->n_params; p++) {
        duffid_parameter *q = &m->params[p];
        const int dof = p < 4 * n ? p / 4 : p - 4 * n, kind = p < 4 * n ? p % 4 : -1;
        static const char *const prefix[] = {"m", "b", "k", "k"};
        set_name(q->name, kind < 0 ? "c" : prefix[kind], dof + 1, kind == P_K1 ? "_1" : (kind == P_K3 ? "_3" : ""));
        q->physical = kind == P_M ? DUFFID_ALLOW_POSITIVE
                                  : (kind == P_B ? DUFFID_ALLOW_POSITIVE | DUFFID_ALLOW_ZERO : ANY_SIGN);
        q->period = kind == P_M || kind == P_K1;
        q->offset = kind < 0;
        q->scale_of = kind == P_M && !m->blocks[dof].forced ? dof : -1;
        for (j = 0; j < n; j++) {
            int u = block_unknown_of(&m->blocks[j], param_of[j], p);
            if (u >= 0) {
                if (q->scale_of < 0) {
                    q->sources[q->n_sources].block = j;
                    q->sources[q->n_sources++].unknown = u;
                }
                q->shares[q->n_shares].block = j;
                q->shares[q->n_shares++].unknown = u;
            } else if (kind == P_M && dof == j && !m->blocks[j].forced) {
                q->shares[q->n_shares].block = j;
                q->shares[q->n_shares++].unknown = -1;
            }
        }
    }
    for (i = 0; i < n; i++) { /* scale rules of the unforced DOFs (Chain.combine_solutions) */
        duffid_block *b = &m->blocks[i];
        if (b->forced) {
            continue;
        }
        for (e = i + 1; e <= i + 2 && e <= n; e++) { /* 1-based elements of mass i */
            int u = block_unknown_of(b, param_of[i], 4 * (e - 1) + P_K1);
            if (u < 0) {
                continue;
            }
            for (j = e - 2; j <= e - 1; j++) { /* the equations that contain element e */
                int v;
                if (j == i || j < 0 || j >= n) {
                    continue;
                }
                v = block_unknown_of(&m->blocks[j], param_of[j], 4 * (e - 1) + P_K1);
                if (v >= 0) {
                    b->rules[b->n_rules].unknown = u;
                    b->rules[b->n_rules].other = j;
                    b->rules[b->n_rules++].other_unknown = v;
                }
            }
        }
    }
    for (i = 0; i < m->n_params; i++) {
        const char *name = est->cfg.model == DUFFID_DUFFING1 ? NAMES1[i] : NAMES2[i];
        strcpy(m->publics[i].name, name);
        m->publics[i].canonical = public_to_canon(est->cfg.model, i);
        m->publics[i].reciprocal = 0;
    }
    /* linearisation: M = diag(m), K = the chain matrix of the linear stiffnesses */
    m->linear = 1;
    for (i = 0; i < n; i++) {
        duffid_linear *l = &m->mass[m->n_mass++];
        l->row = l->col = i;
        l->param = 4 * i + P_M;
        l->coef = 1.0;
    }
    for (i = 0; i < n; i++) {
        duffid_linear *l = &m->stiffness[m->n_stiffness++];
        l->row = l->col = i;
        l->param = 4 * i + P_K1;
        l->coef = 1.0;
    }
    for (i = 0; i + 1 < n; i++) {
        duffid_linear *l = &m->stiffness[m->n_stiffness++];
        l->row = l->col = i;
        l->param = 4 * (i + 1) + P_K1;
        l->coef = 1.0;
    }
    for (i = 0; i + 1 < n; i++) {
        duffid_linear *l = &m->stiffness[m->n_stiffness++];
        l->row = i;
        l->col = i + 1;
        l->param = 4 * (i + 1) + P_K1;
        l->coef = -1.0;
        l = &m->stiffness[m->n_stiffness++];
        l->row = i + 1;
        l->col = i;
        l->param = 4 * (i + 1) + P_K1;
        l->coef = -1.0;
    }
}

/* est->model from the configuration; the counts the engine reads in est */
static void build_structure(duffid_estimator *est)
{
    memset(&est->model, 0, sizeof est->model);
    memset(est->ch, 0, sizeof est->ch);
    if (est->cfg.model == DUFFID_GENERATED) {
        est->model = *generated_model();
    } else {
        describe_builtin(est);
    }
    est->n_dof = est->model.n_dof;
    est->n_forces = est->model.n_forces;
    est->n_params = est->model.n_params;
    est->n_ch = est->model.n_channels;
    est->n_eq = est->model.n_blocks;
}
static uint64_t factorial_u64(int n)
{
    uint64_t r = 1;
    int i;
    for (i = 2; i <= n; i++) {
        r *= (uint64_t)i;
    }
    return r;
}

static uint64_t comb_u64(int n, int k)
{
    uint64_t r = 1;
    int i;
    for (i = 1; i <= k; i++) {
        r = r * (uint64_t)(n - k + i) / (uint64_t)i;
    }
    return r;
}

/* regressors.row_exponents + KernelBank.build (+ __post_init__) */
static void build_kernel_bank(duffid_estimator *est)
{
    int r, m, d, k, n_rows = est->n_rows;
    est->degree = 0;
    for (r = 0; r < n_rows; r++) {
        int a, b;
        if (est->cfg.rows == DUFFID_ROWS_PAPER) {
            a = 1 + r;
            b = 2;
        } else if (est->cfg.rows == DUFFID_ROWS_INTEGRALS) {
            a = 3 + r;
            b = 2;
        } else {
            a = 2 + r;
            b = 1 + n_rows - r;
        }
        est->row_a[r] = a;
        est->row_b[r] = b;
        if (a + b > est->degree) {
            est->degree = a + b;
        }
    }
    memset(est->coef, 0, sizeof est->coef);
    memset(est->expo, 0, sizeof est->expo);
    for (r = 0; r < n_rows; r++) {
        int a = est->row_a[r], b = est->row_b[r];
        uint64_t prod = 1;
        for (m = 0; m <= b; m++) {
            int power = a + m;
            for (d = 0; d <= MAX_ORDER; d++) {
                double num;
                int idx;
                if (power - d < 0) {
                    continue;
                }
                /* comb(b, m) * (-1)**m * falling / factorial(a): exact integers, one rounding */
                num = (double)(comb_u64(b, m) * (factorial_u64(power) / factorial_u64(power - d)));
                if (m % 2) {
                    num = -num;
                }
                idx = (r * N_ORD + d) * MAX_POW + (power - d);
                est->coef[idx] += num / (double)factorial_u64(a);
                est->expo[idx] = (double)(b - m);
            }
        }
        est->raw_b[r] = (a == 1 && est->model.max_order >= 2) ? b : -1;
        for (k = b + 1; k <= a + b + 1; k++) {
            prod *= (uint64_t)k; /* (a+b+1)! / b! */
        }
        est->norm[r] = (double)prod;
        est->norm_power[r] = (double)(a + b + 1);
    }
    /* SlidingMoments._shift: B[k, r] = C(k, r) (1/N)^(k-r) */
    for (k = 0; k <= est->degree; k++) {
        for (r = 0; r <= est->degree; r++) {
            est->shift[k * MAX_POW + r] =
                r <= k ? (double)comb_u64(k, r) * pow(1.0 / (double)est->capacity, (double)(k - r)) : 0.0;
        }
    }
    est->t_ref = (double)est->capacity * est->cfg.dt;
    for (d = 0; d <= MAX_ORDER; d++) {
        est->d_scale[d] = pow(est->t_ref, -(double)d);
    }
}

static void integrators_reset(integrators_t *it)
{
    size_t n = (size_t)(it->depth + 1) * (size_t)it->n_in;
    memset(it->y, 0, n * sizeof(double));
    memset(it->p1, 0, n * sizeof(double));
    memset(it->p2, 0, n * sizeof(double));
    it->count = 0;
}

static double *integrators_setup(integrators_t *it, int n_in, int depth, double *mem)
{
    size_t n = (size_t)(depth + 1) * (size_t)n_in;
    it->n_in = n_in;
    it->depth = depth;
    it->y = mem;
    it->p1 = mem + n;
    it->p2 = mem + 2 * n;
    return mem + 3 * n;
}

/* ------------------------------------------------------------------ lifecycle */
int duffid_init(duffid_estimator **out, void *memory, size_t size, const duffid_config *cfg, char *msg,
                size_t msg_size)
{
    duffid_estimator *est;
    uintptr_t base;
    double *dyn;
    int rc, i;
    if (out == NULL || memory == NULL) {
        set_msg(msg, msg_size, "NULL argument");
        return DUFFID_ERR_ARGUMENT;
    }
    *out = NULL;
    rc = duffid_check_config(cfg, msg, msg_size);
    if (rc != DUFFID_OK) {
        return rc;
    }
    if (size < duffid_memory_size(cfg)) {
        set_msg(msg, msg_size, "memory block of %lu bytes, need %lu", (unsigned long)size,
                (unsigned long)duffid_memory_size(cfg));
        return DUFFID_ERR_ARGUMENT;
    }
    base = ((uintptr_t)memory + (ALIGNMENT - 1u)) & ~(uintptr_t)(ALIGNMENT - 1u);
    est = (duffid_estimator *)base;
    memset(est, 0, sizeof *est);
    est->cfg = *cfg;
    build_structure(est);
    for (i = 0; i < est->n_params; i++) {
        est->nominal[est->model.publics[i].canonical] = fabs(cfg->nominal[i]);
    }
    if (est->n_ch != channel_count(cfg)) { /* cannot happen: the layout below relies on it */
        set_msg(msg, msg_size, "internal error: %d channels, expected %d", est->n_ch, channel_count(cfg));
        return DUFFID_ERR_CONFIG;
    }
    dyn = (double *)(base + ALIGN_UP(sizeof(struct duffid_estimator)));
    est->chan_work = dyn;
    dyn += est->model.channel_work;
    if (cfg->method == DUFFID_ROBUST) {
        est->capacity = capacity_of(cfg);
        est->auto_window = !(cfg->window > 0.0);
        est->n_rows = effective_rows(cfg);
        est->lam = cfg->forgetting > 0.0 ? exp(-cfg->dt / cfg->forgetting) : 1.0;
        est->sqrt_lam = sqrt(est->lam);
        est->ring = dyn;
        build_kernel_bank(est);
        {
            double s = round_half_even(cfg->settle / cfg->dt);
            est->settle_count = s < 1.0 ? 1 : (s > 4e18 ? (int64_t)4e18 : (int64_t)s);
        }
    } else {
        for (i = 0; i < est->n_eq; i++) {
            equation_t *eq = &est->eq[i];
            const int n_unk = est->model.blocks[i].n_unknowns;
            dyn = integrators_setup(&eq->reg, 3 * est->n_ch, n_unk + 1, dyn);
            dyn = integrators_setup(&eq->det, n_unk + 1, 2, dyn);
        }
    }
    duffid_reset(est);
    *out = est;
    return DUFFID_OK;
}

duffid_estimator *duffid_relocate(void *memory)
{
    duffid_estimator *est;
    uintptr_t base;
    double *dyn;
    int i;
    if (memory == NULL) {
        return NULL;
    }
    base = ((uintptr_t)memory + (ALIGNMENT - 1u)) & ~(uintptr_t)(ALIGNMENT - 1u);
    est = (duffid_estimator *)base;
    dyn = (double *)(base + ALIGN_UP(sizeof(struct duffid_estimator)));
    est->chan_work = dyn;
    dyn += est->model.channel_work;
    if (est->cfg.method == DUFFID_ROBUST) {
        est->ring = dyn;
    } else {
        for (i = 0; i < est->n_eq; i++) {
            equation_t *eq = &est->eq[i];
            const int n_unk = est->model.blocks[i].n_unknowns;
            dyn = integrators_setup(&eq->reg, 3 * est->n_ch, n_unk + 1, dyn);
            dyn = integrators_setup(&eq->det, n_unk + 1, 2, dyn);
        }
    }
    est->block = NULL;
    return est;
}

/* The checks of duffid_check_state: a structural field equal to a fresh estimator's, a
 * count within bounds (each failure names the field). */
#define STATE_SAME(field) \
    if (memcmp(&est->field, &fresh->field, sizeof est->field) != 0) { bad = #field; goto done; }
#define STATE_RANGE(value, lo, hi) \
    if (!((value) >= (lo) && (value) <= (hi))) { bad = #value; goto done; }

int duffid_check_state(const void *memory, size_t size, char *msg, size_t msg_size)
{
    const duffid_estimator *est = (const duffid_estimator *)memory;
    duffid_estimator *fresh = NULL;
    duffid_config cfg;
    const char *bad = NULL;
    void *scratch;
    int64_t n, limit = (int64_t)1 << 52; /* sample indices far beyond any record, no overflow */
    int i, rc;
    if (memory == NULL || ((uintptr_t)memory & (ALIGNMENT - 1u)) != 0 || size < sizeof *est) {
        set_msg(msg, msg_size, "estimator memory of %lu bytes is not an estimator", (unsigned long)size);
        return DUFFID_ERR_ARGUMENT;
    }
    memcpy(&cfg, &est->cfg, sizeof cfg);
    rc = duffid_check_config(&cfg, msg, msg_size);
    if (rc != DUFFID_OK) {
        return rc;
    }
    if (size < duffid_memory_size(&cfg) - ALIGNMENT) {
        set_msg(msg, msg_size, "estimator memory of %lu bytes, its configuration needs %lu", (unsigned long)size,
                (unsigned long)(duffid_memory_size(&cfg) - ALIGNMENT));
        return DUFFID_ERR_ARGUMENT;
    }
    scratch = malloc(duffid_memory_size(&cfg));
    if (scratch == NULL || duffid_init(&fresh, scratch, duffid_memory_size(&cfg), &cfg, msg, msg_size) != DUFFID_OK) {
        free(scratch);
        set_msg(msg, msg_size, "out of memory for the check of an estimator state");
        return DUFFID_ERR_ARGUMENT;
    }
    /* structure: everything duffid_init derives from the configuration */
    STATE_SAME(n_dof) STATE_SAME(n_forces) STATE_SAME(n_params) STATE_SAME(n_ch) STATE_SAME(n_eq)
    STATE_SAME(ch) STATE_SAME(model) STATE_SAME(nominal) STATE_SAME(settle_count)
    STATE_SAME(capacity) STATE_SAME(auto_window) STATE_SAME(n_rows) STATE_SAME(degree) STATE_SAME(lam)
    STATE_SAME(sqrt_lam) STATE_SAME(row_a) STATE_SAME(row_b) STATE_SAME(raw_b) STATE_SAME(coef)
    STATE_SAME(expo) STATE_SAME(norm) STATE_SAME(norm_power) STATE_SAME(d_scale) STATE_SAME(t_ref)
    STATE_SAME(shift)
    for (i = 0; i < est->n_eq; i++) {
        STATE_SAME(eq[i].reg.n_in)
        STATE_SAME(eq[i].reg.depth) STATE_SAME(eq[i].det.n_in) STATE_SAME(eq[i].det.depth)
        STATE_RANGE(est->eq[i].reg.count, 0, 2)
        STATE_RANGE(est->eq[i].det.count, 0, 2)
    }
    /* counts, indices and buffer positions */
    n = est->n;
    STATE_RANGE(n, -1, limit)
    STATE_RANGE(est->window_fixed, 0, 1)
    STATE_RANGE(est->has_last_x, 0, 1)
    STATE_RANGE(est->pending, 0, 1)
    STATE_RANGE(est->received, n + est->pending, n + est->pending) /* a held sample is not processed yet */
    STATE_RANGE(est->g_count, 0, est->received + 1)
    STATE_RANGE(est->p_k, 0, limit)
    if (est->pending) {
        STATE_RANGE(est->p_k, est->received, est->received)
    }
    STATE_RANGE(est->outliers, 0, est->received + 1)
    STATE_RANGE(est->outlier_column, -1, est->n_dof - 1)
    for (i = 0; i < DUFFID_MAX_DOF; i++) {
        STATE_RANGE(est->p_suspect[i], 0, 1)
    }
    for (i = 0; i < DUFFID_MAX_PARAMS; i++) {
        STATE_RANGE(est->status[i], DUFFID_STATUS_UNCERTAIN, DUFFID_STATUS_LOST)
        STATE_RANGE(est->last.status[i], DUFFID_STATUS_UNCERTAIN, DUFFID_STATUS_LOST)
        STATE_RANGE(est->steady[i], 0, limit)
        STATE_RANGE(est->anchored[i], -1, limit)
        STATE_RANGE(est->settled[i], 0, limit)
        STATE_RANGE(est->unsettled[i], 0, limit)
    }
    STATE_RANGE(est->last.n_parameters, 0, DUFFID_MAX_PARAMS)
    STATE_RANGE(est->last.identified, 0, 1)
    STATE_RANGE(est->last.outliers, 0, est->received + 1)
    STATE_RANGE(est->last.outlier_column, -1, est->n_dof - 1)
    if (cfg.method == DUFFID_ROBUST) {
        const long N = est->capacity;
        STATE_RANGE(est->target, 1, N)
        STATE_RANGE(est->start, 0, n + 1)
        STATE_RANGE(n - est->start, -1, (int64_t)N)
        STATE_RANGE(est->shadow_from, est->start, n + 1)
        STATE_RANGE(est->poly_L, -1, N)
        STATE_RANGE(est->corr_L, -1, N)
        STATE_RANGE(est->corr_n, 0, MAX_CORR)
        for (i = 0; i < est->corr_n; i++) {
            STATE_RANGE(est->corr_off[i], 0, est->corr_L)
        }
    }
done:
    free(scratch);
    if (bad != NULL) {
        set_msg(msg, msg_size, "estimator field %s out of range", bad);
        return DUFFID_ERR_ARGUMENT;
    }
    return DUFFID_OK;
}
#undef STATE_SAME
#undef STATE_RANGE

int duffid_create(duffid_estimator **out, const duffid_config *cfg, char *msg, size_t msg_size)
{
    size_t size;
    void *mem;
    int rc;
    if (out == NULL) {
        set_msg(msg, msg_size, "NULL argument");
        return DUFFID_ERR_ARGUMENT;
    }
    *out = NULL;
    rc = duffid_check_config(cfg, msg, msg_size);
    if (rc != DUFFID_OK) {
        return rc;
    }
    size = duffid_memory_size(cfg);
    mem = malloc(size);
    if (mem == NULL) {
        set_msg(msg, msg_size, "out of memory (%lu bytes)", (unsigned long)size);
        return DUFFID_ERR_ARGUMENT;
    }
    rc = duffid_init(out, mem, size, cfg, msg, msg_size);
    if (rc != DUFFID_OK) {
        free(mem);
        return rc;
    }
    (*out)->block = mem;
    return DUFFID_OK;
}

void duffid_destroy(duffid_estimator *est)
{
    if (est != NULL && est->block != NULL) {
        free(est->block);
    }
}

void duffid_reset(duffid_estimator *est)
{
    int i, u;
    if (est == NULL) {
        return;
    }
    est->n = -1;
    est->window_fixed = 0;
    est->has_last_x = 0;
    memset(est->last_x, 0, sizeof est->last_x);
    memset(est->sgn, 0, sizeof est->sgn);
    est->received = -1;
    memset(est->gh, 0, sizeof est->gh);
    est->g_count = 0;
    for (i = 0; i < DUFFID_MAX_DOF; i++) {
        est->g_mean[i] = 0.0;
        est->g_lo[i] = DINF;
        est->g_hi[i] = -DINF;
        est->g_step[i] = DINF;
    }
    est->pending = 0;
    est->outliers = 0;
    est->outlier_t = DNAN;
    est->outlier_value = DNAN;
    est->outlier_replaced_by = DNAN;
    est->outlier_column = -1;
    memset(&est->last, 0, sizeof est->last);
    for (i = 0; i < DUFFID_MAX_PARAMS; i++) {
        est->steady[i] = 0;
        est->anchor[i] = DNAN;
        est->anchored[i] = 0;
        est->settled[i] = 0;
        est->unsettled[i] = 0;
        est->status[i] = DUFFID_STATUS_UNCERTAIN;
        est->held[i] = DNAN;
    }
    if (est->cfg.method == DUFFID_ROBUST) {
        memset(est->ring, 0, (size_t)(est->capacity + 2) * (size_t)est->n_ch * sizeof(double));
        memset(est->main_acc, 0, sizeof est->main_acc);
        memset(est->shadow, 0, sizeof est->shadow);
        est->start = 0;
        est->shadow_from = 0;
        est->target = est->capacity;
        est->poly_L = -1;
        est->corr_L = -1;
        for (i = 0; i < est->n_eq; i++) {
            memset(est->eq[i].R, 0, sizeof est->eq[i].R);
            est->eq[i].rows = 0.0;
        }
    } else {
        for (i = 0; i < est->n_eq; i++) {
            integrators_reset(&est->eq[i].reg);
            integrators_reset(&est->eq[i].det);
        }
    }
    for (i = 0; i < est->n_eq; i++) {
        for (u = 0; u < MAX_UNK; u++) {
            est->eq[i].theta[u] = DNAN;
            est->eq[i].rse[u] = DINF;
            est->eq[i].share[u] = DNAN;
        }
        est->eq[i].rhs_share = DNAN;
        est->eq[i].cond = DINF;
    }
}

/* ------------------------------------------------------------------ channels */
static void evaluate_channels(duffid_estimator *est, const double *x, const double *f)
{
    int i;
    if (est->model.uses_sign) { /* _Channels: sgn(dx) where |dx| > deadband, else the previous sign */
        for (i = 0; i < est->n_dof && est->has_last_x; i++) {
            double dx = x[i] - est->last_x[i];
            if (fabs(dx) > est->cfg.deadband) {
                est->sgn[i] = sign_of(dx);
            }
        }
        for (i = 0; i < est->n_dof; i++) {
            est->last_x[i] = x[i];
        }
        est->has_last_x = 1;
    }
    if (est->cfg.model == DUFFID_GENERATED) {
#ifdef DUFFID_GENERATED_MODEL
        duffid_generated_channels(x, f, (double)est->n * est->cfg.dt, est->sgn, est->g, est->chan_work);
#endif
        return;
    }
    for (i = 0; i < est->n_ch; i++) {
        const channel_t *c = &est->ch[i];
        double v;
        switch (c->kind) {
        case CH_X:
            v = x[c->index];
            break;
        case CH_DEFL:
            v = x[c->index] - (c->index > 0 ? x[c->index - 1] : 0.0);
            if (c->power != 1) {
                v = pow(v, (double)c->power);
            }
            break;
        case CH_FORCE:
            v = f[c->index];
            break;
        default:
            v = 1.0;
            break;
        }
        est->g[i] = v;
    }
}

/* ------------------------------------------------------------------ moments */
/* regressors.gregory_corrections + SlidingMoments._corrections, cached for one L */
static void corrections(duffid_estimator *est, long L)
{
    static const double gregory[3] = {-5.0 / 8.0, 1.0 / 6.0, -1.0 / 24.0};
    static const int nc_num[5][6] = {
        {1, 1, 0, 0, 0, 0}, {1, 4, 1, 0, 0, 0}, {3, 9, 9, 3, 0, 0},
        {14, 64, 24, 64, 14, 0}, {95, 375, 250, 250, 375, 95}};
    static const int nc_den[5] = {2, 3, 8, 45, 288};
    double delta[MAX_CORR];
    int m, k;
    if (est->corr_L == L) {
        return;
    }
    if (L < 1) {
        est->corr_n = 1;
        est->corr_off[0] = 0;
        delta[0] = -1.0;
    } else if (L <= 5) {
        est->corr_n = (int)L + 1;
        for (m = 0; m <= L; m++) {
            est->corr_off[m] = m;
            delta[m] = (double)nc_num[L - 1][m] / (double)nc_den[L - 1] - 1.0;
        }
    } else {
        long off[6];
        off[0] = 0;
        off[1] = 1;
        off[2] = 2;
        off[3] = L;
        off[4] = L - 1;
        off[5] = L - 2;
        est->corr_n = 6;
        for (m = 0; m < 6; m++) {
            est->corr_off[m] = off[m];
            delta[m] = gregory[m % 3];
        }
    }
    for (m = 0; m < est->corr_n; m++) {
        double s = (double)est->corr_off[m] / (double)est->capacity;
        for (k = 0; k <= est->degree; k++) {
            est->corr_w[m * MAX_POW + k] = pow(s, (double)k) * delta[m];
        }
    }
    est->corr_L = L;
}

static void shift_accumulator(const duffid_estimator *est, double *acc)
{
    int k, r, c, D = est->degree, n_ch = est->n_ch;
    for (k = D; k >= 0; k--) { /* row k uses rows 0..k of the old values: go downwards */
        for (c = 0; c < n_ch; c++) {
            double sum = 0.0;
            for (r = 0; r <= k; r++) {
                sum += est->shift[k * MAX_POW + r] * acc[r * MAX_CH + c];
            }
            acc[k * MAX_CH + c] = sum;
        }
    }
}

/* SlidingMoments.push: the moments of the window (into est->mom) and its length L */
static long moments_push(duffid_estimator *est, long window)
{
    const long N = est->capacity;
    const int n_ch = est->n_ch, D = est->degree;
    const int64_t ring_len = (int64_t)N + 2;
    int64_t n, j, new_start;
    long w, L;
    int k, c, m;
    double *slot;

    n = est->n; /* SlidingMoments.n == OnlineIdentifier.n */
    slot = est->ring + (size_t)(n % ring_len) * (size_t)n_ch;
    for (c = 0; c < n_ch; c++) {
        slot[c] = est->g[c];
    }
    shift_accumulator(est, est->main_acc);
    shift_accumulator(est, est->shadow);
    for (c = 0; c < n_ch; c++) {
        est->main_acc[c] += est->g[c];
        est->shadow[c] += est->g[c];
    }
    w = window < N ? window : N;
    new_start = n - w > est->start ? n - w : est->start;
    for (j = est->start; j < new_start; j++) { /* samples leaving the window */
        double s = (double)(n - j) / (double)N;
        const double *old = est->ring + (size_t)(j % ring_len) * (size_t)n_ch;
        for (k = 0; k <= D; k++) {
            double p = pow(s, (double)k);
            for (c = 0; c < n_ch; c++) {
                est->main_acc[k * MAX_CH + c] -= p * old[c];
            }
        }
    }
    est->start = new_start;
    if (est->shadow_from < est->start) { /* the shadow holds samples outside the window: rebuild */
        int64_t i;
        est->shadow_from = est->start;
        for (k = 0; k <= D; k++) {
            for (c = 0; c < n_ch; c++) {
                double sum = 0.0;
                for (i = 0; i <= n - est->start; i++) {
                    sum += pow((double)i / (double)N, (double)k) *
                           est->ring[(size_t)((n - i) % ring_len) * (size_t)n_ch + (size_t)c];
                }
                est->shadow[k * MAX_CH + c] = sum;
            }
        }
    }
    if (est->shadow_from == est->start && n - est->start >= 1) {
        /* the shadow holds exactly the window: it becomes the main accumulator */
        memcpy(est->main_acc, est->shadow, sizeof est->main_acc);
        memset(est->shadow, 0, sizeof est->shadow);
        est->shadow_from = n + 1;
    }
    L = (long)(n - est->start);
    corrections(est, L);
    for (k = 0; k <= D; k++) {
        for (c = 0; c < n_ch; c++) {
            double corr = 0.0;
            for (m = 0; m < est->corr_n; m++) {
                corr += est->corr_w[m * MAX_POW + k] *
                        est->ring[(size_t)((n - est->corr_off[m]) % ring_len) * (size_t)n_ch + (size_t)c];
            }
            est->mom[k * MAX_CH + c] = (est->main_acc[k * MAX_CH + c] + corr) / (double)N;
        }
    }
    return L;
}

/* ------------------------------------------------------------------ kernel entries */
/* KernelBank.entries: E[r, d, channel] for a window of L samples */
static void kernel_entries(duffid_estimator *est, long L)
{
    const int n_rows = est->n_rows, n_ch = est->n_ch, D = est->degree;
    const double tau = (double)L / (double)est->capacity;
    int r, d, k, c;
    if (est->poly_L != L) {
        for (r = 0; r < n_rows; r++) {
            for (d = 0; d <= MAX_ORDER; d++) {
                for (k = 0; k <= D; k++) {
                    int idx = (r * N_ORD + d) * MAX_POW + k;
                    est->poly[idx] = est->coef[idx] != 0.0 ? est->coef[idx] * pow(tau, est->expo[idx]) : 0.0;
                }
            }
            est->row_scale[r] = est->norm[r] / pow(tau, est->norm_power[r]);
            est->raw_pow[r] = est->raw_b[r] >= 0 ? pow(tau, (double)est->raw_b[r]) : 0.0;
        }
        est->poly_L = L;
    }
    for (r = 0; r < n_rows; r++) {
        for (d = 0; d <= MAX_ORDER; d++) {
            const double *poly = est->poly + (r * N_ORD + d) * MAX_POW;
            double scale = est->row_scale[r] * est->d_scale[d];
            for (c = 0; c < n_ch; c++) {
                double sum = 0.0;
                for (k = 0; k <= D; k++) {
                    if (poly[k] != 0.0) {
                        sum += poly[k] * est->mom[k * MAX_CH + c];
                    }
                }
                if (d == 2 && est->raw_b[r] >= 0) {
                    sum += est->raw_pow[r] * est->g[c];
                }
                est->E[(r * N_ORD + d) * MAX_CH + c] = sum * scale;
            }
        }
    }
}

/* rows of [A D] of one block (identification._Assembly) into B (parts * n_rows x (n_unk + 1)):
 * the rows of each equation of the block, one equation after the other */
static void assemble(const duffid_block *b, const double *E, int n_rows, double *B)
{
    const int p = b->n_unknowns + 1;
    int r, k;
    memset(B, 0, (size_t)(b->n_parts * n_rows * p) * sizeof(double));
    for (k = 0; k < b->n_terms; k++) {
        const duffid_term *t = &b->terms[k];
        const int col = t->unknown >= 0 ? t->unknown : b->n_unknowns;
        for (r = 0; r < n_rows; r++) {
            B[(t->part * n_rows + r) * p + col] += t->coef * E[(r * N_ORD + t->order) * MAX_CH + t->channel];
        }
    }
}

/* ------------------------------------------------------------------ least squares */
/* identification.solve_factor on the p x p factor Raug (p = n + 1) */
static void solve_factor(duffid_estimator *est, equation_t *eq, int n, const double *Raug, double rows,
                         double overlap)
{
    const int p = n + 1;
    double cond, dof, s2;
    int i, j, k;
    for (j = 0; j < n; j++) { /* column norms: np.linalg.norm(R, axis=0), rows in order */
        double sum = 0.0;
        for (i = 0; i < n; i++) {
            sum += Raug[i * p + j] * Raug[i * p + j];
        }
        est->scale[j] = sqrt(sum);
    }
    for (j = 0; j < n; j++) {
        if (!(est->scale[j] > 0.0)) {
            goto singular;
        }
    }
    for (i = 0; i < n; i++) {
        for (j = 0; j < n; j++) {
            est->U[i * n + j] = Raug[i * p + j] / est->scale[j];
        }
    }
    duffid_la_jacobi_svd(n, est->U, est->sv, est->V);
    cond = est->sv[n - 1] > 0.0 ? est->sv[0] / est->sv[n - 1] : DINF;
    if (!is_finite(cond) || cond > 1e14) {
        goto singular;
    }
    /* Rinv = (V / sv) @ U.T */
    for (i = 0; i < n; i++) {
        for (j = 0; j < n; j++) {
            est->tmp[i * n + j] = est->V[i * n + j] / est->sv[j];
        }
    }
    for (i = 0; i < n; i++) {
        for (k = 0; k < n; k++) {
            double sum = 0.0;
            for (j = 0; j < n; j++) {
                sum += est->tmp[i * n + j] * est->U[k * n + j];
            }
            est->Rinv[i * n + k] = sum;
        }
    }
    for (i = 0; i < n; i++) {
        double sum = 0.0;
        for (k = 0; k < n; k++) {
            sum += est->Rinv[i * n + k] * Raug[k * p + n];
        }
        eq->theta[i] = sum / est->scale[i];
    }
    eq->cond = cond;
    { /* shares of the terms |theta_i| ||A_i|| and of ||D|| in the force balance */
        double sq[MAX_AUG], rhs, balance;
        for (k = 0; k < p; k++) {
            sq[k] = Raug[k * p + n] * Raug[k * p + n];
        }
        rhs = sqrt(duffid_la_pairwise_sum(sq, p, 1));
        for (i = 0; i < n; i++) {
            double term = fabs(eq->theta[i]) * est->scale[i];
            sq[i] = term * term;
        }
        sq[n] = rhs * rhs;
        balance = sqrt(duffid_la_pairwise_sum(sq, p, 1));
        for (i = 0; i < n; i++) {
            eq->share[i] = balance > 0.0 ? fabs(eq->theta[i]) * est->scale[i] / balance : DNAN;
        }
        eq->rhs_share = balance > 0.0 ? rhs / balance : DNAN;
    }
    dof = rows - (double)n;
    if (dof <= 0.0) {
        for (i = 0; i < n; i++) {
            eq->rse[i] = DINF;
        }
        return;
    }
    s2 = pow(Raug[n * p + n], 2.0) / dof * overlap;
    for (i = 0; i < n; i++) {
        double sq[MAX_UNK], std;
        for (k = 0; k < n; k++) {
            sq[k] = est->Rinv[i * n + k] * est->Rinv[i * n + k];
        }
        std = sqrt(s2 * duffid_la_pairwise_sum(sq, n, 1)) / est->scale[i];
        eq->rse[i] = eq->theta[i] != 0.0 ? std / fabs(eq->theta[i]) : DINF;
    }
    return;
singular:
    for (i = 0; i < n; i++) {
        eq->theta[i] = DNAN;
        eq->rse[i] = DINF;
        eq->share[i] = DNAN;
    }
    eq->rhs_share = DNAN;
    eq->cond = DINF;
}

/* OnlineIdentifier._robust_step + _robust_solve; returns the window length L */
static long robust_step(duffid_estimator *est)
{
    long L = moments_push(est, est->target);
    int full, e, i;
    if (L == 0) {
        return 0;
    }
    kernel_entries(est, L);
    full = L >= est->target;
    for (e = 0; e < est->n_eq; e++) {
        equation_t *eq = &est->eq[e];
        const duffid_block *b = &est->model.blocks[e];
        const int n = b->n_unknowns, p = n + 1, m = b->n_parts * est->n_rows;
        assemble(b, est->E, est->n_rows, est->B);
        if (full) {
            duffid_la_qr_accumulate(eq->R, p, est->sqrt_lam, est->B, m);
            eq->rows = est->lam * eq->rows + (double)m;
            solve_factor(est, eq, n, eq->R, eq->rows, (double)L);
        } else {
            for (i = 0; i < p * p; i++) {
                est->W[i] = 0.0;
            }
            duffid_la_qr_accumulate(est->W, p, 1.0, est->B, m);
            solve_factor(est, eq, n, est->W, (double)m, 1.0);
        }
    }
    return L;
}

/* ------------------------------------------------------------------ paper method */
/* identification.Integrators.push: returns y (levels 0..depth, n_in each) */
static const double *integrators_push(integrators_t *it, const double *u, double h, int adams)
{
    const size_t n = (size_t)(it->depth + 1) * (size_t)it->n_in;
    const int m = it->n_in;
    int k, i;
    memcpy(it->p2, it->p1, n * sizeof(double));
    memcpy(it->p1, it->y, n * sizeof(double));
    for (i = 0; i < m; i++) {
        it->y[i] = u[i];
    }
    for (k = 1; k <= it->depth; k++) {
        double *y = it->y + k * m;
        const double *y_lo = it->y + (k - 1) * m;
        const double *p1 = it->p1 + k * m, *p1_lo = it->p1 + (k - 1) * m, *p2_lo = it->p2 + (k - 1) * m;
        for (i = 0; i < m; i++) {
            if (it->count == 0) {
                y[i] = 0.0;
            } else if (it->count == 1 || !adams) {
                y[i] = p1[i] + 0.5 * h * (y_lo[i] + p1_lo[i]);
            } else {
                y[i] = p1[i] + h / 12.0 * (5.0 * y_lo[i] + 8.0 * p1_lo[i] - p2_lo[i]);
            }
        }
    }
    if (it->count < 2) {
        it->count++;
    }
    return it->y;
}

/* identification.equilibrated_condition */
static double equilibrated_condition(duffid_estimator *est, const double *A, int n)
{
    double col[MAX_UNK], row[MAX_UNK], sq[MAX_UNK];
    int i, j;
    for (j = 0; j < n; j++) {
        double sum = 0.0;
        for (i = 0; i < n; i++) {
            sum += A[i * n + j] * A[i * n + j];
        }
        col[j] = sqrt(sum);
    }
    for (i = 0; i < n; i++) {
        for (j = 0; j < n; j++) {
            sq[j] = A[i * n + j] * A[i * n + j];
        }
        row[i] = sqrt(duffid_la_pairwise_sum(sq, n, 1));
    }
    for (i = 0; i < n; i++) {
        if (!(col[i] > 0.0 && row[i] > 0.0)) {
            return DINF;
        }
    }
    for (i = 0; i < n; i++) {
        double rn;
        for (j = 0; j < n; j++) {
            est->Aw[i * n + j] = A[i * n + j] / col[j];
            sq[j] = est->Aw[i * n + j] * est->Aw[i * n + j];
        }
        rn = sqrt(duffid_la_pairwise_sum(sq, n, 1));
        for (j = 0; j < n; j++) {
            est->Aw[i * n + j] /= rn;
        }
    }
    duffid_la_jacobi_svd(n, est->Aw, est->sv, est->V);
    if (est->sv[0] != est->sv[0]) {
        return DNAN;
    }
    if (!(est->sv[n - 1] > 0.0)) {
        return DINF;
    }
    return est->sv[0] / est->sv[n - 1];
}

/* OnlineIdentifier._paper_step; returns the window length (samples since the first) */
static long paper_step(duffid_estimator *est)
{
    const double dt = est->cfg.dt;
    const double tau = (double)est->n * dt;
    const double tau2 = pow(tau, 2.0);
    const int n_ch = est->n_ch, adams = est->cfg.quadrature == DUFFID_ADAMS3;
    const int fixed_sign = est->cfg.sign_in_numerator;
    const double weight = exp(-est->cfg.gamma * tau);
    int e, c, p, u, i;
    for (c = 0; c < n_ch; c++) {
        est->u_in[c] = est->g[c];
        est->u_in[n_ch + c] = tau * est->g[c];
        est->u_in[2 * n_ch + c] = tau2 * est->g[c];
    }
    for (e = 0; e < est->n_eq; e++) {
        equation_t *eq = &est->eq[e];
        const duffid_block *b = &est->model.blocks[e];
        const int n = b->n_unknowns, m = 3 * n_ch;
        const double *y = integrators_push(&eq->reg, est->u_in, dt, adams);
        double delta, deltas[MAX_UNK], in[MAX_UNK + 1];
        const double *z;
        /* E[p, order, channel] of eqs. (16)-(17); Y[k, j, c] = y[k * m + j * n_ch + c] */
        for (p = 0; p < n; p++) {
            for (c = 0; c < n_ch; c++) {
                double *Ep = est->E + (size_t)p * N_ORD * MAX_CH;
                Ep[2 * MAX_CH + c] = y[p * m + 2 * n_ch + c] - 4.0 * y[(p + 1) * m + n_ch + c] +
                                     2.0 * y[(p + 2) * m + c];
                Ep[1 * MAX_CH + c] = y[(p + 1) * m + 2 * n_ch + c] - 2.0 * y[(p + 2) * m + n_ch + c];
                Ep[c] = y[(p + 2) * m + 2 * n_ch + c];
            }
        }
        assemble(b, est->E, n, est->B); /* one part: the paper method refuses joint blocks */
        for (p = 0; p < n; p++) {
            for (u = 0; u < n; u++) {
                est->Ap[p * n + u] = est->B[p * (n + 1) + u];
            }
            est->Dp[p] = est->B[p * (n + 1) + n];
        }
        memcpy(est->tmp, est->Ap, (size_t)(n * n) * sizeof(double));
        delta = duffid_la_det(n, est->tmp);
        for (i = 0; i < n; i++) {
            memcpy(est->tmp, est->Ap, (size_t)(n * n) * sizeof(double));
            for (p = 0; p < n; p++) {
                est->tmp[p * n + i] = est->Dp[p];
            }
            deltas[i] = duffid_la_det(n, est->tmp);
        }
        for (i = 0; i < n; i++) {
            double num = fixed_sign ? deltas[i] * sign_of(delta) : fabs(deltas[i]);
            in[i] = weight * num;
        }
        in[n] = weight * fabs(delta);
        z = integrators_push(&eq->det, in, dt, adams) + 2 * (n + 1);
        if (z[n] > 0.0) { /* eq. (19): filtered |Delta_i| / |Delta|, signs of the current sample */
            for (i = 0; i < n; i++) {
                double ratio = z[i] / z[n];
                eq->theta[i] = fixed_sign ? ratio : sign_of(deltas[i]) * sign_of(delta) * ratio;
            }
        } else {
            for (i = 0; i < n; i++) {
                eq->theta[i] = DNAN;
            }
        }
        eq->cond = equilibrated_condition(est, est->Ap, n);
    }
    return (long)est->n;
}

/* ------------------------------------------------------------------ combination */
/* Chain/EquationModel.combine_solutions into est->canon / est->canon_rse (canonical order):
 * a forced block's unknowns are absolute values; an unforced block's are ratios to its
 * scale, found by its rules from a block already on a known scale (passes until none
 * progresses). Relative errors of products add in quadrature. */
static void combine(duffid_estimator *est)
{
    const duffid_model *m = &est->model;
    const int n = est->n_eq;
    int known[MAX_EQ];
    double s_val[MAX_EQ], s_err[MAX_EQ];
    int i, progress = 1, n_canon = est->n_params;
    for (i = 0; i < n; i++) {
        known[i] = m->blocks[i].forced;
        s_val[i] = 1.0;
        s_err[i] = 0.0;
    }
    for (;;) {
        int missing = 0;
        for (i = 0; i < n; i++) {
            missing |= !known[i];
        }
        if (!(progress && missing)) {
            break;
        }
        progress = 0;
        for (i = 0; i < n; i++) {
            int r;
            if (known[i]) {
                continue;
            }
            for (r = 0; r < m->blocks[i].n_rules; r++) {
                const duffid_rule *rule = &m->blocks[i].rules[r];
                const double ratio = est->eq[i].theta[rule->unknown];
                const int j = rule->other;
                if (ratio == 0.0 || !known[j]) {
                    continue;
                }
                {
                    double abs_val = s_val[j] * est->eq[j].theta[rule->other_unknown];
                    double abs_err = hypot(s_err[j], est->eq[j].rse[rule->other_unknown]);
                    s_val[i] = abs_val / ratio;
                    s_err[i] = hypot(abs_err, est->eq[i].rse[rule->unknown]);
                    known[i] = 1;
                    progress = 1;
                    break;
                }
            }
        }
    }
    for (i = 0; i < n_canon; i++) {
        const duffid_parameter *q = &m->params[i];
        double val = DNAN, err = DINF;
        int k;
        if (q->scale_of >= 0) {
            if (known[q->scale_of]) {
                val = s_val[q->scale_of];
                err = s_err[q->scale_of];
            }
        } else {
            for (k = 0; k < q->n_sources; k++) {
                const int j = q->sources[k].block, u = q->sources[k].unknown;
                if (known[j]) {
                    val = s_val[j] * est->eq[j].theta[u];
                    err = hypot(s_err[j], est->eq[j].rse[u]);
                    break;
                }
            }
        }
        est->canon[i] = val;
        est->canon_rse[i] = err;
    }
    /* OnlineIdentifier._shares: the largest share over the blocks with the term */
    for (i = 0; i < n_canon; i++) {
        const duffid_parameter *q = &m->params[i];
        double share = DNAN;
        int k;
        for (k = 0; k < q->n_shares; k++) {
            const int j = q->shares[k].block, u = q->shares[k].unknown;
            double v = u >= 0 ? est->eq[j].share[u] : est->eq[j].rhs_share;
            if (is_finite(v) && !(v <= share)) {
                share = v;
            }
        }
        est->canon_share[i] = share;
    }
}

static double combined_condition(const duffid_estimator *est)
{
    double cond = est->eq[0].cond;
    int e;
    for (e = 1; e < est->n_eq; e++) {
        cond = max_builtin(cond, est->eq[e].cond);
    }
    return cond;
}

/* identification.auto_window with the model's linear_natural_frequencies of the estimate:
 * the eigenvalues of M^-1 K (np.linalg.solve, then eigvals) */
static long auto_window(duffid_estimator *est, long current)
{
    const duffid_model *m = &est->model;
    const int n = est->n_dof;
    double *M = est->lin, *K = est->lin + n * n;
    double wr[DUFFID_MAX_DOF], wi[DUFFID_MAX_DOF], best = DINF, samples;
    int i;
    if (!m->linear) {
        return est->capacity;
    }
    memset(est->lin, 0, sizeof est->lin);
    for (i = 0; i < m->n_mass; i++) {
        const duffid_linear *l = &m->mass[i];
        M[l->row * n + l->col] += l->param >= 0 ? l->coef * est->canon[l->param] : l->coef;
    }
    for (i = 0; i < m->n_stiffness; i++) {
        const duffid_linear *l = &m->stiffness[i];
        K[l->row * n + l->col] += l->param >= 0 ? l->coef * est->canon[l->param] : l->coef;
    }
    for (i = 0; i < 2 * n * n; i++) {
        if (!is_finite(est->lin[i])) {
            return est->capacity; /* LinAlgError / singular inertia in Python */
        }
    }
    if (duffid_la_solve(n, M, K, n) != 0) {
        return est->capacity;
    }
    if (duffid_la_eigenvalues(n, K, wr, wi) != 0) {
        return est->capacity;
    }
    for (i = 0; i < n; i++) {
        double omega = sqrt(fabs(wr[i]));
        if (is_finite(omega) && omega > 0.0 && omega < best) {
            best = omega;
        }
    }
    if (!is_finite(best)) {
        return est->capacity;
    }
    samples = round_half_even(est->cfg.window_periods * 2.0 * PI / best / est->cfg.dt);
    if (samples < (double)current) {
        samples = (double)current;
    }
    if (!(samples <= (double)est->capacity)) {
        samples = (double)est->capacity;
    }
    return (long)samples;
}

/* ------------------------------------------------------------------ publication */
static int window_ok(const duffid_estimator *est, double cond, long L)
{
    return cond <= est->cfg.max_condition && (double)L * est->cfg.dt >= est->cfg.min_time - 1e-12 &&
           est->n >= MIN_SAMPLES;
}

/* identification._next_status */
static int next_status(int status, int64_t settled, int64_t unsettled, int64_t settle, int good, double share)
{
    if (settled >= settle) {
        return DUFFID_STATUS_PUBLISHED;
    }
    if (status == DUFFID_STATUS_PUBLISHED) {
        return unsettled >= settle ? DUFFID_STATUS_LOST : DUFFID_STATUS_PUBLISHED;
    }
    if (good && share < DUFFID_MIN_SHARE) {
        return DUFFID_STATUS_NOT_EXCITED;
    }
    return status == DUFFID_STATUS_LOST ? DUFFID_STATUS_LOST : DUFFID_STATUS_UNCERTAIN;
}

/* OnlineIdentifier._window_known: masses and linear stiffnesses steady, the rest steady
 * or not excited */
static int window_known(const duffid_estimator *est)
{
    int i;
    for (i = 0; i < est->n_params; i++) {
        int needed = est->model.params[i].period;
        if (!(est->steady[i] >= est->settle_count || (est->status[i] == DUFFID_STATUS_NOT_EXCITED && !needed))) {
            return 0;
        }
    }
    return 1;
}

static void count_up(int64_t *counter, int64_t limit)
{
    if (*counter < limit) {
        (*counter)++;
    }
}

/* the model's is_physical: the sign its term needs (canonical index i) */
static int is_physical(const duffid_estimator *est, int i, double v)
{
    const int allowed = est->model.params[i].physical;
    if (v > 0.0) {
        return (allowed & DUFFID_ALLOW_POSITIVE) != 0;
    }
    if (v < 0.0) {
        return (allowed & DUFFID_ALLOW_NEGATIVE) != 0;
    }
    if (v == 0.0) {
        return (allowed & DUFFID_ALLOW_ZERO) != 0;
    }
    return allowed == ANY_SIGN; /* NaN: only a parameter without a rule is "physical" */
}

/* the public value of canonical value v (models' from_canonical) */
static double public_value(const duffid_estimator *est, int i, double v)
{
    if (!est->model.publics[i].reciprocal) {
        return v;
    }
    return v != 0.0 ? 1.0 / v : DINF;
}

static void publish(duffid_estimator *est, long window, duffid_output *out)
{
    const int np = est->n_params;
    double cond, worst = 0.0;
    int i, ok = 1, good;
    combine(est);
    cond = combined_condition(est);
    good = window_ok(est, cond, window);
    if (est->cfg.method == DUFFID_PAPER) {
        for (i = 0; i < np; i++) {
            double v = est->canon[i];
            est->held[i] = public_value(est, i, est->canon[est->model.publics[i].canonical]);
            ok &= is_finite(v) && is_physical(est, i, v);
        }
        ok = ok && good;
        worst = DNAN;
        for (i = 0; i < np; i++) {
            est->status[i] = ok ? DUFFID_STATUS_PUBLISHED : DUFFID_STATUS_UNCERTAIN;
        }
    } else {
        double trusted[DUFFID_MAX_PARAMS];
        const int full = window >= est->target;
        const double tol = 0.5 * est->cfg.max_uncertainty;
        for (i = 0; i < np; i++) { /* canonical order */
            double v = est->canon[i];
            double relative = (is_finite(v) && v != 0.0) ? est->canon_rse[i] : DINF;
            int small, large;
            if (est->nominal[i] > 0.0 && is_finite(relative)) { /* the user's prior size */
                relative = relative * fabs(v) / (fabs(v) > est->nominal[i] ? fabs(v) : est->nominal[i]);
            }
            worst = max_builtin(worst, relative);
            {
                const int physical = is_physical(est, i, v);
                const int excited = est->canon_share[i] >= DUFFID_MIN_SHARE || est->nominal[i] > 0.0;
                small = good && excited && physical && relative <= est->cfg.max_uncertainty;
                large = !(good && physical && relative <= DUFFID_LOSS_FACTOR * est->cfg.max_uncertainty);
            }
            if (small) {
                count_up(&est->steady[i], est->settle_count);
            } else {
                est->steady[i] = 0;
            }
            if (!(is_finite(v) && fabs(v - est->anchor[i]) <= tol * fabs(est->anchor[i]))) {
                est->anchor[i] = v;
                est->anchored[i] = est->n;
            }
            if (small && (full || (double)(est->n - est->anchored[i]) >= DUFFID_GROWTH_STEADY * (double)window)) {
                count_up(&est->settled[i], est->settle_count);
            } else {
                est->settled[i] = 0;
            }
            if (large) {
                count_up(&est->unsettled[i], est->settle_count);
            } else {
                est->unsettled[i] = 0;
            }
            est->status[i] = next_status(est->status[i], est->settled[i], est->unsettled[i], est->settle_count,
                                         good, est->canon_share[i]);
            trusted[i] = est->settled[i] >= est->settle_count ? v : DNAN;
        }
        for (i = 0; i < np; i++) {
            int c = est->model.publics[i].canonical;
            double v = public_value(est, i, trusted[c]);
            if (est->status[c] != DUFFID_STATUS_PUBLISHED) {
                est->held[i] = DNAN;
            } else if (is_finite(v)) {
                est->held[i] = v;
            }
            ok &= est->status[c] == DUFFID_STATUS_PUBLISHED;
        }
    }
    if (out != NULL) {
        out->t = (double)est->n * est->cfg.dt;
        for (i = 0; i < DUFFID_MAX_PARAMS; i++) {
            out->parameters[i] = i < np ? est->held[i] : DNAN;
            out->status[i] = i < np ? est->status[est->cfg.method == DUFFID_PAPER ? i : est->model.publics[i].canonical]
                                    : DUFFID_STATUS_UNCERTAIN;
        }
        out->n_parameters = np;
        out->identified = ok;
        out->condition = cond;
        out->uncertainty = worst;
        out->window = (double)window * est->cfg.dt;
        for (i = 0; i < DUFFID_MAX_PARAMS; i++) {
            double v = DNAN;
            if (i < np) {
                v = est->cfg.method == DUFFID_PAPER ? est->held[i] : (good ? public_value(est, i, est->canon[est->model.publics[i].canonical]) : DNAN);
            }
            out->current[i] = v;
        }
    }
    if (est->cfg.method == DUFFID_ROBUST && est->auto_window && !est->window_fixed && window_known(est)) {
        est->window_fixed = 1;
        est->target = auto_window(est, window);
    }
}

/* ------------------------------------------------------------------ outliers */
static void guard_threshold(const duffid_estimator *est, double *threshold)
{
    int j;
    for (j = 0; j < est->n_dof; j++) {
        double step = is_finite(est->g_step[j]) ? est->g_step[j] : 0.0;
        double scale = 1.2533141373155003 * est->g_mean[j];
        double range = DUFFID_OUTLIER_RANGE * (est->g_hi[j] - est->g_lo[j]);
        scale = step > scale ? step : scale;
        scale = range > scale ? range : scale;
        threshold[j] = DUFFID_OUTLIER_SIGMAS * scale;
    }
}

static double guard_prediction(const duffid_estimator *est, int j)
{
    const int n = est->n_dof;
    return 3.0 * est->gh[j] - 3.0 * est->gh[n + j] + est->gh[2 * n + j];
}

/* _OutlierGuard._accept (threshold NULL: no clipping) */
static void guard_accept(duffid_estimator *est, const double *x, const double *threshold)
{
    const int n = est->n_dof;
    int j;
    for (j = 0; j < n; j++) {
        if (est->g_count >= 3) {
            double r = fabs(x[j] - guard_prediction(est, j));
            if (threshold != NULL && threshold[j] < r) {
                r = threshold[j];
            }
            est->g_mean[j] = est->g_count == 3 ? r : est->g_mean[j] + (r - est->g_mean[j]) / DUFFID_OUTLIER_MEMORY;
        }
        if (est->g_count >= 1) {
            double d = fabs(x[j] - est->gh[j]);
            if (d > 0.0 && d < est->g_step[j]) {
                est->g_step[j] = d;
            }
        }
        if (x[j] < est->g_lo[j]) {
            est->g_lo[j] = x[j];
        }
        if (x[j] > est->g_hi[j]) {
            est->g_hi[j] = x[j];
        }
        est->gh[2 * n + j] = est->gh[n + j];
        est->gh[n + j] = est->gh[j];
        est->gh[j] = x[j];
    }
    est->g_count++;
}

/* ------------------------------------------------------------------ update */
/* OnlineIdentifier._process: one sample into the estimator, its output into est->last */
static void process(duffid_estimator *est, const double *x, const double *f)
{
    long window;
    est->n++;
    evaluate_channels(est, x, f);
    window = est->cfg.method == DUFFID_ROBUST ? robust_step(est) : paper_step(est);
    publish(est, window, &est->last);
}

/* OnlineIdentifier._reported */
static void report(const duffid_estimator *est, duffid_output *out)
{
    if (out == NULL) {
        return;
    }
    *out = est->last;
    out->t = (double)est->received * est->cfg.dt;
    out->outliers = est->outliers;
    out->outlier_t = est->outlier_t;
    out->outlier_column = est->outlier_column;
    out->outlier_value = est->outlier_value;
    out->outlier_replaced_by = est->outlier_replaced_by;
}

int duffid_update(duffid_estimator *est, const double *x, const double *f, duffid_output *out)
{
    double threshold[DUFFID_MAX_DOF];
    int i, j, suspect = 0;
    if (est == NULL || x == NULL || f == NULL) {
        return DUFFID_ERR_ARGUMENT;
    }
    for (i = 0; i < est->n_dof; i++) {
        if (!is_finite(x[i])) {
            return DUFFID_ERR_SAMPLE;
        }
    }
    for (i = 0; i < est->n_forces; i++) {
        if (!is_finite(f[i])) {
            return DUFFID_ERR_SAMPLE;
        }
    }
    est->received++;
    if (est->pending) { /* _OutlierGuard.admit: was the held sample an isolated glitch? */
        const int n = est->n_dof;
        est->pending = 0;
        for (j = 0; j < n; j++) {
            double ahead = 6.0 * est->gh[j] - 8.0 * est->gh[n + j] + 3.0 * est->gh[2 * n + j];
            if (est->p_suspect[j] && fabs(x[j] - ahead) <= est->p_threshold[j]) {
                double value = (3.0 * est->gh[j] - est->gh[n + j] + x[j]) / 3.0;
                est->outliers++;
                est->outlier_t = (double)est->p_k * est->cfg.dt;
                est->outlier_column = j;
                est->outlier_value = est->p_x[j];
                est->outlier_replaced_by = value;
                est->p_x[j] = value;
            }
        }
        guard_accept(est, est->p_x, est->p_threshold);
        process(est, est->p_x, est->p_f);
    }
    if (est->g_count >= MIN_SAMPLES) {
        guard_threshold(est, threshold);
        for (j = 0; j < est->n_dof; j++) {
            est->p_suspect[j] = fabs(x[j] - guard_prediction(est, j)) > threshold[j];
            suspect |= est->p_suspect[j];
        }
        if (suspect) { /* held back one sample */
            est->pending = 1;
            est->p_k = est->received;
            for (j = 0; j < est->n_dof; j++) {
                est->p_x[j] = x[j];
                est->p_threshold[j] = threshold[j];
            }
            for (j = 0; j < est->n_forces; j++) {
                est->p_f[j] = f[j];
            }
            report(est, out);
            return DUFFID_OK;
        }
        guard_accept(est, x, threshold);
    } else {
        guard_accept(est, x, NULL);
    }
    process(est, x, f);
    report(est, out);
    return DUFFID_OK;
}

long duffid_latest_output(const duffid_estimator *est, duffid_output *out)
{
    if (est == NULL || out == NULL) {
        return 0;
    }
    report(est, out);
    return (long)(est->received + 1);
}

int duffid_flush(duffid_estimator *est, duffid_output *out)
{
    if (est == NULL || !est->pending) {
        return 0;
    }
    est->pending = 0;
    guard_accept(est, est->p_x, est->p_threshold);
    process(est, est->p_x, est->p_f);
    report(est, out);
    return 1;
}

int duffid_run(duffid_estimator *est, long n, const double *x, const double *f, duffid_output *out,
               long *failed)
{
    long k;
    if (est == NULL || n < 0 || (n > 0 && (x == NULL || f == NULL))) {
        return DUFFID_ERR_ARGUMENT;
    }
    for (k = 0; k < n; k++) {
        int rc = duffid_update(est, x + k * est->n_dof, f + k * est->n_forces, out != NULL ? out + k : NULL);
        if (rc != DUFFID_OK) {
            if (failed != NULL) {
                *failed = k;
            }
            return rc;
        }
    }
    return DUFFID_OK;
}

/* ------------------------------------------------------------------ introspection */
int duffid_n_parameters(const duffid_estimator *est)
{
    return est != NULL ? est->n_params : 0;
}

int duffid_n_dof(const duffid_estimator *est)
{
    return est != NULL ? est->n_dof : 0;
}

int duffid_n_forces(const duffid_estimator *est)
{
    return est != NULL ? est->n_forces : 0;
}

const char *duffid_parameter_name(const duffid_estimator *est, int i)
{
    if (est == NULL || i < 0 || i >= est->n_params) {
        return NULL;
    }
    return est->model.publics[i].name;
}

long duffid_capacity(const duffid_estimator *est)
{
    return est != NULL ? est->capacity : 0;
}

const duffid_config *duffid_get_config(const duffid_estimator *est)
{
    return est != NULL ? &est->cfg : NULL;
}

size_t duffid_config_size(void)
{
    return sizeof(duffid_config);
}

size_t duffid_output_size(void)
{
    return sizeof(duffid_output);
}
