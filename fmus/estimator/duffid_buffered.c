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
 *
 * The noise errors (BufferedIdentifier.noise_products): a noise e_s on measured signal j (a
 * displacement or a force) at the window's sample s moves the residual A theta - D by e_s m_s,
 *     m_s = sum_m c_m(s) y_m(s),  y_m(s) = (P_m^T Q[s])[kept],
 *     c_m(s) = sum over n - d + k = m of T^-d alpha_dk (s/N)^(n-k) J_d(s),
 *     J_d(s) = sum_c w[d, c] dg_c/dx_j (s),  w = lhs theta - rhs,
 * and the unknowns by G^-1 A^T m_s (G = A^T A): their variance sums sigma_j^2 (G^-1 A^T m_s)^2
 * over the samples, with sigma_j the signal's noise level at the window's last sample.
 * The window's displacements are kept for that (a ring of N + 1 + stages samples), and
 * A^T m_s = sum_m c_m(s) Z_m^T Q[s] with Z_m = P_m[:, kept] A formed as the rows are; the sum
 * is spread over the stages after the unknowns.
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
    duffid_real *U, *Rinv, *scale; /* per equation: the equilibrated factor, its inverse, the column scales */
    duffid_real *eq_cond;       /* per equation: its condition number (infinite: singular or held) */
    int *eq_state;              /* per equation: SOLVABLE, SINGULAR or HELD (no known term) */
    duffid_real *V;     /* per equation: unknowns x unknowns, the Jacobi iteration's start */
    int *warm;          /* per equation */
    duffid_real *held;  /* per equation: its unknowns of the latest solved window */
    duffid_real *Z;     /* per equation: Z_m = P_m[:, kept] A (m = 0..n, each r x n; P_0 = I), as
                         * r rows of (n + 1) n: Z[j * (n + 1) n + m * n + u] */
    duffid_real *weight; /* per equation: n_ord x n_ch, its weights w = lhs theta - rhs */
    duffid_real *K;     /* per equation: n x n, G^-1 = (A^T A)^-1 */
    duffid_real *zq;    /* per equation: (n + 1) n, Q[s]^T Z of one sample */
    duffid_real *resid, *moved, *var; /* per unknown: the residual's relative error, the check's
                                       * difference, the noise's variance */
    duffid_real *ring;  /* ring_size x n_dof: the latest displacements */
    long ring_size;
    int *offset;        /* per equation: first unknown in held, first square in V, first in R, first
                         * column in norm2 / bound2 */
    int chunk;          /* rows per stage */
    int row_stages;     /* stages of the row chunks */
    int noise_chunk;    /* window samples per stage of the noise errors */
    int stages;         /* stages of a window's solve: row chunks, the conditions, the unknowns, the
                         * noise errors (the last one also the verdict) */
    int immediate;      /* 1: all stages at the window's last sample (every < 5) */
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
    duffid_la_noise_level noise_level, force_level; /* the displacements' and the forces' */
    long ring_pos;                      /* the ring's slot of the latest sample */
    long window_ring;                   /* ... of the pending window's first sample */
    duffid_real window_sigma[DUFFID_MAX_DOF + DUFFID_MAX_FORCES]; /* the noise levels at its last
                                                                  * sample: displacements, forces */
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

/* Rows and window samples per stage of a window's solve: a window's per-window work (its row
 * entries, the factor's update, its noise errors) is spread over the samples after its end, a
 * chunk of rows or of samples per update, so that every update stays within a fixed bound. */
#define ROWS_PER_STAGE 1
#define SAMPLES_PER_STAGE 2

static long every_of(const duffid_buffered_config *cfg)
{
    return cfg->every > 0 ? cfg->every : cfg->tables->n_intervals;
}

/* a window's solve: `rows` chunks of rows, the factors' inverses, their condition numbers, the
 * unknowns, then `noise` chunks of samples; in all at most every (a window ends every `every`
 * samples: its solve is done before the next ends), and when fewer than 5 fit, one of each at
 * the window's last sample (immediate) */
typedef struct {
    int rows, noise, immediate; /* row stages, noise stages, all at the window's last sample */
    int stages;                 /* rows + 3 + noise */
    int chunk, noise_chunk;     /* rows and window samples per stage */
} stage_plan;

