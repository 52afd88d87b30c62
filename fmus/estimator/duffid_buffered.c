/*
 * duffid_buffered.c - the buffered identifier of duffid_buffered.h (paper section 4,
 * Figure 15): a port of duffid.identification.buffered.BufferedIdentifier (per-DOF form,
 * each window alone) over the tables Python generates.
 *
 * Python computes one window as V[d] = W[d] G with the kernels
 *     W[d] = sum_k alpha_dk (P_(n-d+k)^T Q diag(s^(n-k)))[kept],
 *     alpha_dk = (-1)^k C(d, k) n! / (n - k)!,
 * (G: the window's channel samples, s = i / N). Here the same products are associated the
 * other way: the coefficients C_p = Q diag(s^p) G (r x channels, p = 0..n) are accumulated
 * sample by sample, and V[d] = sum_k alpha_dk (P_(n-d+k)^T C_(n-k))[kept] once per window, with
 * P_m stored by kept column as a sparse list (tridiagonal for Legendre). The results equal
 * Python's to rounding amplified by the conditioning (tests/test_buffered_c.py).
 */
#include "duffid_buffered.h"
#include "duffid_linalg.h"

#include <stdint.h>
#include <string.h>

#define MAX_ORD (DUFFID_MAX_DERIVATIVE + 1)
#define MAX_UNK DUFFID_MAX_UNKNOWNS
#define MAX_AUG (MAX_UNK + 1)
#define ALIGNMENT DUFFID_LA_ALIGNMENT
#define ALIGN_UP DUFFID_LA_ALIGN_UP
#define CARVE DUFFID_LA_CARVE

struct duffid_buffered {
    duffid_buffered_config cfg;
    const duffid_buffered_tables *tb;
    long N, every;
    int r, n_ord, n_ch, n_slots, max_unknowns;
    duffid_real alpha[MAX_ORD * MAX_ORD]; /* alpha[d * n_ord + k] */
    duffid_real t_inv[MAX_ORD];           /* T^-d, T = N dt */
    duffid_real cond_limit;               /* the smaller of max_condition-independent singularity and precision */
    /* the block's arrays (carved after the structure) */
    duffid_real *coef;  /* slots x n_ord x n_ch x r: C_p of each open window */
    duffid_real *sumsq; /* slots x n_ch: sum of the channels' squares (rounding bound) */
    long *pos;          /* slots: index of the next sample in that window, -1 when closed */
    duffid_real *E;     /* chunk x n_ord x n_ch: the row entries of one stage's rows */
    duffid_real *B;     /* chunk x (unknowns + 1), column-major: one equation's [A D] rows */
    duffid_real *R;     /* per equation: the (unknowns + 1)^2 factor of the window being solved */
    duffid_real *R_check; /* ... of its first check_rows coefficient equations (buffered.CHECK_SHARE) */
    duffid_real *check; /* workspace of that check: max unknowns x (2 max unknowns + 3) */
    int check_rows;     /* the check's rows per equation */
    duffid_real *norm2, *bound2; /* per equation and column: squares of the rows and of their rounding bounds */
    duffid_real *rse;           /* workspace */
    duffid_real *U, *Rinv, *scale; /* per equation: the equilibrated factor, its inverse, the column scales */
    duffid_real *eq_cond;       /* per equation: its condition number (infinite: singular or held) */
    int *eq_state;              /* per equation: SOLVABLE, SINGULAR or HELD (no known term) */
    duffid_real *V;     /* per equation: unknowns x unknowns, the Jacobi iteration's start */
    int *warm;          /* per equation */
    duffid_real *held;  /* per equation: its unknowns of the latest solved window */
    int *offset;        /* per equation: first unknown in held, first square in V, first in R, first
                         * column in norm2 / bound2 */
    int chunk;          /* rows per stage */
    int stages;         /* stages of a window's solve: row chunks, the conditions, the unknowns */
    int immediate;      /* 1: all stages at the window's last sample (every < 3) */
    /* state */
    int64_t n;          /* samples received - 1 (-1: none) */
    int pending;        /* the slot whose window is being solved, -1: none */
    int stage;          /* its next stage */
    long until_start;   /* samples until the next window starts */
    int next_slot;
    int have_last;
    duffid_real last_x[DUFFID_MAX_DOF], sign[DUFFID_MAX_DOF];
    long windows;
    int identified;
    duffid_real condition, uncertainty;
    duffid_real current[DUFFID_MAX_PARAMS];
};

static int is_finite(duffid_real v)
{
    return v - v == RC(0.0);
}

static int max_unknowns_of(const duffid_buffered_tables *tb)
{
    int e, most = 0;
    for (e = 0; e < tb->n_equations; e++) {
        most = tb->n_unknowns[e] > most ? tb->n_unknowns[e] : most;
    }
    return most;
}