static stage_plan plan_of(const duffid_buffered_config *cfg)
{
    const long kept = cfg->tables->n_kept, samples = cfg->tables->n_intervals + 1, budget = every_of(cfg) - 3;
    const long rows = (kept + ROWS_PER_STAGE - 1) / ROWS_PER_STAGE;
    const long noise = (samples + SAMPLES_PER_STAGE - 1) / SAMPLES_PER_STAGE;
    stage_plan plan;
    plan.immediate = budget < 2;
    if (budget < 2) {
        plan.rows = plan.noise = 1;
    } else if (rows + noise <= budget) {
        plan.rows = (int)rows;
        plan.noise = (int)noise;
    } else { /* shared in proportion */
        long r = budget * rows / (rows + noise);
        r = r < 1 ? 1 : (r > budget - 1 ? budget - 1 : r);
        plan.rows = (int)r;
        plan.noise = (int)(budget - r);
    }
    plan.stages = plan.rows + 3 + plan.noise;
    plan.chunk = (int)((kept + plan.rows - 1) / plan.rows);
    plan.noise_chunk = (int)((samples + plan.noise - 1) / plan.noise);
    return plan;
}

static long ring_of(const duffid_buffered_config *cfg)
{
    return cfg->tables->n_intervals + 1 + plan_of(cfg).stages;
}

static long slots_of(const duffid_buffered_config *cfg)
{
    /* windows open at once, and the one being solved: a slot is reused once its solve is done */
    const long N = cfg->tables->n_intervals, every = every_of(cfg);
    const stage_plan plan = plan_of(cfg);
    return (N + (plan.immediate ? 1 : plan.stages) + every - 1) / every;
}

/* the block after the structure; base NULL: sizes only */
static size_t layout(const duffid_buffered_config *cfg, duffid_buffered *est, char *base)
{
    const duffid_buffered_tables *tb = cfg->tables;
    const long slots = slots_of(cfg);
    const int n_ord = tb->order + 1, n_ch = tb->n_channels, r = tb->n_terms;
    const int p = max_unknowns_of(tb) + 1, n_eq = tb->n_equations;
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
    CARVE(&c, est->E, plan_of(cfg).chunk * n_ord * n_ch);
    CARVE(&c, est->B, plan_of(cfg).chunk * p);
    CARVE(&c, est->R, sum_unknowns(tb, 2));
    CARVE(&c, est->R_check, sum_unknowns(tb, 2));
    CARVE(&c, est->check, (p - 1) * (2 * p + 1));
    CARVE(&c, est->norm2, sum_unknowns(tb, 3));
    CARVE(&c, est->bound2, sum_unknowns(tb, 3));
    CARVE(&c, est->U, sum_unknowns(tb, 1));
    CARVE(&c, est->Rinv, sum_unknowns(tb, 1));
    CARVE(&c, est->scale, sum_unknowns(tb, 0));
    CARVE(&c, est->eq_cond, n_eq);
    CARVE(&c, est->eq_state, n_eq);
    CARVE(&c, est->V, sum_unknowns(tb, 1));
    CARVE(&c, est->warm, n_eq);
    CARVE(&c, est->held, sum_unknowns(tb, 0));
    CARVE(&c, est->Z, n_ord * r * sum_unknowns(tb, 0));
    CARVE(&c, est->weight, n_eq * n_ord * n_ch);
    CARVE(&c, est->K, sum_unknowns(tb, 1));
    CARVE(&c, est->zq, n_ord * sum_unknowns(tb, 0));
    CARVE(&c, est->resid, sum_unknowns(tb, 0));
    CARVE(&c, est->moved, sum_unknowns(tb, 0));
    CARVE(&c, est->var, sum_unknowns(tb, 0));
    CARVE(&c, est->ring, ring_of(cfg) * tb->n_dof);
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
    duffid_la_noise_reset(&est->noise_level);
    duffid_la_noise_reset(&est->force_level);
    memset(est->ring, 0, (size_t)(est->ring_size * tb->n_dof) * sizeof(duffid_real));
    est->ring_pos = -1;
    est->window_ring = 0;
    for (i = 0; i < DUFFID_MAX_DOF + DUFFID_MAX_FORCES; i++) {
        est->window_sigma[i] = RC(0.0);
    }
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
    {
        const stage_plan plan = plan_of(cfg);
        est->chunk = plan.chunk;
        est->noise_chunk = plan.noise_chunk;
        est->row_stages = plan.rows;
        est->stages = plan.stages;
        est->immediate = plan.immediate;
    }
    est->check_rows = (int)(RC(DUFFID_BUFFERED_CHECK_SHARE) * (duffid_real)tb->n_kept);
    est->ring_size = ring_of(cfg);
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
    { /* the rows' A into Z_m (the noise errors) */
        const int r = est->r, kept = tb->n_kept, L = n_ord * n;
        duffid_real *Z = est->Z + (size_t)(n_ord * r) * (size_t)est->offset[4 * e];
        int col, mm, j;
        for (row = 0; row < m; row++) {
            const int rho = row0 + row;
            for (col = 0; col < n; col++) {
                const duffid_real a = est->B[col * m + row];
                Z[tb->kept[rho] * L + col] = a;
                for (mm = 1; mm <= tb->order; mm++) {
                    const int *start = tb->p_start + (mm - 1) * (kept + 1);
                    for (j = start[rho]; j < start[rho + 1]; j++) {
                        Z[tb->p_index[j] * L + mm * n + col] += tb->p_value[j] * a;
                    }
                }
            }
        }
    }
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
 * equation e's first check_rows rows against theta, their relative difference into moved
 * (infinite where that estimate is undetermined) */
static void check_basis(duffid_buffered *est, int e, const duffid_real *theta, duffid_real *moved)
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
        moved[i] = solved && theta[i] != RC(0.0) ? R_FABS((first[i] - theta[i]) / theta[i]) : R_INF;
    }
}