/* over the equations: what = 0 the unknowns n, 1 their squares n^2, 2 (n + 1)^2, 3 n + 1 */
static int sum_unknowns(const duffid_buffered_tables *tb, int what)
{
    int e, total = 0;
    for (e = 0; e < tb->n_equations; e++) {
        const int n = tb->n_unknowns[e];
        total += what == 0 ? n : what == 1 ? n * n : what == 2 ? (n + 1) * (n + 1) : n + 1;
    }
    return total;
}

/* Rows per stage of a window's solve: a window's per-window work (its row entries, the
 * factor's update) is spread over the samples after its end, a chunk of rows per sample, then
 * one sample solves; this keeps every update within a fixed bound. */
#define ROWS_PER_STAGE 2

static long every_of(const duffid_buffered_config *cfg)
{
    return cfg->every > 0 ? cfg->every : cfg->tables->n_intervals;
}

/* stages of one window's solve: the row chunks, the factors' inverses, their condition
 * numbers, the unknowns; at most every (a window ends every `every` samples: its solve is
 * done before the next ends), and when fewer than 4 fit, all of them at the window's last
 * sample */
static int stages_of(const duffid_buffered_config *cfg)
{
    const int kept = cfg->tables->n_kept;
    const long every = every_of(cfg);
    const long wanted = (kept + ROWS_PER_STAGE - 1) / ROWS_PER_STAGE + 3;
    return (int)(wanted < every ? wanted : every);
}

static int immediate(const duffid_buffered_config *cfg)
{
    return stages_of(cfg) < 4;
}

static int chunk_of(const duffid_buffered_config *cfg)
{
    const int kept = cfg->tables->n_kept, chunks = immediate(cfg) ? 1 : stages_of(cfg) - 3;
    return (kept + chunks - 1) / chunks;
}

static long slots_of(const duffid_buffered_config *cfg)
{
    /* windows open at once, and the one being solved: a slot is reused once its solve is done */
    const long N = cfg->tables->n_intervals, every = every_of(cfg);
    return (N + (immediate(cfg) ? 1 : stages_of(cfg)) + every - 1) / every;
}

/* the block after the structure; base NULL: sizes only */
static size_t layout(const duffid_buffered_config *cfg, duffid_buffered *est, char *base)
{
    const duffid_buffered_tables *tb = cfg->tables;
    const long slots = slots_of(cfg);
    const int n_ord = tb->order + 1, n_ch = tb->n_channels, r = tb->n_terms, kept = tb->n_kept;
    const int p = max_unknowns_of(tb) + 1, n_eq = tb->n_equations;
    (void)kept;
    duffid_buffered scratch;
    duffid_la_carver c;
    if (est == NULL) {
        est = &scratch;
    }
    c.base = base;
    c.used = 0;
    CARVE(&c, est->coef, slots * n_ord * n_ch * r);
    CARVE(&c, est->sumsq, slots * n_ch);
    CARVE(&c, est->pos, slots);
    CARVE(&c, est->E, chunk_of(cfg) * n_ord * n_ch);
    CARVE(&c, est->B, chunk_of(cfg) * p);
    CARVE(&c, est->R, sum_unknowns(tb, 2));
    CARVE(&c, est->R_check, sum_unknowns(tb, 2));
    CARVE(&c, est->check, (p - 1) * (2 * p + 1));
    CARVE(&c, est->norm2, sum_unknowns(tb, 3));
    CARVE(&c, est->bound2, sum_unknowns(tb, 3));
    CARVE(&c, est->U, sum_unknowns(tb, 1));
    CARVE(&c, est->rse, p - 1);
    CARVE(&c, est->Rinv, sum_unknowns(tb, 1));
    CARVE(&c, est->scale, sum_unknowns(tb, 0));
    CARVE(&c, est->eq_cond, n_eq);
    CARVE(&c, est->eq_state, n_eq);
    CARVE(&c, est->V, sum_unknowns(tb, 1));
    CARVE(&c, est->warm, n_eq);
    CARVE(&c, est->held, sum_unknowns(tb, 0));
    CARVE(&c, est->offset, 4 * n_eq);
    return c.used;
}

void duffid_buffered_default_config(duffid_buffered_config *cfg, const duffid_buffered_tables *tables,
                                    duffid_real dt)
{
    if (cfg == NULL) {
        return;
    }
    memset(cfg, 0, sizeof *cfg);
    cfg->tables = tables;
    cfg->dt = dt;
    cfg->every = 0;
    cfg->max_condition = RC(1e8);
    cfg->max_uncertainty = RC(0.05);
    cfg->deadband = RC(0.0);
}

static int check_tables(const duffid_buffered_tables *tb, char *msg, size_t size)
{
    int e, k, m;
    if (tb->n_dof < 1 || tb->n_dof > DUFFID_MAX_DOF || tb->n_forces < 0 || tb->n_forces > DUFFID_MAX_FORCES) {
        duffid_la_message(msg, size, "tables: %d displacements and %d forces; at most %d and %d", tb->n_dof,
                          tb->n_forces, DUFFID_MAX_DOF, DUFFID_MAX_FORCES);
        return DUFFID_ERR_CONFIG;
    }
    if (tb->n_channels < 1 || tb->n_channels > DUFFID_MAX_CHANNELS || tb->channels == NULL) {
        duffid_la_message(msg, size, "tables: %d channels; 1 to %d", tb->n_channels, DUFFID_MAX_CHANNELS);
        return DUFFID_ERR_CONFIG;
    }
    for (k = 0; k < tb->n_channels; k++) {
        const duffid_buffered_channel *ch = &tb->channels[k];
        const int limit = ch->kind == DUFFID_BUF_FORCE ? tb->n_forces : tb->n_dof;
        if (ch->kind < DUFFID_BUF_X || ch->kind > DUFFID_BUF_ONE || ch->power < 1 ||
            (ch->kind != DUFFID_BUF_ONE && (ch->index < 0 || ch->index >= limit))) {
            duffid_la_message(msg, size, "tables: channel %d (kind %d, index %d, power %d) is not valid", k,
                              ch->kind, ch->index, ch->power);
            return DUFFID_ERR_CONFIG;
        }
    }
    if (tb->order < 0 || tb->order > DUFFID_MAX_DERIVATIVE || tb->n_terms < 2 || tb->n_intervals < 3 ||
        tb->n_terms > tb->n_intervals || tb->n_kept < 1 || tb->n_kept > tb->n_terms) {
        duffid_la_message(msg, size, "tables: order %d (at most %d), %d basis functions, %d kept, %ld sample "
                          "intervals: need 2 <= functions <= intervals, 3 <= intervals, 1 <= kept <= functions",
                          tb->order, DUFFID_MAX_DERIVATIVE, tb->n_terms, tb->n_kept, tb->n_intervals);
        return DUFFID_ERR_CONFIG;
    }
    if (tb->Q == NULL || tb->kept == NULL || tb->w_norm == NULL || (tb->order > 0 && (tb->p_start == NULL ||
        tb->p_index == NULL || tb->p_value == NULL))) {
        duffid_la_message(msg, size, "tables: a matrix is missing (NULL)");
        return DUFFID_ERR_CONFIG;
    }
    for (k = 0; k < tb->n_kept; k++) {
        if (tb->kept[k] < 0 || tb->kept[k] >= tb->n_terms) {
            duffid_la_message(msg, size, "tables: kept[%d] = %d is not a basis function index", k, tb->kept[k]);
            return DUFFID_ERR_CONFIG;
        }
    }
    for (m = 1; m <= tb->order; m++) {
        const int *start = tb->p_start + (m - 1) * (tb->n_kept + 1);
        for (k = 0; k < tb->n_kept; k++) {
            int j;
            if (start[k] < 0 || start[k + 1] < start[k]) {
                duffid_la_message(msg, size, "tables: P_%d's list of column %d is not valid", m, k);
                return DUFFID_ERR_CONFIG;
            }
            for (j = start[k]; j < start[k + 1]; j++) {
                if (tb->p_index[j] < 0 || tb->p_index[j] >= tb->n_terms) {
                    duffid_la_message(msg, size, "tables: P_%d's entry %d has row %d", m, j, tb->p_index[j]);
                    return DUFFID_ERR_CONFIG;
                }
            }
        }
    }
    if (tb->n_equations < 1 || tb->n_equations > DUFFID_MAX_BLOCKS || tb->n_unknowns == NULL) {
        duffid_la_message(msg, size, "tables: %d equations; 1 to %d", tb->n_equations, DUFFID_MAX_BLOCKS);
        return DUFFID_ERR_CONFIG;
    }
    for (e = 0; e < tb->n_equations; e++) {
        if (tb->n_unknowns[e] < 1 || tb->n_unknowns[e] > MAX_UNK || tb->n_unknowns[e] + 1 > DUFFID_LA_MAX ||
            tb->n_unknowns[e] > tb->n_kept) {
            duffid_la_message(msg, size, "tables: equation %d has %d unknowns; 1 to %d and at most the %d kept "
                              "coefficients", e, tb->n_unknowns[e], MAX_UNK, tb->n_kept);
            return DUFFID_ERR_CONFIG;
        }
    }
    if (tb->n_model_terms < 1 || tb->terms == NULL) {
        duffid_la_message(msg, size, "tables: no terms");
        return DUFFID_ERR_CONFIG;
    }
    for (k = 0; k < tb->n_model_terms; k++) {
        const duffid_buffered_term *t = &tb->terms[k];
        if (t->equation < 0 || t->equation >= tb->n_equations || t->unknown < -1 ||
            t->unknown >= tb->n_unknowns[t->equation] || t->channel < 0 || t->channel >= tb->n_channels ||
            t->order < 0 || t->order > tb->order || !is_finite(t->coef)) {
            duffid_la_message(msg, size, "tables: term %d (equation %d, unknown %d, channel %d, order %d) is not "
                              "valid", k, t->equation, t->unknown, t->channel, t->order);
            return DUFFID_ERR_CONFIG;
        }
    }
    if (tb->n_parameters < 1 || tb->n_parameters > DUFFID_MAX_PARAMS || tb->parameter_equation == NULL ||
        tb->parameter_unknown == NULL) {
        duffid_la_message(msg, size, "tables: %d parameters; 1 to %d", tb->n_parameters, DUFFID_MAX_PARAMS);
        return DUFFID_ERR_CONFIG;
    }
    for (k = 0; k < tb->n_parameters; k++) {
        e = tb->parameter_equation[k];
        if (e < 0 || e >= tb->n_equations || tb->parameter_unknown[k] < 0 ||
            tb->parameter_unknown[k] >= tb->n_unknowns[e]) {
            duffid_la_message(msg, size, "tables: parameter %d maps to equation %d, unknown %d", k, e,
                              tb->parameter_unknown[k]);
            return DUFFID_ERR_CONFIG;
        }
    }
    return DUFFID_OK;
}