/* BufferedIdentifier.solve_window's unknowns and the residual's errors from the conditions, the
 * check's differences; the weights w and G^-1 of the noise errors, whose variances start at 0 */
static void solve_unknowns(duffid_buffered *est)
{
    const duffid_buffered_tables *tb = est->tb;
    const int n_ord = est->n_ord, n_ch = est->n_ch;
    int e, i, k;
    for (e = 0; e < tb->n_equations; e++) {
        const int n = tb->n_unknowns[e], o = est->offset[4 * e];
        duffid_real *held = est->held + o, *w = est->weight + e * n_ord * n_ch, *K = est->K + est->offset[4 * e + 1];
        if (est->eq_state[e] == HELD) {
            continue;
        }
        for (i = 0; i < n; i++) {
            est->var[o + i] = RC(0.0);
        }
        if (est->eq_state[e] == SINGULAR) {
            for (i = 0; i < n; i++) {
                held[i] = R_NAN;
                est->resid[o + i] = est->moved[o + i] = R_INF;
            }
            continue;
        }
        duffid_la_factor_unknowns(n, est->R + est->offset[4 * e + 2], (duffid_real)tb->n_kept, RC(1.0),
                                  est->scale + o, est->Rinv + est->offset[4 * e + 1], held, est->resid + o);
        check_basis(est, e, held, est->moved + o);
        memset(w, 0, (size_t)(n_ord * n_ch) * sizeof(duffid_real));
        for (k = 0; k < tb->n_model_terms; k++) {
            const duffid_buffered_term *t = &tb->terms[k];
            if (t->equation == e) {
                w[t->order * n_ch + t->channel] += t->unknown >= 0 ? t->coef * held[t->unknown] : -t->coef;
            }
        }
        { /* G^-1 = R^-1 R^-T, R^-1 = diag(1 / scale) Rinv (Rinv: the equilibrated factor's) */
            const duffid_real *Rinv = est->Rinv + est->offset[4 * e + 1], *scale = est->scale + o;
            int a, b;
            for (a = 0; a < n; a++) {
                for (b = 0; b < n; b++) {
                    duffid_real sum = RC(0.0);
                    for (k = (a > b ? a : b); k < n; k++) {
                        sum += Rinv[a * n + k] * Rinv[b * n + k];
                    }
                    K[a * n + b] = sum / (scale[a] * scale[b]);
                }
            }
        }
    }
}

/* the derivative of a channel by measured signal j (displacements 0..n_dof - 1, then the
 * forces) at the displacements x (0: not of that signal) */
static duffid_real channel_slope(const duffid_buffered_channel *ch, int j, int n_dof, const duffid_real *x)
{
    duffid_real v, sign, out = RC(1.0);
    int i;
    if (j >= n_dof) {
        return ch->kind == DUFFID_BUF_FORCE && ch->index == j - n_dof ? RC(1.0) : RC(0.0);
    }
    if (ch->kind == DUFFID_BUF_X && ch->index == j) {
        v = x[j];
        sign = RC(1.0);
    } else if (ch->kind == DUFFID_BUF_DEFLECTION && (ch->index == j || ch->index - 1 == j)) {
        v = x[ch->index] - (ch->index > 0 ? x[ch->index - 1] : RC(0.0));
        sign = ch->index == j ? RC(1.0) : RC(-1.0);
    } else {
        return RC(0.0);
    }
    for (i = 1; i < ch->power; i++) {
        out *= v;
    }
    return sign * (duffid_real)ch->power * out;
}

/* the noise errors' variances over the pending window's samples [s0, s1): for each solvable
 * equation the products zq = Q[s]^T Z (the same for every signal), then for each measured
 * signal with a noise level that the equation's channels depend on, c_m, v = sum_m c_m zq_m
 * and (G^-1 v)^2 sigma^2 */
static void noise_samples(duffid_buffered *est, long s0, long s1)
{
    const duffid_buffered_tables *tb = est->tb;
    const int r = est->r, n_ord = est->n_ord, n_ch = est->n_ch, n = tb->order, n_src = tb->n_dof + tb->n_forces;
    long s;
    int rho, m, j, e, d, k, c, u;
    for (s = s0; s < s1; s++) {
        const duffid_real *q = tb->Q + (size_t)s * (size_t)r, sn = (duffid_real)(int)s / (duffid_real)(int)est->N;
        long slot = est->window_ring + s;
        const duffid_real *x;
        duffid_real sp[MAX_ORD];
        slot = slot >= est->ring_size ? slot - est->ring_size : slot;
        x = est->ring + slot * tb->n_dof;
        for (m = 0, sp[0] = RC(1.0); m < n; m++) {
            sp[m + 1] = sp[m] * sn;
        }
        for (e = 0; e < tb->n_equations; e++) {
            const int ne = tb->n_unknowns[e], L = n_ord * ne;
            const duffid_real *Z = est->Z + (size_t)(n_ord * r) * (size_t)est->offset[4 * e];
            duffid_real *zq = est->zq + n_ord * est->offset[4 * e];
            int mu;
            if (est->eq_state[e] != SOLVABLE) {
                continue;
            }
            for (mu = 0; mu < L; mu += 4) { /* zq = Q[s]^T Z, four columns at a time (one load of Q) */
                const duffid_real *z = Z + mu;
                duffid_real a0 = RC(0.0), a1 = RC(0.0), a2 = RC(0.0), a3 = RC(0.0);
                if (L - mu >= 4) {
                    for (rho = 0; rho < r; rho++, z += L) {
                        const duffid_real qr = q[rho];
                        a0 += qr * z[0];
                        a1 += qr * z[1];
                        a2 += qr * z[2];
                        a3 += qr * z[3];
                    }
                    zq[mu + 3] = a3;
                    zq[mu + 2] = a2;
                    zq[mu + 1] = a1;
                } else {
                    for (k = mu; k < L; k++) {
                        duffid_real sum = RC(0.0);
                        for (rho = 0; rho < r; rho++) {
                            sum += q[rho] * Z[rho * L + k];
                        }
                        zq[k] = sum;
                    }
                    a0 = zq[mu];
                }
                zq[mu] = a0;
            }
        }
        for (j = 0; j < n_src; j++) {
            const duffid_real sigma2 = est->window_sigma[j] * est->window_sigma[j];
            duffid_real slope[DUFFID_MAX_CHANNELS];
            int any = 0;
            if (!(sigma2 > RC(0.0))) {
                continue;
            }
            for (c = 0; c < n_ch; c++) {
                slope[c] = channel_slope(&tb->channels[c], j, tb->n_dof, x);
                any |= slope[c] != RC(0.0);
            }
            for (e = 0; any && e < tb->n_equations; e++) {
                const int ne = tb->n_unknowns[e], o = est->offset[4 * e];
                const duffid_real *w = est->weight + e * n_ord * n_ch, *K = est->K + est->offset[4 * e + 1],
                                  *zq = est->zq + n_ord * o;
                duffid_real cm[MAX_ORD], v[MAX_UNK];
                int moves = 0;
                if (est->eq_state[e] != SOLVABLE) {
                    continue;
                }
                for (m = 0; m <= n; m++) {
                    cm[m] = RC(0.0);
                }
                for (d = 0; d <= n; d++) { /* J_d, into c_m for m = n - d + k */
                    duffid_real J = RC(0.0);
                    for (c = 0; c < n_ch; c++) {
                        J += w[d * n_ch + c] * slope[c];
                    }
                    moves |= J != RC(0.0);
                    J *= est->t_inv[d];
                    for (k = 0; k <= d; k++) {
                        cm[n - d + k] += est->alpha[d * n_ord + k] * sp[n - k] * J;
                    }
                }
                if (!moves) {
                    continue;
                }
                for (u = 0; u < ne; u++) { /* v = A^T m_s = sum_m c_m zq_m */
                    v[u] = RC(0.0);
                    for (m = 0; m <= n; m++) {
                        v[u] += cm[m] * zq[m * ne + u];
                    }
                }
                for (u = 0; u < ne; u++) { /* (G^-1 v)_u^2 sigma^2 */
                    duffid_real delta = RC(0.0);
                    for (k = 0; k < ne; k++) {
                        delta += K[u * ne + k] * v[k];
                    }
                    est->var[o + u] += sigma2 * delta * delta;
                }
            }
        }
    }
}