int duffid_buffered_check_config(const duffid_buffered_config *cfg, char *msg, size_t size)
{
    int rc;
    if (cfg == NULL || cfg->tables == NULL) {
        duffid_la_message(msg, size, "no configuration or no tables (NULL)");
        return DUFFID_ERR_ARGUMENT;
    }
    rc = check_tables(cfg->tables, msg, size);
    if (rc != DUFFID_OK) {
        return rc;
    }
    if (!(is_finite(cfg->dt) && cfg->dt > RC(0.0))) {
        duffid_la_message(msg, size, "dt must be a finite number of seconds > 0");
        return DUFFID_ERR_CONFIG;
    }
    if (cfg->every < 0) {
        duffid_la_message(msg, size, "every must be >= 0 samples (0: the window's %ld), got %ld",
                          cfg->tables->n_intervals, cfg->every);
        return DUFFID_ERR_CONFIG;
    }
    if (!(is_finite(cfg->max_condition) && cfg->max_condition >= RC(0.0) && is_finite(cfg->max_uncertainty) &&
          cfg->max_uncertainty >= RC(0.0) && is_finite(cfg->deadband) && cfg->deadband >= RC(0.0))) {
        duffid_la_message(msg, size, "max_condition, max_uncertainty and deadband must be finite numbers >= 0");
        return DUFFID_ERR_CONFIG;
    }
    if (slots_of(cfg) > 4096) {
        duffid_la_message(msg, size, "every = %ld keeps %ld windows open at once; at most 4096", cfg->every,
                          slots_of(cfg));
        return DUFFID_ERR_CONFIG;
    }
    return DUFFID_OK;
}

size_t duffid_buffered_memory_size(const duffid_buffered_config *cfg)
{
    if (duffid_buffered_check_config(cfg, NULL, 0) != DUFFID_OK) {
        return 0;
    }
    return ALIGNMENT + ALIGN_UP(sizeof(duffid_buffered)) + layout(cfg, NULL, NULL);
}

void duffid_buffered_reset(duffid_buffered *est)
{
    const duffid_buffered_tables *tb;
    int i, e;
    if (est == NULL) {
        return;
    }
    tb = est->tb;
    for (i = 0; i < est->n_slots; i++) {
        est->pos[i] = -1;
    }
    for (e = 0; e < tb->n_equations; e++) {
        est->warm[e] = 0;
    }
    for (i = 0; i < sum_unknowns(tb, 0); i++) {
        est->held[i] = R_NAN;
    }
    for (i = 0; i < DUFFID_MAX_DOF; i++) {
        est->last_x[i] = RC(0.0);
        est->sign[i] = RC(0.0);
    }
    for (i = 0; i < DUFFID_MAX_PARAMS; i++) {
        est->current[i] = R_NAN;
    }
    est->n = -1;
    est->pending = -1;
    est->stage = 0;
    est->until_start = 0;
    est->next_slot = 0;
    est->have_last = 0;
    est->windows = 0;
    est->identified = 0;
    est->condition = R_INF;
    est->uncertainty = R_NAN;
}

int duffid_buffered_init(duffid_buffered **out, void *memory, size_t size, const duffid_buffered_config *cfg,
                         char *msg, size_t msg_size)
{
    const duffid_buffered_tables *tb;
    duffid_buffered *est;
    uintptr_t address;
    int rc, d, k, e, off, off2, off3, off4;
    if (out == NULL || memory == NULL) {
        duffid_la_message(msg, msg_size, "no estimator pointer or no memory (NULL)");
        return DUFFID_ERR_ARGUMENT;
    }
    rc = duffid_buffered_check_config(cfg, msg, msg_size);
    if (rc != DUFFID_OK) {
        return rc;
    }
    if (size < duffid_buffered_memory_size(cfg)) {
        duffid_la_message(msg, msg_size, "memory of %lu bytes; this configuration needs %lu",
                          (unsigned long)size, (unsigned long)duffid_buffered_memory_size(cfg));
        return DUFFID_ERR_ARGUMENT;
    }
    address = ((uintptr_t)memory + (ALIGNMENT - 1u)) & ~(uintptr_t)(ALIGNMENT - 1u);
    est = (duffid_buffered *)address;
    memset(est, 0, sizeof *est);
    layout(cfg, est, (char *)est + ALIGN_UP(sizeof *est));
    tb = cfg->tables;
    est->cfg = *cfg;
    est->tb = tb;
    est->N = tb->n_intervals;
    est->every = cfg->every > 0 ? cfg->every : tb->n_intervals;
    est->r = tb->n_terms;
    est->n_ord = tb->order + 1;
    est->n_ch = tb->n_channels;
    est->n_slots = (int)slots_of(cfg);
    est->max_unknowns = max_unknowns_of(tb);
    for (d = 0; d < est->n_ord; d++) { /* alpha_dk = (-1)^k C(d, k) n! / (n - k)! */
        for (k = 0; k <= d; k++) {
            duffid_real a = RC(1.0);
            int i;
            for (i = 0; i < k; i++) {
                a *= (duffid_real)(d - i) / (duffid_real)(i + 1) * (duffid_real)(tb->order - i);
            }
            est->alpha[d * est->n_ord + k] = k % 2 ? -a : a;
        }
        est->t_inv[d] = d == 0 ? RC(1.0) : est->t_inv[d - 1] / ((duffid_real)est->N * cfg->dt);
    }
    est->cond_limit = DUFFID_LA_COND_SINGULAR;
    for (e = 0, off = 0, off2 = 0, off3 = 0, off4 = 0; e < tb->n_equations; e++) {
        const int n = tb->n_unknowns[e];
        est->offset[4 * e] = off;
        est->offset[4 * e + 1] = off2;
        est->offset[4 * e + 2] = off3;
        est->offset[4 * e + 3] = off4;
        off += n;
        off2 += n * n;
        off3 += (n + 1) * (n + 1);
        off4 += n + 1;
    }
    est->chunk = chunk_of(cfg);
    est->check_rows = (int)(RC(DUFFID_BUFFERED_CHECK_SHARE) * (duffid_real)tb->n_kept);
    est->stages = immediate(cfg) ? (tb->n_kept + est->chunk - 1) / est->chunk + 3 : stages_of(cfg);
    est->immediate = immediate(cfg);
    duffid_buffered_reset(est);
    *out = est;
    return DUFFID_OK;
}

/* ------------------------------------------------------------------ per sample */
static duffid_real channel_value(const duffid_buffered *est, const duffid_buffered_channel *ch,
                                 const duffid_real *x, const duffid_real *f)
{
    duffid_real v, out;
    int i;
    switch (ch->kind) {
    case DUFFID_BUF_X:
        v = x[ch->index];
        break;
    case DUFFID_BUF_DEFLECTION:
        v = x[ch->index] - (ch->index > 0 ? x[ch->index - 1] : RC(0.0));
        break;
    case DUFFID_BUF_FORCE:
        return f[ch->index];
    case DUFFID_BUF_SIGN_VELOCITY:
        return est->sign[ch->index];
    default:
        return RC(1.0);
    }
    out = v;
    for (i = 1; i < ch->power; i++) {
        out *= v;
    }
    return out;
}

/* the coefficients of one window: sample i (of 0..N) with channel values g (two of the
 * (power, channel) accumulators per pass over the sample's weights) */
static void accumulate(duffid_buffered *est, int slot, long i, const duffid_real *g)
{
    const int r = est->r, n_ch = est->n_ch, K = est->n_ord * est->n_ch;
    const duffid_real *q = est->tb->Q + (size_t)i * (size_t)r;
    const duffid_real s = (duffid_real)i / (duffid_real)est->N;
    duffid_real *coef = est->coef + (size_t)slot * (size_t)(K * r);
    duffid_real w[MAX_ORD * DUFFID_MAX_CHANNELS], sp = RC(1.0);
    int p, c, j, k;
    for (p = 0, k = 0; p < est->n_ord; p++) { /* the sample's channels times s^p */
        for (c = 0; c < n_ch; c++) {
            w[k++] = g[c] * sp;
        }
        sp *= s;
    }
    for (k = 0; k + 1 < K; k += 2) {
        duffid_real *a = coef + k * r, *b = a + r;
        const duffid_real wa = w[k], wb = w[k + 1];
        for (j = 0; j < r; j++) {
            const duffid_real qj = q[j];
            a[j] += qj * wa;
            b[j] += qj * wb;
        }
    }
    if (k < K) {
        duffid_real *a = coef + k * r;
        const duffid_real wa = w[k];
        for (j = 0; j < r; j++) {
            a[j] += q[j] * wa;
        }
    }
    for (c = 0; c < n_ch; c++) {
        est->sumsq[slot * n_ch + c] += g[c] * g[c];
    }
}