/* BufferedIdentifier.solve_window's errors and verdict: each relative error the larger of the
 * residual's and the noise's, with the check's difference in quadrature */
static void solve_verdict(duffid_buffered *est)
{
    const duffid_buffered_tables *tb = est->tb;
    duffid_real cond = RC(0.0), worst = RC(0.0);
    int e, i, all_finite = 1;
    for (e = 0; e < tb->n_equations; e++) {
        const int n = tb->n_unknowns[e], o = est->offset[4 * e];
        const duffid_real c = est->eq_cond[e], rounding = rows_rounding(est, e);
        if (est->eq_state[e] == HELD) {
            cond = R_INF;
            worst = R_INF;
            continue;
        }
        cond = c > cond ? c : cond;
        for (i = 0; i < n; i++) {
            const duffid_real theta = est->held[o + i], moved = est->moved[o + i];
            duffid_real rse = est->resid[o + i];
            if (est->eq_state[e] == SOLVABLE) {
                const duffid_real noise = theta != RC(0.0) ? R_SQRT(est->var[o + i]) / R_FABS(theta) : R_INF;
                rse = noise > rse ? noise : rse;
            }
            rse = is_finite(moved) ? duffid_la_hypot(rse, moved) : R_INF;
#if DUFFID_SINGLE
            rse = duffid_la_hypot(rse, rounding * c);
#else
            (void)rounding;
#endif
            worst = rse > worst ? rse : worst;
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
        memset(est->Z, 0, (size_t)(est->n_ord * est->r * sum_unknowns(tb, 0)) * sizeof(duffid_real));
    }
    if (est->stage < est->row_stages) {
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
    if (est->stage < est->row_stages + 2) { /* the factors' inverses, then their condition numbers */
        solve_conditions(est, est->stage == est->row_stages + 1);
        est->stage++;
        return 0;
    }
    if (est->stage == est->row_stages + 2) {
        solve_unknowns(est);
        est->stage++;
        return 0;
    }
    { /* the noise errors over a chunk of the window's samples */
        const long s0 = (long)(est->stage - est->row_stages - 3) * est->noise_chunk;
        const long s1 = s0 + est->noise_chunk < est->N + 1 ? s0 + est->noise_chunk : est->N + 1;
        if (s0 < s1) {
            noise_samples(est, s0, s1);
        }
    }
    if (++est->stage < est->stages) {
        return 0;
    }
    solve_verdict(est); /* (the slot is free from here: its position is past the window) */
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
    duffid_la_noise_push(&est->noise_level, tb->n_dof, x); /* the noise levels, the ring */
    duffid_la_noise_push(&est->force_level, tb->n_forces, f);
    est->ring_pos = est->ring_pos + 1 == est->ring_size ? 0 : est->ring_pos + 1;
    for (i = 0; i < tb->n_dof; i++) {
        est->ring[est->ring_pos * tb->n_dof + i] = x[i];
    }
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
                int j;
                est->pending = i;
                est->stage = 0;
                est->window_ring = est->ring_pos - est->N < 0 ? est->ring_pos - est->N + est->ring_size
                                                               : est->ring_pos - est->N;
                for (j = 0; j < tb->n_dof; j++) {
                    est->window_sigma[j] = duffid_la_noise_sigma(&est->noise_level, j);
                }
                for (j = 0; j < tb->n_forces; j++) {
                    est->window_sigma[tb->n_dof + j] = duffid_la_noise_sigma(&est->force_level, j);
                }
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