/* ------------------------------------------------------------------ per window */
/* E[rho - row0, d, c] = T^-d sum_k alpha_dk (P_(n-d+k)^T C_(n-k))[kept[rho], c], rho in [row0, row1) */
static void entries(duffid_buffered *est, int slot, int row0, int row1)
{
    const duffid_buffered_tables *tb = est->tb;
    const int r = est->r, n_ch = est->n_ch, n_ord = est->n_ord, n = tb->order, kept = tb->n_kept;
    const duffid_real *coef = est->coef + (size_t)slot * (size_t)(n_ord * n_ch * r);
    int rho, d, k, c, j;
    for (rho = row0; rho < row1; rho++) {
        for (d = 0; d < n_ord; d++) {
            for (c = 0; c < n_ch; c++) {
                duffid_real v = RC(0.0);
                for (k = 0; k <= d; k++) {
                    const int m = n - d + k, p = n - k;
                    const duffid_real *cp = coef + (p * n_ch + c) * r;
                    duffid_real sum;
                    if (m == 0) {
                        sum = cp[tb->kept[rho]];
                    } else {
                        const int *start = tb->p_start + (m - 1) * (kept + 1);
                        sum = RC(0.0);
                        for (j = start[rho]; j < start[rho + 1]; j++) {
                            sum += tb->p_value[j] * cp[tb->p_index[j]];
                        }
                    }
                    v += est->alpha[d * n_ord + k] * sum;
                }
                est->E[((rho - row0) * n_ord + d) * n_ch + c] = v * est->t_inv[d];
            }
        }
    }
}

/* rows [row0, row1) of one equation's [A D] (column-major, B[col * m + row]), added to its
 * factor; in single precision also the squares of the rows and of their rounding bounds
 * (eps sqrt(N + 1) ||W_row|| ||g|| per entry, the terms' bounds added with |coef|) */
static void factor_rows(duffid_buffered *est, int slot, int e, int row0, int row1)
{
    const duffid_buffered_tables *tb = est->tb;
    const int m = row1 - row0, n_ord = est->n_ord, n_ch = est->n_ch, n = tb->n_unknowns[e], p = n + 1;
    int k, row;
    memset(est->B, 0, (size_t)(m * p) * sizeof(duffid_real));
    for (k = 0; k < tb->n_model_terms; k++) {
        const duffid_buffered_term *t = &tb->terms[k];
        duffid_real *col;
        if (t->equation != e) {
            continue;
        }
        col = est->B + (t->unknown >= 0 ? t->unknown : n) * m;
        for (row = 0; row < m; row++) {
            col[row] += t->coef * est->E[(row * n_ord + t->order) * n_ch + t->channel];
        }
    }
#if DUFFID_SINGLE
    {
        const duffid_real root = R_SQRT((duffid_real)(est->N + 1)) * R_EPS;
        duffid_real *norm2 = est->norm2 + est->offset[4 * e + 3], *bound2 = est->bound2 + est->offset[4 * e + 3];
        int col;
        for (col = 0; col < p; col++) {
            for (row = 0; row < m; row++) {
                duffid_real bound = RC(0.0);
                for (k = 0; k < tb->n_model_terms; k++) {
                    const duffid_buffered_term *t = &tb->terms[k];
                    if (t->equation == e && (t->unknown >= 0 ? t->unknown : n) == col) {
                        bound += R_FABS(t->coef) * tb->w_norm[t->order * tb->n_kept + row0 + row] *
                                 est->t_inv[t->order] * R_SQRT(est->sumsq[slot * n_ch + t->channel]);
                    }
                }
                bound *= root;
                bound2[col] += bound * bound;
                norm2[col] += est->B[col * m + row] * est->B[col * m + row];
            }
        }
    }
#else
    (void)slot;
#endif
    duffid_la_qr_accumulate(est->R + est->offset[4 * e + 2], p, RC(1.0), est->B, m);
}

/* the relative rounding of an equation's rows: the largest column's bound over its norm (0 in
 * double) */
static duffid_real rows_rounding(const duffid_buffered *est, int e)
{
    duffid_real rounding = RC(0.0);
#if DUFFID_SINGLE
    const duffid_real *norm2 = est->norm2 + est->offset[4 * e + 3], *bound2 = est->bound2 + est->offset[4 * e + 3];
    int col;
    for (col = 0; col <= est->tb->n_unknowns[e]; col++) {
        if (norm2[col] > RC(0.0)) {
            const duffid_real rel = R_SQRT(bound2[col] / norm2[col]);
            rounding = rel > rounding ? rel : rounding;
        }
    }
#else
    (void)est;
    (void)e;
#endif
    return rounding;
}

enum { SOLVABLE, SINGULAR, HELD };

/* the scales, equilibrated factors and their inverses of every equation (range = 0), or the
 * condition numbers of the solvable ones (range = 1) */
static void solve_conditions(duffid_buffered *est, int range)
{
    const duffid_buffered_tables *tb = est->tb;
    int e, i;
    for (e = 0; e < tb->n_equations; e++) {
        const int n = tb->n_unknowns[e], p = n + 1;
        const duffid_real *R = est->R + est->offset[4 * e + 2];
        duffid_real *U = est->U + est->offset[4 * e + 1];
        if (range) {
            if (est->eq_state[e] == SOLVABLE &&
                duffid_la_factor_range(n, U, est->cond_limit, est->V + est->offset[4 * e + 1], &est->warm[e],
                                       &est->eq_cond[e]) != 0) {
                est->eq_state[e] = SINGULAR;
            }
            continue;
        }
        {
            int known = 0;
            for (i = 0; i < p; i++) {
                known |= R[i * p + n] != RC(0.0);
            }
            est->eq_cond[e] = R_INF;
            if (!known) { /* no force (or other known term) in the rows: the scale is free; hold */
                est->eq_state[e] = HELD;
            } else if (duffid_la_factor_prepare(n, R, est->scale + est->offset[4 * e], U,
                                                est->Rinv + est->offset[4 * e + 1]) != 0) {
                est->eq_state[e] = SINGULAR;
                est->warm[e] = 0;
            } else {
                est->eq_state[e] = SOLVABLE;
            }
        }
    }
}

/* BufferedIdentifier.solve_window's check of the basis (buffered.CHECK_SHARE): the estimate of
 * equation e's first check_rows rows against theta, their relative difference into rse in
 * quadrature (infinite where that estimate is undetermined) */
static void check_basis(duffid_buffered *est, int e, const duffid_real *theta)
{
    const int n = est->tb->n_unknowns[e];
    duffid_real *scale = est->check, *U = scale + n, *Rinv = U + n * n, *first = Rinv + n * n,
                *unused = first + n;
    int i, solved = duffid_la_factor_prepare(n, est->R_check + est->offset[4 * e + 2], scale, U, Rinv) == 0;
    if (solved) {
        duffid_la_factor_unknowns(n, est->R_check + est->offset[4 * e + 2], (duffid_real)est->check_rows, RC(1.0),
                                  scale, Rinv, first, unused);
    }
    for (i = 0; i < n; i++) {
        const duffid_real moved = solved && theta[i] != RC(0.0) ? R_FABS((first[i] - theta[i]) / theta[i]) : R_INF;
        est->rse[i] = is_finite(moved) ? duffid_la_hypot(est->rse[i], moved) : R_INF;
    }
}

/* BufferedIdentifier.solve_window's unknowns, errors and verdict, from the conditions */
static void solve_unknowns(duffid_buffered *est)
{
    const duffid_buffered_tables *tb = est->tb;
    duffid_real cond = RC(0.0), worst = RC(0.0);
    int e, i, all_finite = 1;
    for (e = 0; e < tb->n_equations; e++) {
        const int n = tb->n_unknowns[e];
        duffid_real *held = est->held + est->offset[4 * e];
        const duffid_real c = est->eq_cond[e], rounding = rows_rounding(est, e);
        if (est->eq_state[e] == HELD) {
            cond = R_INF;
            worst = R_INF;
            continue;
        }
        if (est->eq_state[e] == SINGULAR) {
            for (i = 0; i < n; i++) {
                held[i] = R_NAN;
                est->rse[i] = R_INF;
            }
        } else {
            duffid_la_factor_unknowns(n, est->R + est->offset[4 * e + 2], (duffid_real)tb->n_kept, RC(1.0),
                                      est->scale + est->offset[4 * e], est->Rinv + est->offset[4 * e + 1], held,
                                      est->rse);
            check_basis(est, e, held);
        }
        cond = c > cond ? c : cond;
        for (i = 0; i < n; i++) {
#if DUFFID_SINGLE
            est->rse[i] = duffid_la_hypot(est->rse[i], rounding * c);
#else
            (void)rounding;
#endif
            worst = est->rse[i] > worst ? est->rse[i] : worst;
        }
    }
    for (i = 0; i < tb->n_parameters; i++) {
        est->current[i] = est->held[est->offset[4 * tb->parameter_equation[i]] + tb->parameter_unknown[i]];
        all_finite &= is_finite(est->current[i]);
    }
    est->condition = cond;
    est->uncertainty = worst;
    est->identified = cond <= est->cfg.max_condition && worst <= est->cfg.max_uncertainty && all_finite;
    est->windows++;
}

/* the rows [row0, row1) of the pending window into every equation's factor */
static void stage_rows(duffid_buffered *est, int slot, int row0, int row1)
{
    int e;
    if (row0 < row1) {
        entries(est, slot, row0, row1);
        for (e = 0; e < est->tb->n_equations; e++) {
            factor_rows(est, slot, e, row0, row1);
        }
    }
}

/* one stage of the pending window's solve; returns 1 when the window was solved */
static int solve_stage(duffid_buffered *est)
{
    const duffid_buffered_tables *tb = est->tb;
    const int slot = est->pending;
    if (est->stage == 0) {
        memset(est->R, 0, (size_t)sum_unknowns(tb, 2) * sizeof(duffid_real));
        memset(est->R_check, 0, (size_t)sum_unknowns(tb, 2) * sizeof(duffid_real));
        memset(est->norm2, 0, (size_t)sum_unknowns(tb, 3) * sizeof(duffid_real));
        memset(est->bound2, 0, (size_t)sum_unknowns(tb, 3) * sizeof(duffid_real));
    }
    if (est->stage < est->stages - 3) {
        const int row0 = est->stage * est->chunk;
        const int row1 = row0 + est->chunk < tb->n_kept ? row0 + est->chunk : tb->n_kept;
        const int split = est->check_rows;
        if (row0 < split && split < row1) { /* the check's factor is the one of the rows before it */
            stage_rows(est, slot, row0, split);
            memcpy(est->R_check, est->R, (size_t)sum_unknowns(tb, 2) * sizeof(duffid_real));
            stage_rows(est, slot, split, row1);
        } else {
            stage_rows(est, slot, row0, row1);
            if (row1 == split) {
                memcpy(est->R_check, est->R, (size_t)sum_unknowns(tb, 2) * sizeof(duffid_real));
            }
        }
        est->stage++;
        return 0;
    }
    if (est->stage < est->stages - 1) { /* the factors' inverses, then their condition numbers */
        solve_conditions(est, est->stage == est->stages - 2);
        est->stage++;
        return 0;
    }
    solve_unknowns(est); /* (the slot is free from here: its position is past the window) */
    est->pending = -1;
    est->stage = 0;
    return 1;
}

static void report(const duffid_buffered *est, int solved, duffid_buffered_output *out)
{
    int i;
    out->t = (duffid_real)est->n * est->cfg.dt;
    out->n_parameters = est->tb->n_parameters;
    for (i = 0; i < out->n_parameters; i++) { /* (the entries beyond are not written) */
        out->current[i] = est->current[i];
        out->parameters[i] = est->identified ? est->current[i] : R_NAN;
    }
    out->identified = est->identified;
    out->solved = solved;
    out->windows = est->windows;
    out->condition = est->condition;
    out->uncertainty = est->uncertainty;
    out->window = est->windows > 0 ? (duffid_real)est->N * est->cfg.dt : RC(0.0);
}

int duffid_buffered_update(duffid_buffered *est, const duffid_real *x, const duffid_real *f,
                           duffid_buffered_output *out)
{
    const duffid_buffered_tables *tb;
    duffid_real g[DUFFID_MAX_CHANNELS];
    int i, solved = 0;
    if (est == NULL || x == NULL || (f == NULL && est->tb->n_forces > 0)) {
        return DUFFID_ERR_ARGUMENT;
    }
    tb = est->tb;
    for (i = 0; i < tb->n_dof; i++) {
        if (!is_finite(x[i])) {
            return DUFFID_ERR_SAMPLE;
        }
    }
    for (i = 0; i < tb->n_forces; i++) {
        if (!is_finite(f[i])) {
            return DUFFID_ERR_SAMPLE;
        }
    }
    est->n++;
    if (est->have_last) { /* the sign of velocity from position increments, held inside the deadband */
        for (i = 0; i < tb->n_dof; i++) {
            const duffid_real dx = x[i] - est->last_x[i];
            if (R_FABS(dx) > est->cfg.deadband) {
                est->sign[i] = dx > RC(0.0) ? RC(1.0) : (dx < RC(0.0) ? RC(-1.0) : RC(0.0));
            }
        }
    }
    for (i = 0; i < tb->n_dof; i++) {
        est->last_x[i] = x[i];
    }
    est->have_last = 1;
    for (i = 0; i < est->n_ch; i++) {
        g[i] = channel_value(est, &tb->channels[i], x, f);
    }
    if (est->until_start == 0) { /* a window starts at this sample */
        const int slot = est->next_slot;
        memset(est->coef + (size_t)slot * (size_t)(est->n_ord * est->n_ch * est->r), 0,
               (size_t)(est->n_ord * est->n_ch * est->r) * sizeof(duffid_real));
        memset(est->sumsq + slot * est->n_ch, 0, (size_t)est->n_ch * sizeof(duffid_real));
        est->pos[slot] = 0;
        est->next_slot = slot + 1 == est->n_slots ? 0 : slot + 1;
        est->until_start = est->every;
    }
    est->until_start--;
    if (est->pending >= 0) { /* one stage of the window that ended before this sample */
        solved = solve_stage(est);
    }
    for (i = 0; i < est->n_slots; i++) {
        if (est->pos[i] >= 0 && est->pos[i] <= est->N && i != est->pending) {
            accumulate(est, i, est->pos[i], g);
            if (est->pos[i] == est->N) { /* complete: solved over the next samples */
                est->pending = i;
                est->stage = 0;
                while (est->immediate && !solved) {
                    solved = solve_stage(est);
                }
            }
            est->pos[i]++;
        }
    }
    if (out != NULL) {
        report(est, solved, out);
    }
    return DUFFID_OK;
}

long duffid_buffered_latency(const duffid_buffered *est)
{
    return est != NULL && !est->immediate ? (long)est->stages : 0L;
}

size_t duffid_buffered_output_size(void)
{
    return sizeof(duffid_buffered_output);
}

size_t duffid_buffered_config_size(void)
{
    return sizeof(duffid_buffered_config);
}
