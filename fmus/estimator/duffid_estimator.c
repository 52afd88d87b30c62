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
 * The per-sample work is fixed and O(unknowns^2 + degree x channels) (the online update at its
 * arithmetic floor; see fmus/estimator/README.md for the measured cost):
 *   - the window's moments are kept in the falling-factorial basis (i)_j / N^j, in which the
 *     shift by one sample is bidiagonal with positive coefficients (O(degree) per channel,
 *     no cancellation, no per-sample powers), and converted to the power moments of Python
 *     by the positive Stirling matrix once per sample;
 *   - the kernel's polynomials are evaluated over their non-zero powers only;
 *   - the condition number comes from a one-sided Jacobi iteration started from the previous
 *     sample's right singular vectors (one or two sweeps), the unknowns and their errors
 *     from the inverse of the triangular factor (no SVD per sample);
 *   - the ring buffer is indexed by a running position, not a 64-bit remainder.
 * The results equal Python's to rounding (tests/test_estimator_c.py). All memory is one
 * block sized from the configuration: the model's own counts, the window and the rows.
 */
#include "duffid_estimator.h"
#include "duffid_linalg.h"

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
#define MAX_LINE DUFFID_MAX_LINE_UNKNOWNS /* unknowns of a block whose unknowns are lines in time */
typedef char line_unknowns_fit[MAX_LINE <= MAX_UNK ? 1 : -1]; /* the workspaces are sized by MAX_UNK */
#define MAX_EQ DUFFID_MAX_BLOCKS
#define MAX_ORDER DUFFID_MAX_DERIVATIVE /* derivative orders 0..2 */
#define N_ORD (MAX_ORDER + 1)
#define MAX_DEG (DUFFID_MAX_ROWS + 5) /* highest moment power (the kernels' + 1: KernelBank.within) */
#define MAX_POW (MAX_DEG + 1)
#define MAX_CORR (2 * DUFFID_GREGORY_POINTS) /* quadrature end corrections */
#define MAX_RATE (2 * MAX_CORR + 1)  /* ... of the rule minus the half-rate rule (engine.RATE_NOISE) */
#define NEAR (DUFFID_GREGORY_POINTS + 1) /* a raw ring's newest samples whose channels are kept */
#define MIN_SAMPLES DUFFID_MIN_SAMPLES  /* engine.MIN_SAMPLES (duffid_facts.h) */
#define MAX_CAPACITY 100000000L      /* longest robust window in samples */
#define ANY_SIGN (DUFFID_ALLOW_POSITIVE | DUFFID_ALLOW_ZERO | DUFFID_ALLOW_NEGATIVE)
/* the built-in models' largest description (Duffing2 with offsets) */
#define BUILTIN_BLOCKS 2
#define BUILTIN_TERMS 24
#define BUILTIN_RULES 4
#define BUILTIN_LINEAR 8
#define BUILTIN_PARAMS 10

/* duffid_la_solve_factor's limit (duffid_linalg.h) */
#define COND_SINGULAR DUFFID_LA_COND_SINGULAR
#if DUFFID_SINGLE
/* Shadow accumulators of the sliding moments, started a window / SHADOWS apart: the main one is
 * replaced when a shadow holds exactly the window, so no accumulator lives longer than
 * (1 + 1/SHADOWS) windows, and the rounding errors of its first samples, which the shift
 * amplifies by up to (age / window)^degree, stay small (2^degree with one shadow: fine in
 * double, a 1e-4 moment error in float). */
#define SHADOWS 4
/* Single precision: the rounding of the moments and rows is part of each unknown's standard
 * error, so that what float arithmetic cannot determine is not published. A row entry is a
 * sum of moments that cancel (the kernel's alternating coefficients): its rounding error is
 * about eps sqrt(L) times the sum of the magnitudes of its terms (L samples in the moments'
 * sums), and an unknown's relative error about the condition number times the rows' relative
 * error; this factor scales that estimate. Calibrated on benchmarks/trust.py's records
 * (benchmarks/embedded.py's accuracy table, tests/test_float_core.py): at 1/16 a value the
 * float build published was 1.02 of its stated uncertainty away from the double build's; at
 * 1/4 the largest is 0.21 of it. */
#define ARITHMETIC_FACTOR RC(0.25)
#else
#define SHADOWS 1 /* regressors.SlidingMoments' one shadow */
#endif

static const duffid_real PI = RC(3.141592653589793238462643383279502884);

/* channel kinds of the built-in models (a generated model computes its channels itself) */
enum { CH_X = 0, CH_DEFL = 1, CH_FORCE = 2, CH_ONE = 3 };
/* canonical parameters of the built-in chains: id = 4 * dof + kind, offsets 4 * n_dof + dof */
enum { P_M = 0, P_B = 1, P_K1 = 2, P_K3 = 3 };

typedef struct {
    int kind, index, power;
} channel_t;

/* a block of the description at run time: its terms and rules are ranges of the model's */
typedef struct {
    int n_unknowns, n_parts, n_terms, forced, n_rules, term0, rule0;
} block_t;

typedef struct {
    int part, unknown, channel, order;
    duffid_real coef;
} term_t;

/* The model at run time: its counts, and its tables in the estimator's memory block (sized
 * to the model: a description holds only what the model has). */
typedef struct {
    int n_dof, n_forces, n_channels, max_order, n_blocks, n_params;
    int n_terms, n_rules, linear, n_mass, n_stiffness, channel_work, uses_sign;
    char signature[DUFFID_SIGNATURE_SIZE];
} model_counts;

typedef struct {
    model_counts c;
    block_t *blocks;
    term_t *terms;
    duffid_rule *rules;
    duffid_parameter *params;   /* canonical order; NULL while only counting */
    duffid_public *publics;     /* public order; NULL while only counting */
    duffid_linear *mass, *stiffness;
    channel_t *ch;              /* built-in models: what each channel is */
} rt_model;

typedef struct {
    int n_in, depth;   /* inputs and integrator depth (y has depth + 1 levels) */
    duffid_real *y, *p1, *p2;
    int count;         /* samples pushed, saturated at 2 */
} integrators_t;

/* the parts of a block's score carve (engine.BATCH_WINDOWS) */
#define LAST_SCORE(eq) ((eq)->score + (eq)->line_cap)
#define SCORES(eq) ((eq)->score + 2 * (eq)->line_cap)
#define NOMINAL(eq) ((eq)->score + (eq)->line_cap * ((eq)->line_cap + 2))

typedef struct { /* the state of one block of the description */
    duffid_real *theta, *rse, *share; /* n_unknowns each */
    duffid_real *R;                   /* robust: accumulated factor of [A D], p x p (p = n_line + 1) */
    duffid_real *V;                   /* right singular vectors of the last solve (warm start) */
    duffid_real *R_recent;            /* the change test's recent factor (p x p) */
    /* engine.DriftLine: after a change, the departed unknowns are lines in time */
    int n_line;                       /* unknowns of the accumulated least squares: n + the lines */
    int line_cap;                     /* ... at most (the block's factors are sized for it) */
    int *drifting;                    /* n: 1 if unknown i is a line (its rate: the next unknown) */
    int64_t origin;                   /* the sample whose rows have time 0 */
    duffid_real *line, *line_inv;     /* accumulated: the unknowns (values at 0, then the rates),
                                       * C = U^-1 / scale row-wise (n_line x n_line) */
    duffid_real *line_recent, *line_recent_inv; /* ... the recent least squares' */
    duffid_real line_sigma, line_recent_sigma, times_recent; /* residual scales; the recent
                                       * rows' times, weighted as the rows */
    duffid_real *departure;           /* n: recent - accumulated solution in combined errors */
    /* engine.DRIFT_SIGMAS: the drift probe, a line for each of the first probe_n unknowns */
    int probe_n;                      /* its lines (0: none); its factor is (n + probe_n + 1)^2 */
    duffid_real *R_probe;             /* its accumulated factor of [A, t A_0.., D] (one row a sample) */
    duffid_real rows_probe;           /* its rows (weighted as the accumulated ones) */
    duffid_real times_probe;          /* ... their times, weighted as the rows */
    duffid_real *drift_shift;         /* n: its drift from the rows' mean time to now beyond
                                       * DUFFID_DRIFT_BIAS_SIGMAS (engine.DRIFT_BIAS_SIGMAS) */
    int64_t probed;                   /* samples it has found a drift in a row, saturated at settle */
    int probe_row;                    /* the row of the block's it takes next */
    /* engine.OFFSET_SIGMAS: the offset probe, the rows with an unknown constant force */
    int off_on;                       /* 1: it runs (a block of one part without a constant) */
    duffid_real *R_off;               /* its accumulated factor of [A, 1, D], (n + 2)^2 (one row a sample) */
    duffid_real rows_off;             /* its rows (weighted as the accumulated ones) */
    int off_row;                      /* the row of the block's it takes next */
    int *off_moved;                   /* n: 1 while a constant force moves unknown i beyond max_uncertainty */
    duffid_real R_var[4];             /* its rows' factor of [1, D]: does D vary (DUFFID_FORCE_VARIATION)? */
    /* engine.JUMP_ERROR: the rows' error column J on the force jumps inside their windows */
    duffid_real *jump_v;              /* n_line: A^T J of the accumulated rows (with their forgetting) */
    duffid_real *jump_shift;          /* n: how J moves the unknowns, (A^T A)^-1 A^T J (at the newest rows) */
    /* engine.RATE_NOISE: the rows' change Q at half the rate (the rule on every second sample) */
    duffid_real *rate_v;              /* n_line: A^T Q of the accumulated rows (with their forgetting) */
    duffid_real *rate_shift;          /* n: how Q moves the unknowns (at the newest rows) */
    /* row_noise: the rows' noise dA, dD (the channels' change under the displacements' noise) */
    duffid_real *noise_G;             /* n_line x (n_line + 1): dA^T [dA dD] of the accumulated rows
                                       * (with their forgetting) */
    duffid_real *noise_G_recent;      /* ... of the change test's recent rows */
    duffid_real *noise_shift;         /* n: how it moves the unknowns (row_noise.noise_shift) */
    /* engine.BATCH_WINDOWS: the accumulated rows' scores A^T r by blocks of a window */
    duffid_real *score;               /* line_cap: the open block's; then (LAST_SCORE, SCORES,
                                       * NOMINAL) line_cap: the last closed one's, line_cap^2:
                                       * the closed blocks' products with their neighbours', n: the
                                       * residual's relative errors (the change test's) */
    duffid_real scored, blocks;       /* the rows the closed blocks hold, and the blocks (weighted as the rows) */
    int block;                        /* samples in the open block */
    duffid_real cond, rhs_share, rows, rows_recent, residual;
    int64_t departed;                 /* samples the departure has mattered in a row, saturated
                                       * at settle */
    int64_t surprised;                /* ... the prediction error surprising, the same */
    int64_t drifted;                  /* ... a smaller departure beyond the band, saturated at
                                       * the recent memory */
    int64_t resume;                   /* after a change: the first sample whose window follows it */
    int64_t recent_resume;            /* ... after a surprise: the same for the recent estimate */
    duffid_real rounding;             /* float: the rows' relative rounding error (their average) */
    int warm;                         /* V is from the previous sample */
    integrators_t reg, det;           /* paper */
} equation_t;

struct duffid_estimator {
    duffid_config cfg;
    rt_model m;
    int n_dof, n_forces, n_params, n_ch, n_eq;
    int n_mom;                             /* channels of the moments: the model's n_ch, then n_noise
                                            * of the rows' noise (row_noise; robust only) */
    int n_noise;
    int noise_of[MAX_CH];                  /* a model channel's noise channel (moments), -1: none */
    equation_t eq[MAX_EQ];
    /* derived from the configuration at init (the "structure": duffid_check_state compares it) */
    duffid_real dt, max_condition, max_uncertainty, min_time, deadband;
    duffid_real *nominal;                  /* canonical order, |prior size| (0: none) */
    long capacity;
    int auto_window;
    int n_rows, degree;
    duffid_real lam, sqrt_lam, inv_cap;
    duffid_real change_threshold;          /* 0: no change test */
    int64_t settle_count;
    int row_a[DUFFID_MAX_ROWS], row_b[DUFFID_MAX_ROWS], raw_b[DUFFID_MAX_ROWS];
    duffid_real norm[DUFFID_MAX_ROWS];
    int norm_power[DUFFID_MAX_ROWS];
    duffid_real d_scale[N_ORD];
    int k_first[DUFFID_MAX_ROWS * N_ORD], k_count[DUFFID_MAX_ROWS * N_ORD], k_at[DUFFID_MAX_ROWS * N_ORD];
    int n_coef;
    duffid_real *k_coef;                   /* packed non-zero kernel coefficients */
    int *k_expo;                           /* ... and their powers of tau */
    int n_used, used_order[N_ORD * MAX_CH], used_channel[N_ORD * MAX_CH]; /* what the terms read */
    int n_jobs;                            /* the kernel entries to compute: n_used x n_rows, then */
    int n_noise_jobs;                      /* ... those of the noise channels of the used */
    int *job;                              /* [5 per entry]: poly at, moment at, count, entry, row */
    int *force_channel;                    /* n_forces: the channel that is force j, -1: none */
    duffid_real *stirling;                 /* [k][j] = S2(k, j) N^(j - k) / N: power moments */
    duffid_real *step;                     /* [j] = j / N: the shift in the factorial basis */
    size_t structure_bytes;                /* the block's bytes before the first mutable array */

    /* common state */
    int64_t n;                             /* index of the newest sample, -1 before any */
    int window_fixed;
    int window_capped;                     /* the auto window's longest length holds fewer than
                                            * DUFFID_MIN_WINDOW_PERIODS natural periods */
    int64_t spanned_from;                  /* the rows of full windows span a window from this
                                            * sample (-1 before the first full window) */
    int64_t *steady;                       /* canonical order, saturated at settle_count */
    duffid_real *period_seen;              /* while the auto window grows: a period parameter's latest
                                            * steady value (canonical order; NaN: none yet) */
    duffid_real *anchor;                   /* canonical order: value the estimate stays near */
    int64_t *anchored;                     /* ... since this sample */
    int64_t *settled;                      /* canonical order, saturated at settle_count */
    int64_t *unsettled;                    /* canonical order, saturated at settle_count */
    int *status;                           /* canonical order, DUFFID_STATUS_* */
    int *fresh;                            /* canonical order: restarted since last published */
    int64_t *credible_from;                /* ... and its rows span a window from this sample */
    duffid_real *value;                    /* canonical order: the latest published value */
    int *changed_now;                      /* canonical order: restarted at this sample: -1 no,
                                            * 0 (uncertain) or 1 (changed) */
    duffid_real *held;                     /* public order */
    /* row_noise.NoiseLevel: the displacements' noise level and the generator of the rows' noise */
    uint32_t noise_state;                  /* xorshift32 */
    duffid_la_noise_level noise_level;
    int has_last_x;                        /* signs of velocity (identification._Channels) */
    duffid_real last_x[DUFFID_MAX_DOF], sgn[DUFFID_MAX_DOF];

    /* robust */
    long target;
    int regrow;                             /* after duffid_hold: the window grows again */
    int has_f_prev, has_f_change;           /* force jumps (OnlineIdentifier._force_jumps): */
    duffid_real f_prev[DUFFID_MAX_FORCES];  /* the force of the previous sample processed, */
    duffid_real f_change[DUFFID_MAX_FORCES]; /* the running mean |change| of each force, */
    duffid_real f_peak[DUFFID_MAX_FORCES];  /* the largest |force| seen */
    int has_jump_candidate, has_jump;       /* the previous sample's change when it jumped; the */
    duffid_real jump_candidate[DUFFID_MAX_FORCES]; /* isolated jump before the previous sample */
    duffid_real jump[DUFFID_MAX_FORCES];    /* (DUFFID_JUMP_ISOLATION), 0 for the other forces */
    int64_t n_jumps;                        /* jumps whose interval is inside the window */
    unsigned char *jump_flag;               /* capacity + 2, by ring position: bit j, force j
                                             * jumped in the interval that ends at the sample */
    duffid_real *jump_sum;                  /* (degree + 1) x n_forces: sum df ((n - k + 1/2) / N)^q */
    duffid_real *jump_J;                    /* the rows' error column of a block (workspace) */
    int defer;                              /* duffid_defer_solutions: full windows only accumulate, */
    int row_phase;                          /* ... every defer-th one (0: this one adds its rows) */
    int rows_skipped;                       /* ... this sample's window adds none (no moments) */
    long deferred;                          /* ... the window length whose solve is owed (0: none) */
    duffid_real lam_recent, sqrt_lam_recent; /* the change test's forgetting (follows target) */
    int64_t memory;                         /* ... its memory in samples (a drift lasts it) */
    duffid_real last_L;                     /* the window length of this sample's rows */
    long head;                              /* ring position of the newest sample */
    duffid_real *ring;                      /* (capacity + 2) x ring_width: each sample's raw values (x,
                                             * f, the noisy x) or channels (ring_sample) */
    int ring_raw, ring_width;
    duffid_real *ring_buf;                  /* raw: the channels of MAX_CORR + 1 ring samples (n_mom each) */
    duffid_real *near;                      /* raw: the channels of the NEAR newest samples (n_mom each) */
    int near_head;                          /* ... the newest's slot */
    duffid_real x_now[DUFFID_MAX_DOF], xn_now[DUFFID_MAX_DOF], f_now[DUFFID_MAX_FORCES]; /* the sample
                                             * processed and its noisy x (raw: into the ring) */
    duffid_real *acc, *mom, *fact;          /* (degree + 1) x n_ch each */
    duffid_real *shadow;                    /* SHADOWS of those */
    int64_t start, shadow_from[SHADOWS];    /* first sample of each shadow, -1: not started */
    long poly_L;                            /* cache key of poly/row_scale (-1: empty) */
    duffid_real *poly;                      /* packed like k_coef */
    duffid_real entry_scale[DUFFID_MAX_ROWS * N_ORD], raw_pow[DUFFID_MAX_ROWS];
    long corr_L;                            /* cache key of the corrections (-1: empty) */
    int corr_n, corr_top[MAX_CORR];         /* ... the non-zero extent of each in the basis */
    int corr_near;                          /* the rule's usual shape (moments_push's fast loop): its first
                                             * corr_near offsets are 0, 1, ... (short in the basis) and
                                             * the others full; -1: another */
    long corr_off[MAX_CORR];
    duffid_real *corr_w;                    /* [j][m] (j * MAX_CORR + m): delta_m x the factorial basis
                                             * at its offset */
    /* engine.RATE_NOISE: the window's moments by the rule minus those at half the rate
     * (SlidingMoments.rate_difference) from the alternating sums of the samples */
    duffid_real *acc_alt, *shadow_alt;      /* like acc and shadow, of (-1)^j g[j] */
    duffid_real *dfact, *dmom;              /* the difference, factorial basis and power moments */
    int rate_ok;                            /* this sample has it (a window of 2 intervals or more) */
    long rate_L;                            /* cache key of rate_off and rate_delta (-1: empty) */
    int rate_n;
    long rate_off[MAX_RATE];
    duffid_real rate_delta[MAX_RATE];       /* its weights at those offsets (the basis is not
                                             * stored: memory, issue 28) */
    duffid_real *E_rate;                    /* the difference's kernel entries, like E */
    duffid_real *B_rate;                    /* a block's rows of the difference, like B */
    duffid_real *rate_q;                    /* Q of a block's rows (workspace) */
    duffid_real *B_noise;                   /* a block's rows' noise [dA dD], like B (row_noise) */
    duffid_real *noise_w;                   /* the noise shift's workspace: 3 n x n */
    duffid_real *noise_Gw;                  /* a growing window's rows' noise gram, n x (n + 1) */
    long leave_i;                           /* cache key of leave_phi (-1: empty) */
    duffid_real *leave_phi;                 /* the basis at the offset where samples leave */
    duffid_real *E;                         /* [r][order][channel] */
    long one_L;                             /* cache key of one_E (-1: empty) */
    duffid_real *one_E;                     /* [r]: a constant channel's entries (the offset probe) */
    duffid_real rounding;                   /* float: the rows' relative rounding error at this sample */

    /* workspace of one update (no allocation, no large stack frames) */
    duffid_real *g, *B, *B_copy, *W, *U, *Rinv, *scale, *u_in, *Ap, *Dp, *Aw, *lin;
    duffid_real *canon, *canon_rse, *canon_share;
    duffid_real *canon_steady;              /* canon_rse without the quadrature's bias (RATE_NOISE):
                                             * what the window rule goes by */
    double *chan_work;                      /* a generated channel function's (double) */

    /* isolated outliers (identification._OutlierGuard) */
    int64_t received;                      /* index of the newest sample received */
    duffid_real gh[3 * DUFFID_MAX_DOF];    /* accepted x at n-1, n-2, n-3: [level * n_dof + j] */
    int64_t g_count;
    duffid_real g_mean[DUFFID_MAX_DOF], g_lo[DUFFID_MAX_DOF], g_hi[DUFFID_MAX_DOF], g_step[DUFFID_MAX_DOF];
    int pending;                           /* samples held (0-2): the first suspect, then its glitch's second */
    int64_t p_k;                           /* the first one's index */
    duffid_real p_x[2 * DUFFID_MAX_DOF], p_f[2 * DUFFID_MAX_FORCES], p_threshold[DUFFID_MAX_DOF];
    int p_suspect[DUFFID_MAX_DOF];         /* the first one's suspect columns */
    int p_pair[DUFFID_MAX_DOF];            /* ... whose glitch may last two samples */
    long outliers;
    duffid_real outlier_t, outlier_value, outlier_replaced_by;
    duffid_real outlier_first_value, outlier_first_replaced_by; /* a glitch of two samples: its first */
    int outlier_column;
    duffid_output last;                    /* output after the latest processed sample */

    void *block; /* the malloc'ed block (duffid_create), NULL for caller memory */
};

/* ------------------------------------------------------------------ helpers */
#define set_msg duffid_la_message

static int is_finite(duffid_real v)
{
    return v == v && v - v == RC(0.0);
}

/* Python's round() of a float (half to even) */
static duffid_real round_half_even(duffid_real v)
{
    duffid_real r = R_FLOOR(v);
    duffid_real diff = v - r;
    if (diff > RC(0.5) || (diff == RC(0.5) && R_FMOD(r, RC(2.0)) != RC(0.0))) {
        r += RC(1.0);
    }
    return r;
}

static duffid_real sign_of(duffid_real v) /* np.sign */
{
    if (v > RC(0.0)) {
        return RC(1.0);
    }
    if (v < RC(0.0)) {
        return RC(-1.0);
    }
    return v; /* 0 or NaN */
}

static duffid_real max_builtin(duffid_real current, duffid_real candidate) /* Python max(current, candidate) */
{
    return candidate > current ? candidate : current;
}

/* hypot(a, b) (math.hypot), exact where one side is 0 (a forced block's scale error) */
/* v^power for a small integer power (a channel's), by multiplication */
static duffid_real int_power(duffid_real v, int power)
{
    duffid_real r = v;
    int i;
    for (i = 1; i < power; i++) {
        r *= v;
    }
    return power == 0 ? RC(1.0) : r;
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
int duffid_default_config(duffid_config *cfg, int model, int method, duffid_real dt)
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
    cfg->name = (DUFFID_CTYPE_##kind)(default_value);
    DUFFID_OPTIONS(DUFFID_SET_DEFAULT)
#undef DUFFID_SET_DEFAULT
    return DUFFID_OK;
}

/* The range checks of the option table (duffid_options.h): a REAL option is a finite
 * number >= its minimum, a CODE option an int in 0 .. maximum (maximum < 0: no bound);
 * only the options the configured method reads are checked. */
static int check_REAL(const char *name, int used, duffid_real v, duffid_real minimum, int maximum,
                      const char *valid, char *msg, size_t size)
{
    (void)maximum;
    if (used && !(is_finite(v) && v >= minimum)) {
        set_msg(msg, size, "option %s must be %s, got %g", name, valid, (double)v);
        return DUFFID_ERR_CONFIG;
    }
    return DUFFID_OK;
}

static int check_CODE(const char *name, int used, int v, duffid_real minimum, int maximum, const char *valid,
                      char *msg, size_t size)
{
    (void)minimum;
    if (used && (v < 0 || (maximum >= 0 && v > maximum))) {
        set_msg(msg, size, "option %s must be %s, got %d", name, valid, v);
        return DUFFID_ERR_CONFIG;
    }
    return DUFFID_OK;
}

static long capacity_of(const duffid_config *cfg)
{
    duffid_real seconds = cfg->window > RC(0.0) ? cfg->window : cfg->max_window;
    duffid_real r = round_half_even(seconds / cfg->dt);
    if (!(r <= (duffid_real)MAX_CAPACITY)) {
        return -1;
    }
    return r < RC(2.0) ? 2L : (long)r;
}

/* ------------------------------------------------------------------ the model's description */
static int add_channel(rt_model *m, int kind, int index, int power)
{
    int i;
    if (kind == CH_DEFL && index == 0) {
        kind = CH_X; /* the first deflection is the first displacement: one channel */
    }
    for (i = 0; i < m->c.n_channels; i++) {
        if (m->ch[i].kind == kind && m->ch[i].index == index && m->ch[i].power == power) {
            return i;
        }
    }
    m->ch[i].kind = kind;
    m->ch[i].index = index;
    m->ch[i].power = power;
    return m->c.n_channels++;
}

static void add_term(rt_model *m, block_t *b, int unknown, int kind, int index, int power, int order,
                     duffid_real coef)
{
    term_t *t = &m->terms[b->term0 + b->n_terms++];
    t->part = 0;
    t->unknown = unknown;
    t->channel = add_channel(m, kind, index, power);
    t->order = order;
    t->coef = coef;
    m->c.n_terms++;
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

static int block_unknown_of(const block_t *b, const int *param_of_unknown, int param)
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
 * DOF 1, no Coulomb friction, and what Chain answers about its parameters) into m's arrays
 * (params and publics may be NULL: only the counts and terms are wanted). Channels are
 * registered in first-use order (lhs then rhs terms, equation by equation). */
static void describe_builtin(const duffid_config *cfg, rt_model *m)
{
    const int n = model_dofs(cfg->model), offset = cfg->offset;
    int param_of[MAX_EQ][MAX_UNK];
    int i, j, e, p;
    m->c.n_dof = n;
    m->c.n_forces = 1;
    m->c.max_order = 2;
    m->c.n_blocks = n;
    m->c.n_params = 4 * n + (offset ? n : 0);
    m->c.uses_sign = 0;
    m->c.n_channels = m->c.n_terms = m->c.n_rules = 0;
    for (i = 0; i < n; i++) {
        block_t *b = &m->blocks[i];
        memset(b, 0, sizeof *b);
        b->n_parts = 1;
        b->forced = i == 0;
        b->term0 = m->c.n_terms;
        if (b->forced) {
            param_of[i][b->n_terms] = 4 * i + P_M;
            add_term(m, b, b->n_unknowns++, CH_X, i, 1, 2, RC(1.0));
        }
        param_of[i][b->n_terms] = 4 * i + P_B;
        add_term(m, b, b->n_unknowns++, CH_DEFL, i, 1, 1, RC(1.0));
        param_of[i][b->n_terms] = 4 * i + P_K1;
        add_term(m, b, b->n_unknowns++, CH_DEFL, i, 1, 0, RC(1.0));
        param_of[i][b->n_terms] = 4 * i + P_K3;
        add_term(m, b, b->n_unknowns++, CH_DEFL, i, 3, 0, RC(1.0));
        if (i + 1 < n) {
            param_of[i][b->n_terms] = 4 * (i + 1) + P_B;
            add_term(m, b, b->n_unknowns++, CH_DEFL, i + 1, 1, 1, RC(-1.0));
            param_of[i][b->n_terms] = 4 * (i + 1) + P_K1;
            add_term(m, b, b->n_unknowns++, CH_DEFL, i + 1, 1, 0, RC(-1.0));
            param_of[i][b->n_terms] = 4 * (i + 1) + P_K3;
            add_term(m, b, b->n_unknowns++, CH_DEFL, i + 1, 3, 0, RC(-1.0));
        }
        if (offset) {
            param_of[i][b->n_terms] = 4 * n + i;
            add_term(m, b, b->n_unknowns++, CH_ONE, 0, 1, 0, RC(1.0));
        }
        if (b->forced) {
            add_term(m, b, -1, CH_FORCE, 0, 1, 0, RC(1.0));
        } else {
            add_term(m, b, -1, CH_X, i, 1, 2, RC(-1.0));
        }
    }
    for (i = 0; i < n; i++) { /* scale rules of the unforced DOFs (Chain.combine_solutions) */
        block_t *b = &m->blocks[i];
        b->rule0 = m->c.n_rules;
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
                    duffid_rule *r = &m->rules[m->c.n_rules++];
                    r->unknown = u;
                    r->other = j;
                    r->other_unknown = v;
                    b->n_rules++;
                }
            }
        }
    }
    for (p = 0; m->params != NULL && p < m->c.n_params; p++) {
        duffid_parameter *q = &m->params[p];
        const int dof = p < 4 * n ? p / 4 : p - 4 * n, kind = p < 4 * n ? p % 4 : -1;
        static const char *const prefix[] = {"m", "b", "k", "k"};
        memset(q, 0, sizeof *q);
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
    for (i = 0; m->publics != NULL && i < m->c.n_params; i++) {
        memset(&m->publics[i], 0, sizeof m->publics[i]);
        strcpy(m->publics[i].name, cfg->model == DUFFID_DUFFING1 ? NAMES1[i] : NAMES2[i]);
        m->publics[i].canonical = public_to_canon(cfg->model, i);
        m->publics[i].reciprocal = 0;
    }
    /* linearisation: M = diag(m), K = the chain matrix of the linear stiffnesses */
    m->c.linear = 1;
    m->c.n_mass = m->c.n_stiffness = 0;
    for (i = 0; i < n; i++) {
        duffid_linear *l = &m->mass[m->c.n_mass++];
        l->row = l->col = i;
        l->param = 4 * i + P_M;
        l->coef = 1.0;
    }
    for (i = 0; i < n; i++) {
        duffid_linear *l = &m->stiffness[m->c.n_stiffness++];
        l->row = l->col = i;
        l->param = 4 * i + P_K1;
        l->coef = 1.0;
    }
    for (i = 0; i + 1 < n; i++) {
        duffid_linear *l = &m->stiffness[m->c.n_stiffness++];
        l->row = l->col = i;
        l->param = 4 * (i + 1) + P_K1;
        l->coef = 1.0;
    }
    for (i = 0; i + 1 < n; i++) {
        duffid_linear *l = &m->stiffness[m->c.n_stiffness++];
        l->row = i;
        l->col = i + 1;
        l->param = 4 * (i + 1) + P_K1;
        l->coef = -1.0;
        l = &m->stiffness[m->c.n_stiffness++];
        l->row = i + 1;
        l->col = i;
        l->param = 4 * (i + 1) + P_K1;
        l->coef = -1.0;
    }
    m->c.channel_work = 0;
    m->c.signature[0] = '\0';
}

/* The generated description into m's arrays (m->blocks ... NULL: the counts only). */
static void copy_generated(rt_model *m)
{
    const duffid_model *g = generated_model();
    int i, k;
    memset(&m->c, 0, sizeof m->c);
    m->c.n_dof = g->n_dof;
    m->c.n_forces = g->n_forces;
    m->c.n_channels = g->n_channels;
    m->c.max_order = g->max_order;
    m->c.n_blocks = g->n_blocks;
    m->c.n_params = g->n_params;
    m->c.linear = g->linear;
    m->c.n_mass = g->n_mass;
    m->c.n_stiffness = g->n_stiffness;
    m->c.channel_work = g->channel_work;
    m->c.uses_sign = g->uses_sign;
    memcpy(m->c.signature, g->signature, sizeof m->c.signature);
    for (i = 0; i < g->n_blocks; i++) {
        const duffid_block *b = &g->blocks[i];
        if (m->blocks != NULL) {
            block_t *t = &m->blocks[i];
            t->n_unknowns = b->n_unknowns;
            t->n_parts = b->n_parts;
            t->n_terms = b->n_terms;
            t->forced = b->forced;
            t->n_rules = b->n_rules;
            t->term0 = m->c.n_terms;
            t->rule0 = m->c.n_rules;
            for (k = 0; k < b->n_terms; k++) {
                term_t *d = &m->terms[t->term0 + k];
                d->part = b->terms[k].part;
                d->unknown = b->terms[k].unknown;
                d->channel = b->terms[k].channel;
                d->order = b->terms[k].order;
                d->coef = (duffid_real)b->terms[k].coef;
            }
            for (k = 0; k < b->n_rules; k++) {
                m->rules[t->rule0 + k] = b->rules[k];
            }
        }
        m->c.n_terms += b->n_terms;
        m->c.n_rules += b->n_rules;
    }
    if (m->params != NULL) {
        memcpy(m->params, g->params, (size_t)g->n_params * sizeof *m->params);
        memcpy(m->publics, g->publics, (size_t)g->n_params * sizeof *m->publics);
        memcpy(m->mass, g->mass, (size_t)g->n_mass * sizeof *m->mass);
        memcpy(m->stiffness, g->stiffness, (size_t)g->n_stiffness * sizeof *m->stiffness);
    }
}

/* What the memory block's layout depends on: the model's counts, the method, the window. */
typedef struct {
    rt_model m;          /* counts, and (counting only) the scratch tables below */
    int method, n_rows, degree, n_coef;
    long capacity;
    int unknowns[MAX_EQ], parts[MAX_EQ], lines[MAX_EQ]; /* lines: most unknowns with the lines' rates */
    int offset_probe[MAX_EQ];  /* the offset probe runs: robust, one part, no constant (offset) parameter */
    int n_noise;               /* robust: channels of the rows' noise (one per channel of x, row_noise) */
    int ring_width;            /* robust: values a sample takes in the ring (ring_sample) */
    int ring_raw;              /* ... 1: the raw sample (a built-in model), 0: the channels */
    block_t blocks[BUILTIN_BLOCKS > MAX_EQ ? BUILTIN_BLOCKS : MAX_EQ];
    term_t terms[BUILTIN_TERMS];
    duffid_rule rules[BUILTIN_RULES];
    duffid_linear mass[BUILTIN_LINEAR], stiffness[BUILTIN_LINEAR];
    channel_t ch[MAX_CH];
} shape_t;

/* the kernel rows (a, b) of regressors.row_exponents */
static void row_exponents(int family, int n_rows, int *row_a, int *row_b)
{
    int r;
    for (r = 0; r < n_rows; r++) {
        if (family == DUFFID_ROWS_PAPER) {
            row_a[r] = 1 + r;
            row_b[r] = 2;
        } else if (family == DUFFID_ROWS_INTEGRALS) {
            row_a[r] = 3 + r;
            row_b[r] = 2;
        } else {
            row_a[r] = 2 + r;
            row_b[r] = 1 + n_rows - r;
        }
    }
}

/* the non-zero powers of row r's order-d kernel: s^(a+m-d), m = 0..b, those >= 0 */
static int kernel_first(int a, int d)
{
    return a - d < 0 ? 0 : a - d;
}

static void shape_of(const duffid_config *cfg, shape_t *s)
{
    int e, n_max = 0, r, d;
    memset(&s->m, 0, sizeof s->m);
    if (cfg->model == DUFFID_GENERATED) {
        copy_generated(&s->m); /* counts only */
        for (e = 0; e < s->m.c.n_blocks; e++) {
            s->unknowns[e] = generated_model()->blocks[e].n_unknowns;
            s->parts[e] = generated_model()->blocks[e].n_parts;
        }
    } else {
        s->m.blocks = s->blocks;
        s->m.terms = s->terms;
        s->m.rules = s->rules;
        s->m.mass = s->mass;
        s->m.stiffness = s->stiffness;
        s->m.ch = s->ch;
        describe_builtin(cfg, &s->m);
        for (e = 0; e < s->m.c.n_blocks; e++) {
            s->unknowns[e] = s->blocks[e].n_unknowns;
            s->parts[e] = s->blocks[e].n_parts;
        }
    }
    for (e = 0; e < s->m.c.n_blocks; e++) {
        const int n = s->unknowns[e];
        n_max = n > n_max ? n : n_max;
        /* the lines only come with the change test */
        s->lines[e] = cfg->method == DUFFID_ROBUST && cfg->change_threshold > 0 ? (2 * n < MAX_LINE ? 2 * n : MAX_LINE)
                                                                                   : n;
        s->lines[e] = s->lines[e] > n ? s->lines[e] : n;
        s->offset_probe[e] = cfg->method == DUFFID_ROBUST && s->parts[e] == 1;
    }
    if (cfg->model == DUFFID_GENERATED) { /* a block with a constant (offset) parameter has no probe */
        const duffid_model *g = generated_model();
        int q, k;
        for (q = 0; q < g->n_params; q++) {
            for (k = 0; g->params[q].offset && k < g->params[q].n_shares; k++) {
                s->offset_probe[g->params[q].shares[k].block] = 0;
            }
        }
    } else if (cfg->offset) {
        for (e = 0; e < s->m.c.n_blocks; e++) {
            s->offset_probe[e] = 0;
        }
    }
    s->method = cfg->method;
    s->n_noise = 0;
    for (e = 0; e < s->m.c.n_channels && cfg->method == DUFFID_ROBUST; e++) { /* the channels of x (row_noise) */
        s->n_noise += cfg->model == DUFFID_GENERATED ? generated_model()->channel_force[e] < 0
                                                     : s->ch[e].kind == CH_X || s->ch[e].kind == CH_DEFL;
    }
    /* the ring: a built-in model's raw sample (x, f and, with the rows' noise, the noisy x: its
     * channels are recomputed where the ring is read), a generated model's channels */
    s->ring_raw = cfg->model != DUFFID_GENERATED;
    s->ring_width = !s->ring_raw ? s->m.c.n_channels + s->n_noise
                                 : s->m.c.n_dof * (s->n_noise > 0 ? 2 : 1) + s->m.c.n_forces;
    s->n_rows = cfg->n_rows ? cfg->n_rows : (n_max + 1 > 8 ? n_max + 1 : 8);
    s->capacity = cfg->method == DUFFID_ROBUST ? capacity_of(cfg) : 0;
    s->degree = s->n_coef = 0;
    if (cfg->method == DUFFID_ROBUST && s->n_rows <= DUFFID_MAX_ROWS) {
        int row_a[DUFFID_MAX_ROWS], row_b[DUFFID_MAX_ROWS];
        row_exponents(cfg->rows, s->n_rows, row_a, row_b);
        for (r = 0; r < s->n_rows; r++) {
            s->degree = row_a[r] + row_b[r] > s->degree ? row_a[r] + row_b[r] : s->degree;
            for (d = 0; d <= MAX_ORDER; d++) {
                s->n_coef += row_a[r] + row_b[r] - d - kernel_first(row_a[r], d) + 1;
            }
        }
        s->degree += 1; /* the moments: one power more than the kernels take (within_entry) */
    }
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
#if DUFFID_SINGLE
    if (cfg->method == DUFFID_PAPER) {
        set_msg(msg, size, "the paper method needs double precision: its raw Cramer determinants (1e-75 .. 1e-33) "
                           "underflow in single precision; use the robust method or a double build");
        return DUFFID_ERR_CONFIG;
    }
#endif
    if (cfg->offset != 0 && cfg->offset != 1) {
        set_msg(msg, size, "offset must be 0 or 1, got %d", cfg->offset);
        return DUFFID_ERR_CONFIG;
    }
    if (cfg->offset && cfg->model == DUFFID_GENERATED) {
        set_msg(msg, size, "offset must be 0 for the generated model (its description has its offsets)");
        return DUFFID_ERR_CONFIG;
    }
    if (!(is_finite(cfg->dt) && cfg->dt > RC(0.0))) {
        set_msg(msg, size, "dt must be a positive number of seconds, got %g", (double)cfg->dt);
        return DUFFID_ERR_CONFIG;
    }
    n_pub = public_count(cfg->model, cfg->offset);
    for (i = 0; i < n_pub; i++) {
        duffid_real v = cfg->nominal[i];
        if (!is_finite(v)) {
            set_msg(msg, size, "the prior size %s_nominal must be a finite number (0: none), got %g",
                    public_name(cfg, i), (double)v);
            return DUFFID_ERR_CONFIG;
        }
    }
    method_bit = cfg->method == DUFFID_ROBUST ? DUFFID_FOR_ROBUST : DUFFID_FOR_PAPER;
#define DUFFID_CHECK_OPTION(kind, name, default_value, minimum, maximum, methods, valid) \
    if ((rc = check_##kind(#name, ((methods) & method_bit) != 0, cfg->name, RC(minimum), maximum, valid, msg, \
                           size)) != DUFFID_OK) {                                                             \
        return rc;                                                                                            \
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
        shape_t s;
        shape_of(cfg, &s);
        if (s.n_rows > DUFFID_MAX_ROWS) {
            set_msg(msg, size, "n_rows must be at most %d in the C core, got %d", DUFFID_MAX_ROWS, s.n_rows);
            return DUFFID_ERR_CONFIG;
        }
        if (s.capacity < 0 || ((duffid_real)s.capacity + RC(2.0)) * (duffid_real)s.ring_width *
                                      (duffid_real)sizeof(duffid_real) >
                                  (duffid_real)SIZE_MAX / RC(2.0)) {
            set_msg(msg, size, "the window (%g s at dt %g s) exceeds %ld samples or the address space",
                    (double)(cfg->window > RC(0.0) ? cfg->window : cfg->max_window), (double)cfg->dt, MAX_CAPACITY);
            return DUFFID_ERR_CONFIG;
        }
    }
    set_msg(msg, size, "");
    return DUFFID_OK;
}

/* ------------------------------------------------------------------ memory layout */
#define ALIGNMENT DUFFID_LA_ALIGNMENT
#define ALIGN_UP DUFFID_LA_ALIGN_UP
#define CARVE DUFFID_LA_CARVE
typedef duffid_la_carver carver_t; /* the arrays of a block one after the other (duffid_linalg.h) */

/* The arrays of the block after the estimator structure, in order: first the structure (the
 * model's tables and everything init derives from the configuration, never written after),
 * then the state. With est == NULL the pointers go to a scratch estimator (sizes only).
 * Returns the bytes used. */
static size_t layout(const shape_t *s, duffid_estimator *est, char *base)
{
    duffid_estimator scratch;
    carver_t c;
    const int n_ch = s->m.c.n_channels, n_blk = s->m.c.n_blocks, np = s->m.c.n_params;
    const int n_mom = n_ch + s->n_noise; /* the moments' channels: the model's and their noise's */
    const int D = s->degree, robust = s->method == DUFFID_ROBUST;
    int e, n_max = 0, p_max, rows_max = 0, line_max = 0;
    c.base = base;
    c.used = 0;
    if (est == NULL) {
        est = &scratch;
        c.base = NULL;
    }
    for (e = 0; e < n_blk; e++) {
        n_max = s->unknowns[e] > n_max ? s->unknowns[e] : n_max;
        rows_max = s->parts[e] * s->n_rows > rows_max ? s->parts[e] * s->n_rows : rows_max;
        line_max = s->lines[e] > line_max ? s->lines[e] : line_max;
    }
    p_max = n_max + 1;
    /* structure */
    CARVE(&c, est->m.blocks, n_blk);
    CARVE(&c, est->m.terms, s->m.c.n_terms);
    CARVE(&c, est->m.rules, s->m.c.n_rules);
    CARVE(&c, est->m.params, np);
    CARVE(&c, est->m.publics, np);
    CARVE(&c, est->m.mass, s->m.c.n_mass);
    CARVE(&c, est->m.stiffness, s->m.c.n_stiffness);
    CARVE(&c, est->m.ch, n_ch);
    CARVE(&c, est->nominal, np);
    CARVE(&c, est->k_coef, robust ? s->n_coef : 0);
    CARVE(&c, est->k_expo, robust ? s->n_coef : 0);
    CARVE(&c, est->stirling, robust ? (D + 1) * (D + 1) : 0);
    CARVE(&c, est->job, robust ? 5 * N_ORD * n_mom * s->n_rows : 0);
    CARVE(&c, est->step, robust ? D + 1 : 0);
    CARVE(&c, est->force_channel, s->m.c.n_forces);
    est->structure_bytes = c.used;
    /* state */
    CARVE(&c, est->steady, np);
    CARVE(&c, est->period_seen, np);
    CARVE(&c, est->anchor, np);
    CARVE(&c, est->anchored, np);
    CARVE(&c, est->settled, np);
    CARVE(&c, est->unsettled, np);
    CARVE(&c, est->status, np);
    CARVE(&c, est->fresh, np);
    CARVE(&c, est->credible_from, np);
    CARVE(&c, est->value, np);
    CARVE(&c, est->changed_now, np);
    CARVE(&c, est->held, np);
    CARVE(&c, est->canon, np);
    CARVE(&c, est->canon_rse, np);
    CARVE(&c, est->canon_steady, np);
    CARVE(&c, est->canon_share, np);
    CARVE(&c, est->chan_work, s->m.c.channel_work);
    CARVE(&c, est->g, n_mom);
    CARVE(&c, est->lin, 2 * s->m.c.n_dof * s->m.c.n_dof);
    for (e = 0; e < n_blk; e++) {
        equation_t *eq = &est->eq[e];
        const int n = s->unknowns[e], nl = s->lines[e], p = nl + 1, lines = robust && nl > n;
        CARVE(&c, eq->theta, n);
        CARVE(&c, eq->rse, n);
        CARVE(&c, eq->share, n);
        CARVE(&c, eq->V, nl * nl);
        CARVE(&c, eq->R, robust ? p * p : 0);
        CARVE(&c, eq->R_recent, robust ? p * p : 0);
        CARVE(&c, eq->departure, n);
        eq->line_cap = nl;
        eq->probe_n = lines ? nl - n : 0; /* the probe's lines: as many as the factors hold */
        CARVE(&c, eq->R_probe, lines ? p * p : 0);
        eq->off_on = s->offset_probe[e];
        CARVE(&c, eq->R_off, eq->off_on ? (n + 2) * (n + 2) : 0);
        CARVE(&c, eq->off_moved, n);
        CARVE(&c, eq->jump_v, robust ? nl : 0);
        CARVE(&c, eq->jump_shift, n);
        CARVE(&c, eq->rate_v, robust ? nl : 0);
        CARVE(&c, eq->rate_shift, n);
        CARVE(&c, eq->noise_G, robust ? nl * p : 0);
        CARVE(&c, eq->noise_G_recent, robust ? nl * p : 0);
        CARVE(&c, eq->noise_shift, n);
        CARVE(&c, eq->score, nl * (nl + 2) + n); /* with LAST_SCORE, SCORES, NOMINAL */
        CARVE(&c, eq->drift_shift, n);
        CARVE(&c, eq->drifting, n);
        CARVE(&c, eq->line, lines ? nl : 0);
        CARVE(&c, eq->line_inv, lines ? nl * nl : 0);
        CARVE(&c, eq->line_recent, lines ? nl : 0);
        CARVE(&c, eq->line_recent_inv, lines ? nl * nl : 0);
        if (!robust) {
            integrators_t *it = &eq->reg;
            int k;
            for (k = 0; k < 2; k++, it = &eq->det) {
                const int n_in = k == 0 ? 3 * n_ch : n + 1, depth = k == 0 ? n + 1 : 2;
                it->n_in = n_in;
                it->depth = depth;
                CARVE(&c, it->y, (depth + 1) * n_in);
                CARVE(&c, it->p1, (depth + 1) * n_in);
                CARVE(&c, it->p2, (depth + 1) * n_in);
            }
        }
    }
    CARVE(&c, est->U, line_max * line_max);
    CARVE(&c, est->Rinv, line_max * line_max);
    CARVE(&c, est->scale, line_max);
    if (robust) {
        CARVE(&c, est->ring, (s->capacity + 2) * s->ring_width);
        CARVE(&c, est->ring_buf, s->ring_raw ? (MAX_CORR + 1) * n_mom : 0);
        CARVE(&c, est->near, s->ring_raw ? NEAR * n_mom : 0);
        CARVE(&c, est->acc, (D + 1) * n_mom);
        CARVE(&c, est->shadow, SHADOWS * (D + 1) * n_mom);
        CARVE(&c, est->fact, (D + 1) * n_mom);
        CARVE(&c, est->mom, (D + 1) * n_mom);
        CARVE(&c, est->poly, s->n_coef);
        CARVE(&c, est->corr_w, MAX_CORR * (D + 1));
        CARVE(&c, est->acc_alt, (D + 1) * n_ch);
        CARVE(&c, est->shadow_alt, SHADOWS * (D + 1) * n_ch);
        CARVE(&c, est->dfact, (D + 1) * n_ch);
        CARVE(&c, est->dmom, (D + 1) * n_ch);
        CARVE(&c, est->E_rate, s->n_rows * N_ORD * n_mom);
        CARVE(&c, est->B_rate, rows_max * (line_max + 1));
        CARVE(&c, est->rate_q, rows_max);
        CARVE(&c, est->B_noise, s->n_noise ? rows_max * (line_max + 1) : 0);
        CARVE(&c, est->noise_w, s->n_noise ? 3 * line_max * line_max : 0);
        CARVE(&c, est->noise_Gw, s->n_noise ? line_max * (line_max + 1) : 0);
        CARVE(&c, est->leave_phi, D + 1);
        CARVE(&c, est->E, s->n_rows * N_ORD * n_mom);
        CARVE(&c, est->one_E, s->n_rows);
        CARVE(&c, est->jump_flag, s->capacity + 2);
        CARVE(&c, est->jump_sum, (D + 1) * s->m.c.n_forces);
        CARVE(&c, est->jump_J, rows_max);
        CARVE(&c, est->B, rows_max * (line_max + 1));
        CARVE(&c, est->B_copy, rows_max * (line_max + 1));
        CARVE(&c, est->W, p_max * p_max);
    } else {
        CARVE(&c, est->E, (n_max + 2) * N_ORD * n_ch);
        CARVE(&c, est->B, n_max * p_max);
        CARVE(&c, est->u_in, 3 * n_ch);
        CARVE(&c, est->Ap, n_max * n_max);
        CARVE(&c, est->Dp, n_max);
        CARVE(&c, est->Aw, n_max * n_max);
        CARVE(&c, est->W, n_max * n_max);
    }
    return c.used;
}
#undef CARVE

size_t duffid_memory_size(const duffid_config *cfg)
{
    shape_t s;
    if (duffid_check_config(cfg, NULL, 0) != DUFFID_OK) {
        return 0;
    }
    shape_of(cfg, &s);
    return ALIGN_UP(sizeof(struct duffid_estimator)) + layout(&s, NULL, NULL) + ALIGNMENT;
}

/* ------------------------------------------------------------------ structure */
/* regressors.row_exponents + KernelBank.build (+ __post_init__), the falling-factorial
 * basis of the moments and its map to power moments */
static void build_kernel_bank(duffid_estimator *est)
{
    int r, m, d, k, j, at = 0, n_rows = est->n_rows;
    const duffid_real inv_n = RC(1.0) / (duffid_real)est->capacity;
    row_exponents(est->cfg.rows, n_rows, est->row_a, est->row_b);
    est->degree = 0;
    for (r = 0; r < n_rows; r++) {
        est->degree = est->row_a[r] + est->row_b[r] > est->degree ? est->row_a[r] + est->row_b[r] : est->degree;
    }
    est->degree += 1; /* the moments: one power more than the kernels take (within_entry) */
    for (r = 0; r < n_rows; r++) {
        const int a = est->row_a[r], b = est->row_b[r];
        duffid_real prod = RC(1.0), fact_a = RC(1.0);
        for (k = 2; k <= a; k++) {
            fact_a *= (duffid_real)k;
        }
        for (d = 0; d <= MAX_ORDER; d++) {
            const int first = kernel_first(a, d), last = a + b - d;
            est->k_first[r * N_ORD + d] = first;
            est->k_count[r * N_ORD + d] = last - first + 1;
            est->k_at[r * N_ORD + d] = at;
            for (k = first; k <= last; k++) {
                est->k_coef[at + k - first] = RC(0.0);
                est->k_expo[at + k - first] = 0;
            }
            for (m = 0; m <= b; m++) {
                const int power = a + m;
                duffid_real num = RC(1.0), binom = RC(1.0);
                if (power - d < 0) {
                    continue;
                }
                for (k = 0; k < m; k++) { /* C(b, m), exact */
                    binom = binom * (duffid_real)(b - k) / (duffid_real)(k + 1);
                }
                for (k = 0; k < d; k++) { /* power! / (power - d)! */
                    num *= (duffid_real)(power - k);
                }
                num *= binom;
                est->k_coef[at + power - d - first] += (m % 2 ? -num : num) / fact_a;
                est->k_expo[at + power - d - first] = b - m;
            }
            at += last - first + 1;
        }
        est->raw_b[r] = (a == 1 && est->m.c.max_order >= 2) ? b : -1;
        for (k = b + 1; k <= a + b + 1; k++) {
            prod *= (duffid_real)k; /* (a+b+1)! / b! */
        }
        est->norm[r] = prod;
        est->norm_power[r] = a + b + 1;
    }
    est->n_coef = at;
    /* the falling-factorial basis phi_j(i) = i (i-1) ... (i-j+1) / N^j: one step later every
     * sample is one further away, phi_j(i+1) = phi_j(i) + (j / N) phi_(j-1)(i); and
     * (i/N)^k = sum_j S2(k, j) N^(j-k) phi_j(i) (Stirling numbers of the second kind) */
    for (j = 0; j <= est->degree; j++) {
        est->step[j] = (duffid_real)j * inv_n;
    }
    for (k = 0; k <= est->degree; k++) {
        for (j = 0; j <= est->degree; j++) {
            duffid_real *t = &est->stirling[k * (est->degree + 1) + j];
            if (j > k) {
                *t = RC(0.0);
            } else if (k == 0) {
                *t = RC(1.0);
            } else if (j == 0) {
                *t = RC(0.0);
            } else { /* S2(k,j) = j S2(k-1,j) + S2(k-1,j-1), each times N^(j-k) */
                const duffid_real *above = &est->stirling[(k - 1) * (est->degree + 1)];
                *t = (duffid_real)j * above[j] * inv_n + above[j - 1];
            }
        }
    }
    for (k = 0; k <= est->degree; k++) { /* the moments' 1/N */
        for (j = 0; j <= k; j++) {
            est->stirling[k * (est->degree + 1) + j] *= inv_n;
        }
    }
    est->d_scale[0] = RC(1.0);
    for (d = 1; d <= MAX_ORDER; d++) {
        est->d_scale[d] = est->d_scale[d - 1] / ((duffid_real)est->capacity * est->cfg.dt);
    }
}

/* the structure of est (its model, tables and constants) from est->cfg */
static void build_structure(duffid_estimator *est, const shape_t *s)
{
    int i, k;
    if (est->cfg.model == DUFFID_GENERATED) {
        copy_generated(&est->m);
    } else {
        describe_builtin(&est->cfg, &est->m);
        for (i = 0; i < s->m.c.n_channels; i++) {
            est->m.ch[i] = s->ch[i];
        }
    }
    est->n_dof = est->m.c.n_dof;
    est->n_forces = est->m.c.n_forces;
    est->n_params = est->m.c.n_params;
    est->n_ch = est->m.c.n_channels;
    est->n_eq = est->m.c.n_blocks;
    est->n_noise = s->n_noise;
    est->n_mom = est->n_ch + est->n_noise;
    est->ring_raw = s->ring_raw;
    est->ring_width = s->ring_width;
    for (i = 0, k = est->n_ch; i < est->n_ch; i++) { /* the channels of x have a noise channel each */
        const int noisy = est->cfg.model == DUFFID_GENERATED ? generated_model()->channel_force[i] < 0
                                                             : est->m.ch[i].kind == CH_X || est->m.ch[i].kind == CH_DEFL;
        est->noise_of[i] = noisy && est->n_noise > 0 ? k++ : -1;
    }
    for (i = 0; i < est->n_params; i++) {
        est->nominal[est->m.publics[i].canonical] = R_FABS(est->cfg.nominal[i]);
    }
    for (i = 0; i < est->n_forces; i++) { /* the channel that is each force (JUMP_ERROR) */
        est->force_channel[i] = -1;
    }
    for (i = 0; i < est->n_ch; i++) {
        const int force = est->cfg.model == DUFFID_GENERATED ? generated_model()->channel_force[i]
                          : est->m.ch[i].kind == CH_FORCE ? est->m.ch[i].index : -1;
        if (force >= 0 && force < est->n_forces && est->force_channel[force] < 0) {
            est->force_channel[force] = i;
        }
    }
    est->n_used = 0;
    for (i = 0; i < N_ORD * est->n_ch; i++) { /* the (order, channel) pairs the terms read */
        for (k = 0; k < est->m.c.n_terms; k++) {
            if (est->m.terms[k].order * est->n_ch + est->m.terms[k].channel == i) {
                est->used_order[est->n_used] = i / est->n_ch;
                est->used_channel[est->n_used++] = i % est->n_ch;
                break;
            }
        }
    }
    est->dt = est->cfg.dt;
    est->max_condition = est->cfg.max_condition;
    est->max_uncertainty = est->cfg.max_uncertainty;
    est->min_time = est->cfg.min_time;
    est->deadband = est->cfg.deadband;
    est->n_rows = s->n_rows;
    if (est->cfg.method == DUFFID_ROBUST) {
        duffid_real settle;
        est->capacity = s->capacity;
        est->auto_window = !(est->cfg.window > RC(0.0));
        est->lam = est->cfg.forgetting > RC(0.0) ? R_EXP(-est->cfg.dt / est->cfg.forgetting) : RC(1.0);
        est->sqrt_lam = R_SQRT(est->lam);
        est->inv_cap = RC(1.0) / (duffid_real)est->capacity;
        build_kernel_bank(est);
        est->n_jobs = est->n_noise_jobs = 0;
        for (k = 0; k < 2; k++) { /* the kernel entries: E[(r * N_ORD + d) * n_mom + c]; then the
                                   * entries of the used channels' noise channels */
            for (i = 0; i < est->n_used; i++) {
                const int d = est->used_order[i], c = k == 0 ? est->used_channel[i] : est->noise_of[est->used_channel[i]];
                int r;
                for (r = 0; r < est->n_rows && c >= 0; r++) {
                    int *job = est->job + 5 * (est->n_jobs + est->n_noise_jobs);
                    job[0] = est->k_at[r * N_ORD + d];
                    job[1] = c * (est->degree + 1) + est->k_first[r * N_ORD + d];
                    job[2] = est->k_count[r * N_ORD + d];
                    job[3] = (r * N_ORD + d) * est->n_mom + c;
                    job[4] = d == 2 && est->raw_b[r] >= 0 ? r : -1;
                    if (k == 0) {
                        est->n_jobs++;
                    } else {
                        est->n_noise_jobs++;
                    }
                }
            }
        }
        est->change_threshold = est->cfg.change_threshold;
        settle = round_half_even(est->cfg.settle / est->cfg.dt);
        est->settle_count = settle < RC(1.0) ? 1 : (settle > RC(4e18) ? (int64_t)4e18 : (int64_t)settle);
    }
}

/* ------------------------------------------------------------------ lifecycle */
static duffid_estimator *place(void *memory)
{
    return (duffid_estimator *)(((uintptr_t)memory + (ALIGNMENT - 1u)) & ~(uintptr_t)(ALIGNMENT - 1u));
}

static char *dynamic_base(duffid_estimator *est)
{
    return (char *)est + ALIGN_UP(sizeof(struct duffid_estimator));
}

int duffid_init(duffid_estimator **out, void *memory, size_t size, const duffid_config *cfg, char *msg,
                size_t msg_size)
{
    duffid_estimator *est;
    shape_t s;
    int rc;
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
    shape_of(cfg, &s);
    est = place(memory);
    memset(est, 0, sizeof *est);
    memset(dynamic_base(est), 0, layout(&s, NULL, NULL));
    est->cfg = *cfg;
    layout(&s, est, dynamic_base(est));
    build_structure(est, &s);
    duffid_reset(est);
    *out = est;
    return DUFFID_OK;
}

duffid_estimator *duffid_relocate(void *memory)
{
    duffid_estimator *est;
    shape_t s;
    if (memory == NULL) {
        return NULL;
    }
    est = place(memory);
    shape_of(&est->cfg, &s);
    layout(&s, est, dynamic_base(est));
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
    STATE_SAME(n_dof) STATE_SAME(n_forces) STATE_SAME(n_params) STATE_SAME(n_ch) STATE_SAME(n_mom) STATE_SAME(n_eq) STATE_SAME(ring_raw) STATE_SAME(ring_width)
    STATE_SAME(n_noise) STATE_SAME(noise_of) STATE_SAME(n_noise_jobs)
    if (memcmp(&est->m.c, &fresh->m.c, sizeof est->m.c) != 0) { /* another model (its counts, signature) */
        bad = "model";
        goto done;
    }
    STATE_SAME(settle_count) STATE_SAME(change_threshold) STATE_SAME(dt) STATE_SAME(max_condition)
    STATE_SAME(max_uncertainty) STATE_SAME(min_time) STATE_SAME(deadband)
    STATE_SAME(capacity) STATE_SAME(auto_window) STATE_SAME(n_rows) STATE_SAME(degree) STATE_SAME(lam)
    STATE_SAME(sqrt_lam) STATE_SAME(inv_cap) STATE_SAME(row_a) STATE_SAME(row_b) STATE_SAME(raw_b)
    STATE_SAME(norm) STATE_SAME(norm_power) STATE_SAME(d_scale) STATE_SAME(k_first) STATE_SAME(k_count)
    STATE_SAME(k_at) STATE_SAME(n_coef) STATE_SAME(n_used) STATE_SAME(used_order) STATE_SAME(used_channel) STATE_SAME(n_jobs)
    STATE_SAME(structure_bytes)
    if (memcmp((const char *)est + ALIGN_UP(sizeof *est), dynamic_base(fresh), fresh->structure_bytes) != 0) {
        bad = "structure (the model's tables)";
        goto done;
    }
    for (i = 0; i < est->n_eq; i++) {
        STATE_RANGE(est->eq[i].warm, 0, 1)
        /* the window's prediction error is output as it is until the block's next full window */
        if (est->eq[i].residual == est->eq[i].residual) { /* not NaN */
            STATE_RANGE(est->eq[i].residual, RC(0.0), R_INF)
        }
        STATE_RANGE(est->eq[i].departed, 0, est->settle_count)
        STATE_RANGE(est->eq[i].surprised, 0, est->settle_count)
        STATE_RANGE(est->eq[i].drifted, 0, est->memory)
        STATE_RANGE(est->eq[i].probed, 0, est->settle_count)
        if (cfg.method == DUFFID_ROBUST) { /* a row of the block (est's pointers are not relocated yet) */
            STATE_RANGE(est->eq[i].probe_row, 0, fresh->m.blocks[i].n_parts * fresh->n_rows - 1)
        }
        STATE_SAME(eq[i].probe_n)
        STATE_SAME(eq[i].off_on)
        if (cfg.method == DUFFID_ROBUST) {
            STATE_RANGE(est->eq[i].off_row, 0, fresh->m.blocks[i].n_parts * fresh->n_rows - 1)
        }
        STATE_RANGE(est->eq[i].resume, 0, limit)
        STATE_RANGE(est->eq[i].block, 0, fresh->capacity)
        STATE_RANGE(est->eq[i].recent_resume, 0, limit)
        STATE_SAME(eq[i].line_cap)
        if (cfg.method == DUFFID_ROBUST) { /* n_line: the block's unknowns and one rate per line */
            const int *drifting = (const int *)((const char *)est + ALIGN_UP(sizeof *est) +
                                                ((const char *)fresh->eq[i].drifting - dynamic_base(fresh)));
            const int n_unknowns = fresh->m.blocks[i].n_unknowns; /* est's pointers are not relocated yet */
            int u, lines = 0;
            for (u = 0; u < n_unknowns; u++) {
                STATE_RANGE(drifting[u], 0, 1)
                lines += drifting[u];
            }
            STATE_RANGE(est->eq[i].n_line, n_unknowns + lines, n_unknowns + lines)
            STATE_RANGE(est->eq[i].n_line, 0, est->eq[i].line_cap)
            STATE_RANGE(est->eq[i].origin, 0, limit)
        }
        if (cfg.method == DUFFID_PAPER) {
            STATE_SAME(eq[i].reg.n_in)
            STATE_SAME(eq[i].reg.depth) STATE_SAME(eq[i].det.n_in) STATE_SAME(eq[i].det.depth)
            STATE_RANGE(est->eq[i].reg.count, 0, 2)
            STATE_RANGE(est->eq[i].det.count, 0, 2)
        }
    }
    /* counts, indices and buffer positions */
    n = est->n;
    STATE_RANGE(n, -1, limit)
    STATE_RANGE(est->window_fixed, 0, 1)
    STATE_RANGE(est->window_capped, 0, est->window_fixed)
    if (cfg.method == DUFFID_ROBUST) {
        STATE_RANGE(est->n_jumps, 0, (int64_t)est->capacity + 2)
        STATE_RANGE(est->has_jump, 0, 1)
        STATE_RANGE(est->has_jump_candidate, 0, 1)
    }
    STATE_RANGE(est->spanned_from, -1, n + 1 + (int64_t)est->capacity)
    STATE_RANGE(est->has_last_x, 0, 1)
    STATE_RANGE(est->noise_level.count, 0, DUFFID_LA_NOISE_HISTORY) /* the rows' noise */
    STATE_RANGE(est->near_head, 0, NEAR - 1)
    STATE_RANGE(est->noise_level.n4, 0, n + 1)
    STATE_RANGE(est->noise_level.n6, 0, est->noise_level.n4)
    STATE_RANGE(est->noise_state, 1, UINT32_MAX) /* xorshift32 never reaches 0 */
    STATE_RANGE(est->pending, 0, 2)
    STATE_RANGE(est->received, n + est->pending, n + est->pending) /* a held sample is not processed yet */
    STATE_RANGE(est->g_count, 0, est->received + 1)
    STATE_RANGE(est->p_k, 0, limit)
    if (est->pending) {
        STATE_RANGE(est->p_k, est->received - est->pending + 1, est->received - est->pending + 1)
    }
    STATE_RANGE(est->outliers, 0, est->received + 1)
    STATE_RANGE(est->outlier_column, -1, est->n_dof - 1)
    for (i = 0; i < DUFFID_MAX_DOF; i++) {
        STATE_RANGE(est->p_suspect[i], 0, 1)
        STATE_RANGE(est->p_pair[i], 0, 1)
    }
    {
        /* the per-parameter state lives in the block: read it through a relocated view */
        const char *dyn = (const char *)est + ALIGN_UP(sizeof *est);
        const int64_t *steady = (const int64_t *)(dyn + ((const char *)fresh->steady - dynamic_base(fresh)));
        const int64_t *anchored = (const int64_t *)(dyn + ((const char *)fresh->anchored - dynamic_base(fresh)));
        const int64_t *settled = (const int64_t *)(dyn + ((const char *)fresh->settled - dynamic_base(fresh)));
        const int64_t *unsettled = (const int64_t *)(dyn + ((const char *)fresh->unsettled - dynamic_base(fresh)));
        const int *status = (const int *)(dyn + ((const char *)fresh->status - dynamic_base(fresh)));
        const int *restarted = (const int *)(dyn + ((const char *)fresh->fresh - dynamic_base(fresh)));
        const int *changed_now = (const int *)(dyn + ((const char *)fresh->changed_now - dynamic_base(fresh)));
        const int64_t *credible_from = (const int64_t *)(dyn + ((const char *)fresh->credible_from - dynamic_base(fresh)));
        for (i = 0; i < est->n_params; i++) {
            STATE_RANGE(status[i], DUFFID_STATUS_UNCERTAIN, DUFFID_STATUS_CHANGED)
            STATE_RANGE(restarted[i], 0, 1)
            STATE_RANGE(changed_now[i], -1, 1)
            STATE_RANGE(steady[i], 0, limit)
            STATE_RANGE(anchored[i], -1, limit)
            STATE_RANGE(settled[i], 0, limit)
            STATE_RANGE(unsettled[i], 0, limit)
            STATE_RANGE(credible_from[i], 0, n + 1 + 2 * (int64_t)est->capacity)
        }
    }
    for (i = 0; i < DUFFID_MAX_PARAMS; i++) {
        STATE_RANGE(est->last.status[i], DUFFID_STATUS_UNCERTAIN, DUFFID_STATUS_CHANGED)
    }
    STATE_RANGE(est->last.n_parameters, 0, DUFFID_MAX_PARAMS)
    STATE_RANGE(est->last.identified, 0, 1)
    STATE_RANGE(est->last.outliers, 0, est->received + 1)
    STATE_RANGE(est->last.outlier_column, -1, est->n_dof - 1)
    if (cfg.method == DUFFID_ROBUST) {
        const long N = est->capacity;
        STATE_RANGE(est->target, 1, N)
        STATE_RANGE(est->regrow, 0, 1)
        STATE_RANGE(est->has_f_prev, 0, 1)
        STATE_RANGE(est->has_f_change, 0, 1)
        STATE_RANGE(est->defer, 0, DUFFID_MAX_ROW_STRIDE)
        STATE_RANGE(est->row_phase, 0, est->defer > 1 ? est->defer - 1 : 0)
        STATE_RANGE(est->deferred, 0, N)
        STATE_RANGE(est->head, 0, N + 1)
        STATE_RANGE(est->start, 0, n + 1)
        STATE_RANGE(n - est->start, -1, (int64_t)N)
        for (i = 0; i < SHADOWS; i++) {
            if (est->shadow_from[i] >= 0) {
                STATE_RANGE(est->shadow_from[i], est->start, n + 1)
            }
        }
        STATE_RANGE(est->poly_L, -1, N)
        STATE_RANGE(est->one_L, -1, N)
        STATE_RANGE(est->corr_L, -1, N)
        STATE_RANGE(est->leave_i, -1, N + 1)
        STATE_RANGE(est->corr_n, 0, MAX_CORR)
        for (i = 0; i < est->corr_n; i++) {
            STATE_RANGE(est->corr_off[i], 0, est->corr_L)
        }
        STATE_RANGE(est->rate_L, -1, N)
        STATE_RANGE(est->rate_ok, 0, 1)
        STATE_RANGE(est->rate_n, 0, MAX_RATE)
        for (i = 0; i < est->rate_n; i++) {
            STATE_RANGE(est->rate_off[i], 0, est->rate_L)
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

static void integrators_reset(integrators_t *it)
{
    size_t n = (size_t)(it->depth + 1) * (size_t)it->n_in;
    memset(it->y, 0, n * sizeof(duffid_real));
    memset(it->p1, 0, n * sizeof(duffid_real));
    memset(it->p2, 0, n * sizeof(duffid_real));
    it->count = 0;
}

/* OnlineIdentifier._set_target: the full window length and the change test's memory */
static void set_target(duffid_estimator *est, long samples)
{
    const duffid_real tau = est->cfg.change_memory > RC(0.0)
                                ? est->cfg.change_memory
                                : RC(DUFFID_CHANGE_WINDOWS) * (duffid_real)samples * est->dt;
    est->target = samples;
    est->lam_recent = R_EXP(-est->dt / tau);
    est->sqrt_lam_recent = R_SQRT(est->lam_recent);
    est->memory = (int64_t)R_FLOOR(tau / est->dt + RC(0.5));
    if (est->memory < 1) {
        est->memory = 1;
    }
}

static void count_up(int64_t *counter, int64_t limit)
{
    if (*counter < limit) {
        (*counter)++;
    }
}

/* the change test's per-equation state of _EquationState.clear */
static void clear_change(equation_t *eq, int n)
{
    int u;
    for (u = 0; u < n; u++) {
        eq->departure[u] = RC(0.0);
    }
    eq->departed = 0;
    eq->surprised = 0;
    eq->drifted = 0;
    eq->probed = 0;
    eq->probe_row = 0;
    eq->off_row = 0;
    for (u = 0; u < n; u++) {
        eq->off_moved[u] = 0;
    }
    eq->resume = 0;
    eq->recent_resume = 0;
    eq->residual = R_NAN;
    for (u = 0; u < n; u++) {
        eq->jump_shift[u] = RC(0.0);
        eq->rate_shift[u] = RC(0.0);
        eq->drift_shift[u] = RC(0.0);
        eq->noise_shift[u] = RC(0.0);
        NOMINAL(eq)[u] = R_INF;
    }
}

/* a fresh accumulated and recent least squares of block e (n_line unknowns): OnlineIdentifier's
 * new _QRLeastSquares and DriftLine objects */
static void clear_factors(duffid_estimator *est, int e)
{
    equation_t *eq = &est->eq[e];
    const int p = eq->line_cap + 1;
    int i;
    memset(eq->R, 0, (size_t)(p * p) * sizeof(duffid_real));
    memset(eq->R_recent, 0, (size_t)(p * p) * sizeof(duffid_real));
    memset(eq->noise_G, 0, (size_t)((p - 1) * p) * sizeof(duffid_real));
    memset(eq->noise_G_recent, 0, (size_t)((p - 1) * p) * sizeof(duffid_real));
    memset(eq->score, 0, (size_t)(p - 1) * sizeof(duffid_real));
    memset(LAST_SCORE(eq), 0, (size_t)(p - 1) * sizeof(duffid_real));
    memset(SCORES(eq), 0, (size_t)((p - 1) * (p - 1)) * sizeof(duffid_real));
    eq->scored = eq->blocks = RC(0.0);
    eq->block = 0;
    if (eq->probe_n > 0) {
        memset(eq->R_probe, 0, (size_t)(p * p) * sizeof(duffid_real));
    }
    if (eq->off_on) {
        const int q = est->m.blocks[e].n_unknowns + 2;
        memset(eq->R_off, 0, (size_t)(q * q) * sizeof(duffid_real));
        memset(eq->R_var, 0, sizeof eq->R_var);
    }
    eq->rows = eq->rows_recent = eq->times_recent = eq->rows_probe = eq->times_probe = eq->rows_off = RC(0.0);
    for (i = 0; i < eq->line_cap; i++) {
        eq->jump_v[i] = eq->rate_v[i] = RC(0.0);
    }
    if (eq->line_cap > est->m.blocks[e].n_unknowns) {
        for (i = 0; i < eq->line_cap; i++) {
            eq->line[i] = eq->line_recent[i] = R_NAN;
        }
        for (i = 0; i < eq->line_cap * eq->line_cap; i++) {
            eq->line_inv[i] = eq->line_recent_inv[i] = R_NAN;
        }
    }
    eq->line_sigma = eq->line_recent_sigma = R_INF;
}

static void guard_reset(duffid_estimator *est);

/* _JumpMoments.reset: no jump inside the window */
static void jumps_reset(duffid_estimator *est)
{
    memset(est->jump_flag, 0, (size_t)(est->capacity + 2));
    memset(est->jump_sum, 0, (size_t)((est->degree + 1) * est->n_forces) * sizeof(duffid_real));
    est->n_jumps = 0;
}

void duffid_reset(duffid_estimator *est)
{
    int i, u;
    if (est == NULL) {
        return;
    }
    est->n = -1;
    est->window_fixed = 0;
    est->window_capped = 0;
    est->spanned_from = -1;
    est->has_f_prev = est->has_f_change = 0;
    est->has_jump_candidate = est->has_jump = 0;
    memset(est->jump_candidate, 0, sizeof est->jump_candidate);
    memset(est->jump, 0, sizeof est->jump);
    memset(est->f_prev, 0, sizeof est->f_prev);
    memset(est->f_change, 0, sizeof est->f_change);
    memset(est->f_peak, 0, sizeof est->f_peak);
    est->deferred = 0;
    est->row_phase = 0;
    est->has_last_x = 0;
    memset(est->last_x, 0, sizeof est->last_x);
    memset(est->sgn, 0, sizeof est->sgn);
    est->noise_state = DUFFID_NOISE_SEED; /* row_noise.NoiseLevel.reset */
    duffid_la_noise_reset(&est->noise_level);
    est->received = -1;
    guard_reset(est);
    est->pending = 0;
    est->outliers = 0;
    est->outlier_t = R_NAN;
    est->outlier_value = R_NAN;
    est->outlier_replaced_by = R_NAN;
    est->outlier_first_value = R_NAN;
    est->outlier_first_replaced_by = R_NAN;
    est->outlier_column = -1;
    memset(&est->last, 0, sizeof est->last);
    est->last.residual = R_NAN;
    for (i = 0; i < DUFFID_MAX_PARAMS; i++) {
        est->last.parameters[i] = R_NAN;
        est->last.current[i] = R_NAN;
        est->last.std_errors[i] = R_NAN;
        est->last.status[i] = DUFFID_STATUS_UNCERTAIN;
    }
    for (i = 0; i < est->n_params; i++) {
        est->steady[i] = 0;
        est->period_seen[i] = R_NAN;
        est->anchor[i] = R_NAN;
        est->anchored[i] = 0;
        est->settled[i] = 0;
        est->unsettled[i] = 0;
        est->status[i] = DUFFID_STATUS_UNCERTAIN;
        est->fresh[i] = 0;
        est->credible_from[i] = 0;
        est->value[i] = R_NAN;
        est->changed_now[i] = -1;
        est->held[i] = R_NAN;
    }
    if (est->cfg.method == DUFFID_ROBUST) {
        const size_t moments = (size_t)(est->degree + 1) * (size_t)est->n_ch * sizeof(duffid_real);
        const size_t all = (size_t)(est->degree + 1) * (size_t)est->n_mom * sizeof(duffid_real);
        memset(est->ring, 0, (size_t)(est->capacity + 2) * (size_t)est->ring_width * sizeof(duffid_real));
        if (est->ring_raw) {
            memset(est->near, 0, (size_t)(NEAR * est->n_mom) * sizeof(duffid_real));
        }
        est->near_head = NEAR - 1; /* the first sample goes to slot 0 */
        memset(est->acc, 0, all);
        memset(est->shadow, 0, SHADOWS * all);
        memset(est->acc_alt, 0, moments);
        memset(est->shadow_alt, 0, SHADOWS * moments);
        est->rate_ok = 0;
        est->rate_L = -1;
        est->rate_n = 0;
        est->head = est->capacity + 1; /* the first sample goes to position 0 */
        est->start = 0;
        jumps_reset(est);
        for (i = 0; i < SHADOWS; i++) {
            est->shadow_from[i] = i == 0 ? 0 : -1;
        }
        set_target(est, est->capacity);
        est->regrow = 0;
        est->poly_L = -1;
        est->one_L = -1;
        est->corr_L = -1;
        est->leave_i = -1;
        for (i = 0; i < est->n_eq; i++) {
            for (u = 0; u < est->m.blocks[i].n_unknowns; u++) {
                est->eq[i].drifting[u] = 0;
            }
            est->eq[i].n_line = est->m.blocks[i].n_unknowns;
            est->eq[i].origin = 0;
            clear_factors(est, i);
        }
    } else {
        for (i = 0; i < est->n_eq; i++) {
            integrators_reset(&est->eq[i].reg);
            integrators_reset(&est->eq[i].det);
        }
    }
    for (i = 0; i < est->n_eq; i++) {
        for (u = 0; u < est->m.blocks[i].n_unknowns; u++) {
            est->eq[i].theta[u] = R_NAN;
            est->eq[i].rse[u] = R_INF;
            est->eq[i].share[u] = R_NAN;
        }
        clear_change(&est->eq[i], est->m.blocks[i].n_unknowns);
        est->eq[i].rhs_share = R_NAN;
        est->eq[i].cond = R_INF;
        est->eq[i].warm = 0;
    }
}

/* ------------------------------------------------------------------ channels */
/* a built-in model's channel c at x, f */
static duffid_real channel_value(const channel_t *c, const duffid_real *x, const duffid_real *f)
{
    switch (c->kind) {
    case CH_X:
        return int_power(x[c->index], c->power);
    case CH_DEFL:
        return int_power(x[c->index] - (c->index > 0 ? x[c->index - 1] : RC(0.0)), c->power);
    case CH_FORCE:
        return f[c->index];
    default:
        return RC(1.0);
    }
}

#ifdef DUFFID_GENERATED_MODEL
/* the generated model's channels at x, f into g (the channel function is CasADi's double code) */
static void generated_channels(duffid_estimator *est, const duffid_real *x, const duffid_real *f, duffid_real *g)
{
    double xd[DUFFID_MAX_DOF], fd[DUFFID_MAX_FORCES], sd[DUFFID_MAX_DOF], gd[MAX_CH];
    int i;
    for (i = 0; i < est->n_dof; i++) {
        xd[i] = (double)x[i];
        sd[i] = (double)est->sgn[i];
    }
    for (i = 0; i < est->n_forces; i++) {
        fd[i] = (double)f[i];
    }
    duffid_generated_channels(xd, fd, (double)est->n * (double)est->dt, sd, gd, est->chan_work);
    for (i = 0; i < est->n_ch; i++) {
        g[i] = (duffid_real)gd[i];
    }
}
#endif

/* ------------------------------------------------------------------ the rows' noise (row_noise) */
/* NoiseLevel.uniform: the next pseudo-random number of unit variance (xorshift32) */
static duffid_real noise_uniform(duffid_estimator *est)
{
    uint32_t v = est->noise_state;
    v ^= v << 13;
    v ^= v >> 17;
    v ^= v << 5;
    est->noise_state = v;
    return (RC(2.0) * ((duffid_real)v * RC(2.3283064365386963e-10)) - RC(1.0)) * RC(1.7320508075688772); /* v / 2^32 */
}

/* NoiseLevel.push and .perturbed: xn = x plus a noise of the level measured so far */
static void noise_perturbed(duffid_estimator *est, const duffid_real *x, duffid_real *xn)
{
    int j;
    duffid_la_noise_push(&est->noise_level, est->n_dof, x);
    for (j = 0; j < est->n_dof; j++) {
        xn[j] = x[j] + duffid_la_noise_sigma(&est->noise_level, j) * noise_uniform(est);
    }
}

static void evaluate_channels(duffid_estimator *est, const duffid_real *x, const duffid_real *f)
{
    int i;
    if (est->m.c.uses_sign) { /* _Channels: sgn(dx) where |dx| > deadband, else the previous sign */
        for (i = 0; i < est->n_dof && est->has_last_x; i++) {
            duffid_real dx = x[i] - est->last_x[i];
            if (R_FABS(dx) > est->deadband) {
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
        generated_channels(est, x, f, est->g);
#endif
    } else {
        for (i = 0; i < est->n_ch; i++) {
            est->g[i] = channel_value(&est->m.ch[i], x, f);
        }
    }
    for (i = 0; i < est->n_dof; i++) { /* the raw ring's sample (the noisy x: x without noise) */
        est->x_now[i] = est->xn_now[i] = x[i];
    }
    for (i = 0; i < est->n_forces; i++) {
        est->f_now[i] = f[i];
    }
    if (est->n_noise > 0 && !est->defer) { /* OnlineIdentifier._row_noise: the channels of x at xn minus
                                             * at x (a deferred run gives values only: none) */
        duffid_real *xn = est->xn_now;
        noise_perturbed(est, x, xn);
        if (est->cfg.model == DUFFID_GENERATED) {
#ifdef DUFFID_GENERATED_MODEL
            duffid_real gn[MAX_CH];
            generated_channels(est, xn, f, gn);
            for (i = 0; i < est->n_ch; i++) {
                if (est->noise_of[i] >= 0) {
                    est->g[est->noise_of[i]] = gn[i] - est->g[i];
                }
            }
#endif
        } else {
            for (i = 0; i < est->n_ch; i++) {
                if (est->noise_of[i] >= 0) {
                    est->g[est->noise_of[i]] = channel_value(&est->m.ch[i], xn, f) - est->g[i];
                }
            }
        }
    }
}

/* ------------------------------------------------------------------ moments */
/* The sliding moments (regressors.SlidingMoments) are kept in the falling-factorial basis
 * phi_j(i) = i (i-1) ... (i-j+1) / N^j of the sample's distance i from the newest sample:
 * when a sample arrives every distance grows by one, phi_j(i+1) = phi_j(i) + (j/N) phi_(j-1)(i),
 * a bidiagonal step with positive coefficients. */

/* ring position of the sample `back` samples before the newest */
static long ring_at(const duffid_estimator *est, long back)
{
    long k = est->head - back;
    return k < 0 ? k + est->capacity + 2 : k;
}

/* the first count of the n_mom channels (the model's, then their noise's) of the ring's sample
 * `back` samples before the newest: a pointer into a ring of channels, or, for a raw ring,
 * recomputed into buf from the sample's x, f and noisy x as evaluate_channels computed them */
static const duffid_real *ring_sample(const duffid_estimator *est, long back, int count, duffid_real *buf)
{
    const duffid_real *slot = est->ring + (size_t)ring_at(est, back) * (size_t)est->ring_width;
    const duffid_real *x = slot, *f = slot + est->n_dof, *xn = f + est->n_forces;
    int c;
    if (!est->ring_raw) {
        return slot;
    }
    if (back < NEAR) { /* kept as evaluate_channels computed them */
        const int k = est->near_head - (int)back;
        return est->near + (k < 0 ? k + NEAR : k) * est->n_mom;
    }
    for (c = 0; c < est->n_ch; c++) {
        buf[c] = channel_value(&est->m.ch[c], x, f);
    }
    for (c = 0; c < est->n_ch; c++) {
        const int k = est->noise_of[c];
        if (k >= 0 && k < count) {
            buf[k] = channel_value(&est->m.ch[c], xn, f) - buf[c];
        }
    }
    return buf;
}

/* phi_j(i), j = 0..degree */
static void factorial_basis(const duffid_estimator *est, long i, duffid_real *phi)
{
    int j;
    phi[0] = RC(1.0);
    for (j = 1; j <= est->degree; j++) {
        phi[j] = phi[j - 1] * (duffid_real)(i - j + 1) * est->inv_cap;
    }
}

/* regressors.gregory_corrections: the offsets and weights minus one of the rule over L
 * intervals; returns their count */
static int gregory_rule(long L, long *off, duffid_real *delta)
{
    static const duffid_real gregory[DUFFID_GREGORY_POINTS][DUFFID_GREGORY_POINTS] = DUFFID_GREGORY_END(RC);
    static const int nc_num[5][6] = {
        {1, 1, 0, 0, 0, 0}, {1, 4, 1, 0, 0, 0}, {3, 9, 9, 3, 0, 0},
        {14, 64, 24, 64, 14, 0}, {95, 375, 250, 250, 375, 95}};
    static const int nc_den[5] = {2, 3, 8, 45, 288};
    int m;
    if (L < 1) {
        off[0] = 0;
        delta[0] = RC(-1.0);
        return 1;
    }
    if (L <= 5) {
        for (m = 0; m <= L; m++) {
            off[m] = m;
            delta[m] = (duffid_real)nc_num[L - 1][m] / (duffid_real)nc_den[L - 1] - RC(1.0);
        }
        return (int)L + 1;
    }
    { /* regressors.gregory_points: fewer where the two ends would meet */
        const int p = L + 1 < 2 * DUFFID_GREGORY_POINTS ? (int)(L + 1) / 2 : DUFFID_GREGORY_POINTS;
        for (m = 0; m < p; m++) {
            off[m] = m;
            off[p + m] = L - m;
            delta[m] = delta[p + m] = gregory[p - 1][m];
        }
        return 2 * p;
    }
}

/* w[j][m] (j * MAX_CORR + m) = delta_m x the factorial basis at off[m] */
static void basis_weights(const duffid_estimator *est, int count, const long *off, const duffid_real *delta,
                          duffid_real *w)
{
    const int D1 = est->degree + 1;
    duffid_real phi[MAX_POW];
    int m, j;
    for (m = 0; m < count; m++) {
        factorial_basis(est, off[m], phi);
        for (j = 0; j < D1; j++) {
            w[j * MAX_CORR + m] = phi[j] * delta[m];
        }
    }
}

/* regressors.gregory_corrections (SlidingMoments._corrections) in the factorial basis, cached
 * for one L */
static void corrections(duffid_estimator *est, long L)
{
    duffid_real delta[MAX_CORR];
    const int D1 = est->degree + 1;
    int m;
    if (est->corr_L == L) {
        return;
    }
    est->corr_n = gregory_rule(L, est->corr_off, delta);
    basis_weights(est, est->corr_n, est->corr_off, delta, est->corr_w);
    est->corr_near = 0;
    for (m = 0; m < est->corr_n; m++) {
        est->corr_top[m] = est->corr_off[m] + 1 < D1 ? (int)est->corr_off[m] + 1 : D1; /* phi_j(i) = 0, j > i */
        if (est->corr_near == m && est->corr_off[m] == m && est->corr_top[m] < D1) {
            est->corr_near = m + 1;
        } else if (est->corr_top[m] < D1) {
            est->corr_near = -1; /* a short one after a full one */
        }
    }
    est->corr_L = L;
}

/* SlidingMoments._rate_weights (the basis is applied as they are used), cached for one L (at least 2): the
 * rule's corrections over the even part L_e, minus twice the half-rate rule's at every second
 * sample, and minus the oldest sample when L is odd (one weight per distinct offset) */
static void rate_weights(duffid_estimator *est, long L)
{
    long off[MAX_RATE], half_off[MAX_CORR];
    duffid_real delta[MAX_RATE], half[MAX_CORR];
    const long even = L - L % 2;
    int n, n_half, m, i;
    if (est->rate_L == L) {
        return;
    }
    /* an even window's own corrections are the rule's over L_e: moments_push takes them from
     * fact - acc, so only the half-rate rule's are listed */
    n = L % 2 ? gregory_rule(even, off, delta) : 0;
    n_half = gregory_rule(even / 2, half_off, half);
    for (m = 0; m < n_half + (L % 2); m++) {
        const long at = m < n_half ? 2 * half_off[m] : L;
        const duffid_real w = m < n_half ? RC(-2.0) * half[m] : RC(-1.0);
        for (i = 0; i < n && off[i] != at; i++) {
        }
        if (i == n) {
            off[n] = at;
            delta[n++] = RC(0.0);
        }
        delta[i] += w;
    }
    est->rate_n = n;
    memcpy(est->rate_off, off, (size_t)n * sizeof(long));
    memcpy(est->rate_delta, delta, (size_t)n * sizeof(duffid_real));
    est->rate_L = L;
}

/* step an accumulator of n_ch channels: every sample one further away (acc[c * (degree + 1) + j]),
 * the new sample g in; leaving (if not NULL) is the sample that leaves the window, phi its basis
 * values at its distance */
static void shift_accumulator(const duffid_estimator *est, int n_ch, duffid_real *acc, const duffid_real *g,
                              const duffid_real *leaving, const duffid_real *phi)
{
    const int D1 = est->degree + 1;
    int j, c;
    for (c = 0; c < n_ch; c++) {
        duffid_real *a = acc + c * D1, below = a[0];
        if (leaving != NULL) {
            const duffid_real old = leaving[c];
            for (j = 1; j < D1; j++) { /* row j uses the old row j-1 */
                const duffid_real here = a[j];
                a[j] = here + est->step[j] * below - phi[j] * old;
                below = here;
            }
            a[0] += g[c] - phi[0] * old;
        } else {
            for (j = 1; j < D1; j++) {
                const duffid_real here = a[j];
                a[j] = here + est->step[j] * below;
                below = here;
            }
            a[0] += g[c];
        }
    }
}

/* acc += sign * phi(i) x sample (n_ch channels) */
static void accumulate(const duffid_estimator *est, int n_ch, duffid_real *acc, const duffid_real *phi,
                       const duffid_real *sample, duffid_real sign)
{
    const int D1 = est->degree + 1;
    int j, c, top = 0;
    while (top < D1 && phi[top] != RC(0.0)) {
        top++; /* phi_j(i) = 0 for j > i */
    }
    for (c = 0; c < n_ch; c++) {
        const duffid_real w = sign * sample[c];
        duffid_real *a = acc + c * D1;
        for (j = 0; j < top; j++) {
            a[j] += w * phi[j];
        }
    }
}

/* the leaving sample's basis values at distance i (cached: in a sliding window it is always the same) */
static const duffid_real *leaving_basis(duffid_estimator *est, long i)
{
    if (est->leave_i != i) {
        factorial_basis(est, i, est->leave_phi);
        est->leave_i = i;
    }
    return est->leave_phi;
}

/* the power moments S_k = sum_j S2(k, j) N^(j-k) / N x fact_j (positive weights;
 * S2(k, 0) = 0 for k > 0), channel after channel (n_ch of them) */
static void power_moments(const duffid_estimator *est, int n_ch, const duffid_real *fact, duffid_real *mom)
{
    const int D = est->degree, D1 = D + 1;
    int c, k;
    for (c = 0; c + 1 < n_ch; c += 2) { /* two channels at a time: each weight is loaded once */
        const duffid_real *in = fact + c * D1, *in2 = in + D1;
        duffid_real *out = mom + c * D1, *out2 = out + D1;
        out[0] = est->stirling[0] * in[0];
        out2[0] = est->stirling[0] * in2[0];
        for (k = 1; k <= D; k++) {
            const duffid_real *st = est->stirling + k * D1;
            duffid_real sum = RC(0.0), sum2 = RC(0.0);
            int i;
            for (i = 1; i <= k; i++) {
                sum += st[i] * in[i];
                sum2 += st[i] * in2[i];
            }
            out[k] = sum;
            out2[k] = sum2;
        }
    }
    if (c < n_ch) { /* an odd channel */
        const duffid_real *in = fact + c * D1;
        duffid_real *out = mom + c * D1;
        out[0] = est->stirling[0] * in[0];
        for (k = 1; k <= D; k++) {
            const duffid_real *st = est->stirling + k * D1;
            duffid_real sum = RC(0.0);
            int i;
            for (i = 1; i <= k; i++) {
                sum += st[i] * in[i];
            }
            out[k] = sum;
        }
    }
}

/* out = sign x sample (n_ch values): a sample of the alternating sums */
static void signed_sample(const duffid_real *sample, duffid_real sign, int n_ch, duffid_real *out)
{
    int c;
    for (c = 0; c < n_ch; c++) {
        out[c] = sign * sample[c];
    }
}

/* fact = acc + the end corrections of the rule's usual shape (corrections: corr_near offsets
 * 0, 1, ... near the newest sample, short in the basis, then the far ones, full), each entry
 * summed in the order of the general loop (the full ones, then the short ones), two channels
 * at a time: each weight is loaded once */
static void end_corrections(duffid_estimator *est, int n_ch, const duffid_real *const *sample, int near)
{
    const int D1 = est->degree + 1, n_far = est->corr_n - near;
    int c, k, m;
    for (c = 0; c < n_ch; c += 2) {
        const int pair = c + 1 < n_ch;
        const duffid_real *a = est->acc + c * D1, *a2 = a + (pair ? D1 : 0);
        duffid_real *out = est->fact + c * D1, *out2 = out + D1;
        duffid_real v[MAX_CORR], v2[MAX_CORR];
        for (m = 0; m < est->corr_n; m++) {
            v[m] = sample[m][c];
            v2[m] = sample[m][pair ? c + 1 : c];
        }
        for (k = 0; k < D1; k++) {
            const duffid_real *w = est->corr_w + k * MAX_CORR;
            duffid_real sum = a[k], sum2 = a2[k];
            if (pair) {
                for (m = near; m < near + n_far; m++) {
                    sum += w[m] * v[m];
                    sum2 += w[m] * v2[m];
                }
                for (m = k; m < near; m++) { /* phi_k(m) = 0 for m < k */
                    sum += w[m] * v[m];
                    sum2 += w[m] * v2[m];
                }
                out2[k] = sum2;
            } else { /* an odd channel */
                for (m = near; m < near + n_far; m++) {
                    sum += w[m] * v[m];
                }
                for (m = k; m < near; m++) {
                    sum += w[m] * v[m];
                }
            }
            out[k] = sum;
        }
    }
}

/* SlidingMoments.push: the moments of the window (into est->mom, mom[c * (degree + 1) + k])
 * and its length L */
static long moments_push(duffid_estimator *est, long window)
{
    const long N = est->capacity;
    /* the moments are those of n_mom channels: the model's and, but in a deferred run (values
     * only), their noise's; the alternating sums the model's channels' only (the rows at half
     * the rate); the ring's samples are read through ring_sample */
    const int n_ch = est->n_ch, n_mom = est->defer ? est->n_ch : est->n_mom;
    duffid_real *one = est->ring_buf + MAX_CORR * est->n_mom; /* a raw ring's sample's channels */
    const int D = est->degree, D1 = D + 1;
    const int64_t n = est->n; /* SlidingMoments.n == OnlineIdentifier.n */
    const size_t bytes = (size_t)(D1 * n_mom) * sizeof(duffid_real), bytes_alt = (size_t)(D1 * n_ch) * sizeof(duffid_real);
    duffid_real phi[MAX_POW], signed_g[MAX_CH], leaving[MAX_CH];
    const duffid_real sign = (n & 1) ? RC(-1.0) : RC(1.0); /* (-1)^n: the alternating sums' */
    const int alt = !est->defer; /* the alternating sums feed only the half-rate rows, which deferred
                                  * solutions skip (duffid_defer_solutions) */
    int64_t j, new_start;
    long w, L;
    int k, c, m;
    duffid_real *slot;

    est->head = est->head == N + 1 ? 0 : est->head + 1;
    slot = est->ring + (size_t)est->head * (size_t)est->ring_width;
    if (est->ring_raw) { /* x, f, the noisy x; the channels of the newest samples */
        est->near_head = est->near_head + 1 == NEAR ? 0 : est->near_head + 1;
        memcpy(est->near + est->near_head * est->n_mom, est->g, (size_t)n_mom * sizeof(duffid_real));
        memcpy(slot, est->x_now, (size_t)est->n_dof * sizeof(duffid_real));
        memcpy(slot + est->n_dof, est->f_now, (size_t)est->n_forces * sizeof(duffid_real));
        if (est->n_noise > 0) {
            memcpy(slot + est->n_dof + est->n_forces, est->xn_now, (size_t)est->n_dof * sizeof(duffid_real));
        }
    } else {
        for (c = 0; c < n_mom; c++) {
            slot[c] = est->g[c];
        }
    }
    for (c = 0; c < n_ch; c++) {
        signed_g[c] = sign * est->g[c];
    }
    w = window < N ? window : N;
    new_start = n - w > est->start ? n - w : est->start;
    if (new_start == est->start + 1) { /* a sliding window: one sample leaves */
        const long i = (long)(n - est->start);
        const duffid_real *old = ring_sample(est, i, n_mom, one);
        shift_accumulator(est, n_mom, est->acc, est->g, old, leaving_basis(est, i));
        if (alt) {
            signed_sample(old, (i & 1) ? -sign : sign, n_ch, leaving);
            shift_accumulator(est, n_ch, est->acc_alt, signed_g, leaving, leaving_basis(est, i));
        }
        est->start = new_start;
    } else {
        shift_accumulator(est, n_mom, est->acc, est->g, NULL, NULL);
        if (alt) {
            shift_accumulator(est, n_ch, est->acc_alt, signed_g, NULL, NULL);
        }
        if (new_start - est->start > (int64_t)w + 1) {
            /* many samples leave at once (the window shrank): rebuilding from the new window
             * costs less than removing them one by one */
            est->start = new_start;
            est->shadow_from[0] = est->start - 1; /* rebuilt below */
        } else {
            for (j = est->start; j < new_start; j++) { /* samples leaving the window */
                const long i = (long)(n - j);
                const duffid_real *old = ring_sample(est, i, n_mom, one);
                accumulate(est, n_mom, est->acc, leaving_basis(est, i), old, RC(-1.0));
                if (alt) {
                    signed_sample(old, (i & 1) ? -sign : sign, n_ch, leaving);
                    accumulate(est, n_ch, est->acc_alt, leaving_basis(est, i), leaving, RC(-1.0));
                }
            }
            est->start = new_start;
        }
    }
    for (k = 0; k < SHADOWS; k++) {
        if (est->shadow_from[k] >= 0) {
            shift_accumulator(est, n_mom, est->shadow + k * D1 * est->n_mom, est->g, NULL, NULL);
            if (alt) {
                shift_accumulator(est, n_ch, est->shadow_alt + k * D1 * n_ch, signed_g, NULL, NULL);
            }
        }
    }
    for (k = 0; k < SHADOWS; k++) {
        duffid_real *shadow = est->shadow + k * D1 * est->n_mom, *shadow_alt = est->shadow_alt + k * D1 * n_ch;
        if (est->shadow_from[k] >= 0 && est->shadow_from[k] < est->start) {
            /* the shadow holds samples outside the window (it shrank): the first is rebuilt
             * from the window, the others start again */
            if (k == 0) {
                long i;
                est->shadow_from[0] = est->start;
                memset(shadow, 0, bytes);
                memset(shadow_alt, 0, bytes_alt);
                for (i = 0; i <= (long)(n - est->start); i++) {
                    const duffid_real *old = ring_sample(est, i, n_mom, one);
                    factorial_basis(est, i, phi);
                    accumulate(est, n_mom, shadow, phi, old, RC(1.0));
                    if (alt) {
                        signed_sample(old, (i & 1) ? -sign : sign, n_ch, leaving);
                        accumulate(est, n_ch, shadow_alt, phi, leaving, RC(1.0));
                    }
                }
            } else {
                est->shadow_from[k] = -1;
            }
        }
    }
    for (k = 0; k < SHADOWS; k++) {
        duffid_real *shadow = est->shadow + k * D1 * est->n_mom, *shadow_alt = est->shadow_alt + k * D1 * n_ch;
        if (est->shadow_from[k] == est->start && n - est->start >= 1) {
            /* the shadow holds exactly the window: it becomes the main accumulator */
            memcpy(est->acc, shadow, bytes);
            memcpy(est->acc_alt, shadow_alt, bytes_alt);
            memset(shadow, 0, bytes);
            memset(shadow_alt, 0, bytes_alt);
            est->shadow_from[k] = n + 1;
        }
    }
#if SHADOWS > 1
    { /* start a free shadow a window / SHADOWS after the latest */
        int64_t latest = -1;
        for (k = 0; k < SHADOWS; k++) {
            latest = est->shadow_from[k] > latest ? est->shadow_from[k] : latest;
        }
        for (k = 0; k < SHADOWS; k++) {
            if (est->shadow_from[k] < 0 && SHADOWS * (n + 1 - latest) >= (int64_t)w) {
                memset(est->shadow + k * D1 * est->n_mom, 0, bytes);
                memset(est->shadow_alt + k * D1 * n_ch, 0, bytes_alt);
                est->shadow_from[k] = n + 1;
                break;
            }
        }
    }
#endif
    L = (long)(n - est->start);
    est->rows_skipped = 0;
    if (est->defer > 1 && L >= est->target) { /* a deferred run's rows every defer-th full window */
        est->rows_skipped = est->row_phase != 0;
        est->row_phase = est->row_phase + 1 == est->defer ? 0 : est->row_phase + 1;
        if (est->rows_skipped) {
            est->rate_ok = 0;
            return L;
        }
    }
    corrections(est, L);
    { /* fact = acc + the quadrature's end corrections (those near the newest sample are short) */
        const duffid_real *sample[MAX_CORR];
        for (m = 0; m < est->corr_n; m++) {
            sample[m] = ring_sample(est, est->corr_off[m], n_mom, est->ring_buf + m * est->n_mom);
        }
        if (est->corr_near >= 0) {
            end_corrections(est, n_mom, sample, est->corr_near);
        } else { /* the full ones first, then the short ones */
            for (c = 0; c < n_mom; c++) {
                duffid_real *out = est->fact + c * D1;
                memcpy(out, est->acc + c * D1, (size_t)D1 * sizeof(duffid_real));
                for (m = 0; m < est->corr_n; m++) {
                    if (est->corr_top[m] == D1) {
                        const duffid_real v = sample[m][c];
                        for (k = 0; k < D1; k++) {
                            out[k] += est->corr_w[k * MAX_CORR + m] * v;
                        }
                    }
                }
                for (m = 0; m < est->corr_n; m++) {
                    if (est->corr_top[m] < D1) {
                        const duffid_real v = sample[m][c];
                        for (k = 0; k < est->corr_top[m]; k++) {
                            out[k] += est->corr_w[k * MAX_CORR + m] * v;
                        }
                    }
                }
            }
        }
    }
    power_moments(est, n_mom, est->fact, est->mom);
    /* SlidingMoments.rate_difference: minus the alternating sums plus the rules' corrections */
    est->rate_ok = L >= 2 && !est->defer; /* deferred solutions publish nothing */
    if (est->rate_ok) {
        rate_weights(est, L);
        if (L % 2) {
            for (k = 0; k < D1 * n_ch; k++) {
                est->dfact[k] = -sign * est->acc_alt[k];
            }
        } else { /* the rule's corrections over L_e = L: fact - acc */
            for (k = 0; k < D1 * n_ch; k++) {
                est->dfact[k] = -sign * est->acc_alt[k] + (est->fact[k] - est->acc[k]);
            }
        }
        for (m = 0; m < est->rate_n; m++) {
            const long at = est->rate_off[m];
            const duffid_real *sample = ring_sample(est, at, n_ch, one);
            const int top = at + 1 < D1 ? (int)at + 1 : D1; /* phi_j(i) = 0, j > i */
            factorial_basis(est, at, phi);
            for (c = 0; c < n_ch; c++) {
                const duffid_real v = est->rate_delta[m] * sample[c];
                duffid_real *out = est->dfact + c * D1;
                for (k = 0; k < top; k++) {
                    out[k] += phi[k] * v;
                }
            }
        }
        power_moments(est, n_ch, est->dfact, est->dmom);
    }
    return L;
}


/* ------------------------------------------------------------------ force jumps (JUMP_ERROR) */
/* x^0 .. x^D by multiplication (_JumpMoments._powers) */
static void jump_powers(int D, duffid_real x, duffid_real *out)
{
    int q;
    out[0] = RC(1.0);
    for (q = 1; q <= D; q++) {
        out[q] = out[q - 1] * x;
    }
}

/* the forces' jumps in the interval that ends at sample k (its ring position back from the
 * newest sample n), from the ring: df_j, 0 where force j did not jump */
static void jump_at(const duffid_estimator *est, long back, duffid_real *df)
{
    const unsigned char flags = est->jump_flag[ring_at(est, back)];
    const duffid_real *now = est->ring + (size_t)ring_at(est, back) * (size_t)est->ring_width;
    const duffid_real *before = est->ring + (size_t)ring_at(est, back + 1) * (size_t)est->ring_width;
    int j;
    for (j = 0; j < est->n_forces; j++) { /* a raw ring holds the forces after x */
        const int c = est->ring_raw ? est->n_dof + j : est->force_channel[j];
        df[j] = (flags >> j) & 1u && est->force_channel[j] >= 0 ? now[c] - before[c] : RC(0.0);
    }
}

/* _JumpMoments.step after moments_push (the window's oldest sample was old_start before it):
 * the sums one sample further, the jumps whose interval left the window subtracted, the
 * isolated jump of force_jumps added */
static void jumps_step(duffid_estimator *est, int64_t old_start)
{
    const int D = est->degree, D1 = D + 1, nf = est->n_forces;
    const int64_t n = est->n;
    duffid_real pw[MAX_POW], df[DUFFID_MAX_FORCES];
    int64_t k;
    int q, r, j;
    est->jump_flag[est->head] = 0; /* the newest sample's position held a sample long gone */
    if (est->n_jumps > 0) {
        const duffid_real h = est->inv_cap;
        for (q = D; q >= 1; q--) { /* S_q <- sum_r C(q, r) h^(q-r) S_r */
            for (j = 0; j < nf; j++) {
                duffid_real total = est->jump_sum[q * nf + j], c = RC(1.0), hp = RC(1.0);
                for (r = q - 1; r >= 0; r--) {
                    c = c * (duffid_real)(r + 1) / (duffid_real)(q - r);
                    hp *= h;
                    total += c * hp * est->jump_sum[r * nf + j];
                }
                est->jump_sum[q * nf + j] = total;
            }
        }
        for (k = old_start + 1; k <= est->start && est->n_jumps > 0; k++) { /* interval k-1..k left */
            const long back = (long)(n - k);
            if (est->jump_flag[ring_at(est, back)] == 0) {
                continue;
            }
            jump_at(est, back, df);
            jump_powers(D, ((duffid_real)back + RC(0.5)) * est->inv_cap, pw);
            for (q = 0; q < D1; q++) {
                for (j = 0; j < nf; j++) {
                    est->jump_sum[q * nf + j] -= pw[q] * df[j];
                }
            }
            est->jump_flag[ring_at(est, back)] = 0;
            est->n_jumps--;
        }
    }
    if (est->has_jump && n - 2 >= est->start) { /* the interval n-2..n-1 */
        unsigned char flags = 0;
        for (j = 0; j < nf; j++) {
            if (est->jump[j] != RC(0.0)) {
                flags = (unsigned char)(flags | (1u << j));
            }
        }
        est->jump_flag[ring_at(est, 1)] = flags;
        est->n_jumps++;
        jump_at(est, 1, df);
        jump_powers(D, RC(1.5) * est->inv_cap, pw);
        for (q = 0; q < D1; q++) {
            for (j = 0; j < nf; j++) {
                est->jump_sum[q * nf + j] += pw[q] * df[j];
            }
        }
    }
    if (est->n_jumps == 0) {
        memset(est->jump_sum, 0, (size_t)(D1 * nf) * sizeof(duffid_real));
    }
}

/* OnlineIdentifier._jump_columns for block b into est->jump_J (parts x n_rows, as B's rows):
 * its force terms' kernel entries on the jumps' moments (sums / N) */
static void jump_column(duffid_estimator *est, const block_t *b)
{
    const int nf = est->n_forces, n_rows = est->n_rows;
    int k, r, i;
    memset(est->jump_J, 0, (size_t)(b->n_parts * n_rows) * sizeof(duffid_real));
    for (k = 0; k < b->n_terms; k++) {
        const term_t *t = &est->m.terms[b->term0 + k];
        int force = -1;
        for (i = 0; i < nf; i++) {
            force = t->unknown < 0 && est->force_channel[i] == t->channel ? i : force;
        }
        if (force < 0) {
            continue;
        }
        for (r = 0; r < n_rows; r++) {
            const int at = est->k_at[r * N_ORD + t->order], first = est->k_first[r * N_ORD + t->order];
            duffid_real sum = RC(0.0);
            for (i = 0; i < est->k_count[r * N_ORD + t->order]; i++) {
                sum += est->poly[at + i] * est->jump_sum[(first + i) * nf + force] * est->inv_cap;
            }
            est->jump_J[t->part * n_rows + r] += t->coef * sum * est->entry_scale[r * N_ORD + t->order];
        }
    }
}

/* _jump_shift: (R^T R)^-1 v for the n x n leading block of the p x p factor R; zeros when v
 * is zero or R singular */
static void jump_shift(int n, int p, const duffid_real *R, const duffid_real *v, duffid_real *out)
{
    duffid_real w[MAX_LINE];
    int i, k, any = 0;
    for (i = 0; i < n; i++) {
        any |= v[i] != RC(0.0) && R[i * p + i] != RC(0.0);
        out[i] = RC(0.0);
    }
    for (i = 0; i < n; i++) {
        if (R[i * p + i] == RC(0.0)) {
            return;
        }
    }
    if (!any) {
        return;
    }
    for (i = 0; i < n; i++) { /* R^T w = v */
        duffid_real sum = v[i];
        for (k = 0; k < i; k++) {
            sum -= R[k * p + i] * w[k];
        }
        w[i] = sum / R[i * p + i];
    }
    for (i = n - 1; i >= 0; i--) { /* R out = w */
        duffid_real sum = w[i];
        for (k = i + 1; k < n; k++) {
            sum -= R[i * p + k] * out[k];
        }
        out[i] = sum / R[i * p + i];
    }
}

/* A^T J of the m rows B (column after column, n columns) */
static void jump_product(const duffid_real *B, const duffid_real *J, int m, int n, duffid_real lam, duffid_real *v)
{
    int i, r;
    for (i = 0; i < n; i++) {
        duffid_real sum = RC(0.0);
        for (r = 0; r < m; r++) {
            sum += B[i * m + r] * J[r];
        }
        v[i] = lam * v[i] + sum;
    }
}

/* ------------------------------------------------------------------ the rows' noise's bias */
/* S = dA^T [dA dD] of the m rows' noise B ([dA dD] column after column, nl + 1 columns; S is
 * nl x (nl + 1), its leading nl x nl block symmetric) */
static void noise_product(const duffid_real *B, int m, int nl, duffid_real *S)
{
    int i, k, r;
    for (i = 0; i < nl; i++) {
        for (k = i; k <= nl; k++) {
            duffid_real sum = RC(0.0);
            for (r = 0; r < m; r++) {
                sum += B[i * m + r] * B[k * m + r];
            }
            S[i * (nl + 1) + k] = sum;
            if (k < nl) {
                S[k * (nl + 1) + i] = sum;
            }
        }
    }
}

/* G = lam G + S (nl x (nl + 1)): the rows' noise accumulated with the rows' forgetting */
static void noise_forget(const duffid_real *S, int nl, duffid_real lam, duffid_real *G)
{
    int i;
    for (i = 0; i < nl * (nl + 1); i++) {
        G[i] = lam * G[i] + S[i];
    }
}

/* R^-T b of the n x n leading block of the p x p factor R (forward substitution); b and out
 * are read and written with strides sb and so */
static void forward_solve(int n, int p, const duffid_real *R, const duffid_real *b, int sb, duffid_real *out, int so)
{
    int i, k;
    for (i = 0; i < n; i++) {
        duffid_real sum = RC(0.0);
        for (k = 0; k < i; k++) {
            sum += R[k * p + i] * out[k * so];
        }
        out[i * so] = (b[i * sb] - sum) / R[i * p + i];
    }
}

/* row_noise._cholesky: the lower factor L of s I - M (its lower triangle); 0 unless positive definite */
static int noise_cholesky(int n, duffid_real s, const duffid_real *M, duffid_real *L)
{
    int i, j, k;
    for (j = 0; j < n; j++) {
        duffid_real d = RC(0.0);
        for (k = 0; k < j; k++) {
            d += L[j * n + k] * L[j * n + k];
        }
        d = (s - M[j * n + j]) - d;
        if (!(d > RC(0.0))) {
            return 0;
        }
        L[j * n + j] = R_SQRT(d);
        for (i = j + 1; i < n; i++) {
            duffid_real sum = RC(0.0);
            for (k = 0; k < j; k++) {
                sum += L[i * n + k] * L[j * n + k];
            }
            L[i * n + j] = (-M[i * n + j] - sum) / L[j * n + j];
        }
    }
    return 1;
}

/* row_noise.noise_shift: how the rows' noise (G = dA^T [dA dD], n x (n + 1)) moves the solution
 * of the p x p factor R (its n x n leading block and column n): R^-1 (I - M)^-1 (M z - R^-T c),
 * M = R^-T N R^-1; infinite where DUFFID_NOISE_SHARE I - M is not positive definite, zeros
 * without noise or for a singular R; work: 3 n^2 */
static void noise_shift_of(int n, int p, const duffid_real *R, const duffid_real *G, duffid_real *work,
                           duffid_real *out)
{
    duffid_real *Y = work, *M = work + n * n, *L = work + 2 * n * n;
    duffid_real z[MAX_LINE], rhs[MAX_LINE], w[MAX_LINE];
    int i, k, any = 0, singular = 0;
    for (i = 0; i < n; i++) {
        for (k = 0; k < n; k++) {
            any |= G[i * (n + 1) + k] != RC(0.0);
        }
        singular |= R[i * p + i] == RC(0.0);
        out[i] = RC(0.0);
    }
    if (!any || singular) {
        return;
    }
    for (k = 0; k < n; k++) { /* Y = R^-T N, column after column */
        forward_solve(n, p, R, G + k, n + 1, Y + k, n);
    }
    for (k = 0; k < n; k++) { /* M's column k: R^-T (row k of Y) */
        forward_solve(n, p, R, Y + k * n, 1, M + k, n);
    }
    if (!noise_cholesky(n, RC(DUFFID_NOISE_SHARE), M, L) || !noise_cholesky(n, RC(1.0), M, L)) {
        for (i = 0; i < n; i++) {
            out[i] = R_INF;
        }
        return;
    }
    forward_solve(n, p, R, G + n, n + 1, w, 1); /* R^-T c */
    for (i = 0; i < n; i++) {
        z[i] = R[i * p + n];
    }
    for (i = 0; i < n; i++) {
        duffid_real sum = RC(0.0);
        for (k = 0; k < n; k++) {
            sum += M[i * n + k] * z[k];
        }
        rhs[i] = sum - w[i];
    }
    for (i = 0; i < n; i++) { /* L y = rhs */
        duffid_real sum = RC(0.0);
        for (k = 0; k < i; k++) {
            sum += L[i * n + k] * w[k];
        }
        w[i] = (rhs[i] - sum) / L[i * n + i];
    }
    for (i = n - 1; i >= 0; i--) { /* L^T s = y */
        duffid_real sum = RC(0.0);
        for (k = i + 1; k < n; k++) {
            sum += L[k * n + i] * rhs[k];
        }
        rhs[i] = (w[i] - sum) / L[i * n + i];
    }
    for (i = n - 1; i >= 0; i--) { /* R out = s */
        duffid_real sum = RC(0.0);
        for (k = i + 1; k < n; k++) {
            sum += R[i * p + k] * out[k];
        }
        out[i] = (rhs[i] - sum) / R[i * p + i];
    }
}

/* ------------------------------------------------------------------ kernel entries */
/* KernelBank.entries: E[r, d, channel] for a window of L samples (the orders and channels
 * a term reads) */
static void kernel_entries(duffid_estimator *est, long L)
{
    const int n_rows = est->n_rows, n_ch = est->n_mom;
    const duffid_real tau = (duffid_real)L * est->inv_cap;
    int r, k, u;
    if (est->poly_L != L) {
        duffid_real tau_pow[2 * MAX_POW + 2];
        tau_pow[0] = RC(1.0);
        for (k = 1; k < 2 * MAX_POW + 2; k++) {
            tau_pow[k] = tau_pow[k - 1] * tau;
        }
        for (k = 0; k < est->n_coef; k++) {
            est->poly[k] = est->k_coef[k] * tau_pow[est->k_expo[k]];
        }
        for (r = 0; r < n_rows; r++) {
            const duffid_real row_scale = est->norm[r] / tau_pow[est->norm_power[r]];
            int d;
            for (d = 0; d < N_ORD; d++) {
                est->entry_scale[r * N_ORD + d] = row_scale * est->d_scale[d];
            }
            est->raw_pow[r] = est->raw_b[r] >= 0 ? tau_pow[est->raw_b[r]] : RC(0.0);
        }
        est->poly_L = L;
    }
#if DUFFID_SINGLE
    duffid_real norm2 = RC(0.0), size2 = RC(0.0);
#endif
    for (u = 0; u < est->n_jobs; u++) {
        const int *job = est->job + 5 * u, count = job[2], entry = job[3];
        const duffid_real *poly = est->poly + job[0], *m = est->mom + job[1];
        const duffid_real scale = est->entry_scale[entry / n_ch];
        duffid_real sum = RC(0.0);
#if DUFFID_SINGLE
        duffid_real size = RC(0.0); /* the sum of the terms' magnitudes: how much they cancel */
        for (k = 0; k < count; k++) {
            const duffid_real term = poly[k] * m[k];
            sum += term;
            size += R_FABS(term);
        }
        if (job[4] >= 0) { /* the raw term of a row with a = 1 */
            const duffid_real term = est->raw_pow[job[4]] * est->g[entry % n_ch];
            sum += term;
            size += R_FABS(term);
        }
        norm2 += sum * sum * scale * scale;
        size2 += size * size * scale * scale;
#else
        for (k = 0; k < count; k++) {
            sum += poly[k] * m[k];
        }
        if (job[4] >= 0) { /* the raw term of a row with a = 1 */
            sum += est->raw_pow[job[4]] * est->g[entry % n_ch];
        }
#endif
        est->E[entry] = sum * scale;
    }
#if DUFFID_SINGLE
    /* the entries' relative rounding error: eps sqrt(L) (the moments' sums) times how much
     * their terms cancel */
    est->rounding = norm2 > RC(0.0) ? R_EPS * R_SQRT((duffid_real)L * size2 / norm2) : R_INF;
#endif
    for (u = est->n_jobs; u < est->n_jobs + (est->defer ? 0 : est->n_noise_jobs); u++) { /* the rows' noise's */
        const int *job = est->job + 5 * u, count = job[2], entry = job[3];
        const duffid_real *poly = est->poly + job[0], *m = est->mom + job[1];
        duffid_real sum = RC(0.0);
        for (k = 0; k < count; k++) {
            sum += poly[k] * m[k];
        }
        if (job[4] >= 0) {
            sum += est->raw_pow[job[4]] * est->g[entry % n_ch];
        }
        est->E[entry] = sum * est->entry_scale[entry / n_ch];
    }
}

/* OnlineIdentifier._rate_rows: the kernel entries of the moments' difference at half the rate
 * (est->dmom) with the window's kernels (kernel_entries' cache, for this L), into est->E_rate
 * (the raw terms cancel) */
static void rate_entries(duffid_estimator *est)
{
    const int n_ch = est->n_mom;
    int k, u;
    for (u = 0; u < est->n_jobs; u++) {
        const int *job = est->job + 5 * u, count = job[2], entry = job[3];
        const duffid_real *poly = est->poly + job[0], *m = est->dmom + job[1];
        duffid_real sum = RC(0.0);
        for (k = 0; k < count; k++) {
            sum += poly[k] * m[k];
        }
        est->E_rate[entry] = sum * est->entry_scale[entry / n_ch];
    }
}

/* rows of [A D] of one block (identification._Assembly) into B, column after column
 * (B[col * m + row], m = parts * n_rows rows: those of each equation of the block, one
 * equation after the other); E[(r * N_ORD + d) * n_mom + c]. noise: the rows' noise [dA dD]
 * instead, from the channels' noise channels (0 for a channel without). */
static void assemble(const duffid_estimator *est, const block_t *b, const duffid_real *E, int n_rows, int noise,
                     duffid_real *B)
{
    const int p = b->n_unknowns + 1, n_ch = est->n_mom, m = b->n_parts * n_rows;
    int r, k;
    memset(B, 0, (size_t)(m * p) * sizeof(duffid_real));
    for (k = 0; k < b->n_terms; k++) {
        const term_t *t = &est->m.terms[b->term0 + k];
        const int col = t->unknown >= 0 ? t->unknown : b->n_unknowns;
        const int channel = noise ? est->noise_of[t->channel] : t->channel;
        duffid_real *out = B + col * m + t->part * n_rows;
        const duffid_real *in;
        if (channel < 0) {
            continue;
        }
        in = E + t->order * n_ch + channel;
        for (r = 0; r < n_rows; r++) {
            out[r] += t->coef * in[r * N_ORD * n_ch];
        }
    }
}

/* ------------------------------------------------------------------ least squares */
static void singular(equation_t *eq, int n)
{
    int i;
    for (i = 0; i < n; i++) {
        eq->theta[i] = R_NAN;
        eq->rse[i] = NOMINAL(eq)[i] = R_INF;
        eq->share[i] = R_NAN;
    }
    eq->rhs_share = R_NAN;
    eq->cond = R_INF;
    eq->warm = 0;
}

/* the shares of solve_factor: of the n_terms terms |theta_i| ||A_i|| and of ||D|| in the force
 * balance of the factor Raug (p = n_terms + 1), the first n of them kept */
static void shares(duffid_estimator *est, equation_t *eq, int n, int n_terms, const duffid_real *Raug,
                   const duffid_real *theta)
{
    const int p = n_terms + 1;
    duffid_real sq[MAX_AUG], rhs, balance;
    int i, k;
    for (k = 0; k < p; k++) {
        sq[k] = Raug[k * p + n_terms] * Raug[k * p + n_terms];
    }
    rhs = R_SQRT(duffid_la_pairwise_sum(sq, p, 1));
    for (i = 0; i < n_terms; i++) {
        duffid_real term = R_FABS(theta[i]) * est->scale[i];
        sq[i] = term * term;
    }
    sq[n_terms] = rhs * rhs;
    balance = R_SQRT(duffid_la_pairwise_sum(sq, p, 1));
    for (i = 0; i < n; i++) {
        eq->share[i] = balance > RC(0.0) ? R_FABS(theta[i]) * est->scale[i] / balance : R_NAN;
    }
    eq->rhs_share = balance > RC(0.0) ? rhs / balance : R_NAN;
}

/* float: each unknown's relative standard error (and rse, when not NULL, too) includes the
 * rounding of the rows it rests on */
static void with_rounding(equation_t *eq, int n, duffid_real *rse)
{
#if DUFFID_SINGLE
    int i;
    for (i = 0; i < n; i++) {
        eq->rse[i] = duffid_la_hypot(eq->rse[i], ARITHMETIC_FACTOR * eq->rounding * eq->cond);
        if (rse != NULL) {
            rse[i] = duffid_la_hypot(rse[i], ARITHMETIC_FACTOR * eq->rounding * eq->cond);
        }
    }
#else
    (void)eq;
    (void)n;
    (void)rse;
#endif
}

/* identification.solve_factor on the p x p factor Raug (p = n + 1): the condition number of
 * the column-equilibrated factor by a warm-started Jacobi iteration, the unknowns and their
 * standard errors from its triangular inverse */
static int solve_plain(duffid_estimator *est, equation_t *eq, int n, const duffid_real *Raug, duffid_real rows,
                       duffid_real overlap)
{
    if (duffid_la_solve_factor(n, Raug, rows, overlap, COND_SINGULAR, est->scale, est->U, est->Rinv, eq->V,
                               &eq->warm, eq->theta, eq->rse, &eq->cond) != 0) {
        singular(eq, n);
        return 1;
    }
    shares(est, eq, n, n, Raug, eq->theta);
    return 0;
}

static void solve_factor(duffid_estimator *est, equation_t *eq, int n, const duffid_real *Raug, duffid_real rows,
                         duffid_real overlap)
{
    if (solve_plain(est, eq, n, Raug, rows, overlap) == 0) {
        with_rounding(eq, n, NULL);
    }
}

static int rate_column(const duffid_real *B, int m, int n, const duffid_real *theta, duffid_real *q);

/* engine._QRLeastSquares.add_scores: the m rows B = [A D] (nl unknowns) with their residuals
 * against the previous solution into the open block's score (before B is factored away);
 * NaN-free previous only (returns 0 otherwise) */
static int add_score(duffid_estimator *est, equation_t *eq, int m, int nl, const duffid_real *previous)
{
    if (!rate_column(est->B, m, nl, previous, est->rate_q)) {
        return 0;
    }
    jump_product(est->B, est->rate_q, m, nl, est->lam, eq->score);
    return 1;
}

/* ... and, after the rows were accumulated, the block's end: its score's products with itself and
 * its neighbour's into scores (engine.BATCH_WINDOWS) once it holds `length` samples */
static void close_block(duffid_estimator *est, equation_t *eq, int nl, long length)
{
    const duffid_real lam2 = est->lam * est->lam;
    int i, j;
    if (lam2 != RC(1.0)) {
        for (i = 0; i < nl * nl; i++) {
            SCORES(eq)[i] *= lam2;
        }
    }
    eq->scored *= est->lam;
    eq->blocks *= est->lam;
    if (++eq->block < length) {
        return;
    }
    for (i = 0; i < nl; i++) {
        const duffid_real u = eq->score[i], q = LAST_SCORE(eq)[i];
        for (j = 0; j < nl; j++) {
            SCORES(eq)[i * nl + j] += u * eq->score[j] + u * LAST_SCORE(eq)[j] + q * eq->score[j];
        }
    }
    for (i = 0; i < nl; i++) {
        LAST_SCORE(eq)[i] = eq->score[i];
        eq->score[i] = RC(0.0);
    }
    eq->block = 0;
    eq->blocks += RC(1.0);
    eq->scored = eq->rows;
}

/* engine._batch_relative: after a solve of the accumulated factor (inv = R^-1, nl x nl), each of
 * the block's n unknowns at time t (lines: value + t rate) with its batch-means error
 * (engine.BATCH_WINDOWS): where larger than the residual's (kept in NOMINAL for the change
 * test), it is the unknown's error */
static void batch_means(equation_t *eq, int n, duffid_real t, const duffid_real *inv)
{
    const int nl = eq->n_line;
    duffid_real K[MAX_LINE];
    int i, j, k, rate = n, known = eq->blocks > (duffid_real)nl && eq->scored > RC(0.0);
    for (i = 0; i < n; i++) {
        known &= is_finite(eq->theta[i]);
        NOMINAL(eq)[i] = eq->rse[i];
    }
    if (!known) {
        return;
    }
    for (i = 0; i < n; i++) {
        const int r = nl > n && eq->drifting[i] ? rate++ : -1;
        duffid_real var = RC(0.0), batch;
        for (j = 0; j < nl; j++) { /* the unknown's row of G^-1 = C R^-T, C its row of the map z -> theta */
            duffid_real sum = RC(0.0);
            for (k = j; k < nl; k++) { /* R^-1 is upper triangular */
                const duffid_real c = r >= 0 ? inv[i * nl + k] + t * inv[r * nl + k] : inv[i * nl + k];
                sum += c * inv[j * nl + k];
            }
            K[j] = sum;
        }
        for (j = 0; j < nl; j++) {
            duffid_real sum = RC(0.0);
            for (k = 0; k < nl; k++) {
                sum += SCORES(eq)[j * nl + k] * K[k];
            }
            var += K[j] * sum;
        }
        var *= eq->rows / eq->scored * eq->blocks / (eq->blocks - (duffid_real)nl);
        batch = eq->theta[i] != RC(0.0) ? R_SQRT(var > RC(0.0) ? var : RC(0.0)) / R_FABS(eq->theta[i]) : R_INF;
        if (batch > eq->rse[i]) {
            eq->rse[i] = batch;
        }
    }
}

/* engine.DriftLine._inverse: after a solve of the factor Raug of nl unknowns (est->Rinv and
 * est->scale hold U^-1 and the column norms), C = U^-1 / scale row-wise and the residual
 * scale sigma (infinite without degrees of freedom) */
static duffid_real line_inverse(const duffid_estimator *est, int nl, const duffid_real *Raug, duffid_real rows,
                                duffid_real overlap, duffid_real *inv)
{
    const int p = nl + 1;
    const duffid_real dof = rows - (duffid_real)nl;
    int i, j;
    for (i = 0; i < nl; i++) {
        for (j = 0; j < nl; j++) {
            inv[i * nl + j] = est->Rinv[i * nl + j] / est->scale[i];
        }
    }
    return dof > RC(0.0) ? R_SQRT(Raug[nl * p + nl] * Raug[nl * p + nl] / dof * overlap) : R_INF;
}

/* engine.DriftLine.at: the block's n unknowns at time t from the line unknowns theta (values at
 * 0, then one rate per drifting unknown), C and sigma, with their relative standard errors */
static void line_at(const equation_t *eq, int n, duffid_real t, const duffid_real *theta, const duffid_real *inv,
                    duffid_real sigma, duffid_real *value, duffid_real *rse)
{
    const int nl = eq->n_line;
    int i, j, rate = n;
    for (i = 0; i < n; i++) {
        duffid_real sum = RC(0.0);
        value[i] = theta[i];
        for (j = 0; j < nl; j++) {
            const duffid_real c = eq->drifting[i] ? inv[i * nl + j] + t * inv[rate * nl + j] : inv[i * nl + j];
            sum += c * c;
        }
        if (eq->drifting[i]) {
            value[i] += t * theta[rate++];
        }
        rse[i] = is_finite(value[i]) && value[i] != RC(0.0) ? sigma * R_SQRT(sum) / R_FABS(value[i]) : R_INF;
        if (!(rse[i] == rse[i])) { /* NaN: an undetermined line */
            rse[i] = R_INF;
        }
    }
}

/* engine.accumulated_rows: the row count that gives the accumulated least squares of full
 * windows (n unknowns, m rows per sample, windows of L intervals) its degrees of freedom,
 * rows - n m L / DUFFID_WINDOW_EQUATIONS, at least (rows - n) / DUFFID_WINDOW_INFLATION^2 */
static duffid_real accumulated_rows(duffid_real rows, int n, int m, duffid_real L)
{
    const duffid_real used = rows - (duffid_real)n * ((duffid_real)m * L / RC(DUFFID_WINDOW_EQUATIONS) - RC(1.0));
    const duffid_real capped = (rows - (duffid_real)n) / (RC(DUFFID_WINDOW_INFLATION) * RC(DUFFID_WINDOW_INFLATION)) +
                               (duffid_real)n;
    return used > capped ? used : capped;
}

/* engine.DriftLine.solve and .at: the accumulated least squares of a block with lines (m rows
 * per sample), its unknowns at time t */
static void line_solve(duffid_estimator *est, equation_t *eq, int n, int m, duffid_real t, duffid_real overlap)
{
    const int nl = eq->n_line;
    const duffid_real rows = accumulated_rows(eq->rows, nl, m, overlap);
    duffid_real rse[MAX_UNK];
    int i;
    if (duffid_la_solve_factor(nl, eq->R, rows, overlap, COND_SINGULAR, est->scale, est->U, est->Rinv, eq->V,
                               &eq->warm, eq->line, rse, &eq->cond) != 0) {
        singular(eq, n);
        for (i = 0; i < nl; i++) {
            eq->line[i] = R_NAN;
        }
        eq->line_sigma = R_INF;
        return;
    }
    shares(est, eq, n, nl, eq->R, eq->line);
    eq->line_sigma = line_inverse(est, nl, eq->R, rows, overlap, eq->line_inv);
    line_at(eq, n, t, eq->line, eq->line_inv, eq->line_sigma, eq->theta, eq->rse);
    batch_means(eq, n, t, eq->line_inv);
    with_rounding(eq, n, NOMINAL(eq));
}

/* engine._relative_residual: ||D - A theta|| over the norm of the force balance of the m
 * rows B = [A D] (column-major, p = n + 1 columns); NaN for a non-finite theta */
static duffid_real relative_residual(const duffid_real *B, int m, int n, const duffid_real *theta)
{
    duffid_real balance = RC(0.0), error = RC(0.0);
    int r, i;
    for (i = 0; i < n; i++) {
        if (!is_finite(theta[i])) {
            return R_NAN;
        }
    }
    for (r = 0; r < m; r++) {
        duffid_real d = B[n * m + r], predicted = RC(0.0);
        for (i = 0; i < n; i++) {
            const duffid_real term = B[i * m + r] * theta[i];
            predicted += term;
            balance += term * term;
        }
        balance += d * d;
        error += (d - predicted) * (d - predicted);
    }
    return balance > RC(0.0) ? R_SQRT(error) / R_SQRT(balance) : R_NAN;
}

/* engine._relative_fit: the same for every row the p x p factor R of [A D] holds */
static duffid_real relative_fit(const duffid_real *R, int n, const duffid_real *theta)
{
    const int p = n + 1;
    duffid_real balance = RC(0.0);
    int k, i;
    for (i = 0; i < n; i++) {
        duffid_real column = RC(0.0);
        if (!is_finite(theta[i])) {
            return R_NAN;
        }
        for (k = 0; k <= i; k++) {
            column += R[k * p + i] * R[k * p + i];
        }
        balance += column * theta[i] * theta[i];
    }
    for (k = 0; k < p; k++) {
        balance += R[k * p + n] * R[k * p + n];
    }
    return balance > RC(0.0) ? R_FABS(R[n * p + n]) / R_SQRT(balance) : R_NAN;
}

/* engine.recent_solution: the unknowns and relative standard errors of the factor R without its
 * condition number (no singular values): the column-equilibrated factor U is inverted as a
 * triangle and sqrt(n) |U^-1|_F (|U|_F = sqrt(n)), an upper bound of the condition number
 * at most sqrt(n) times too large, must stay at most COND_SINGULAR; returns 1 if not */
static int recent_solution(int n, const duffid_real *R, duffid_real rows, duffid_real overlap, duffid_real *scale,
                           duffid_real *U, duffid_real *Rinv, duffid_real *theta, duffid_real *rse)
{
    duffid_real sum = RC(0.0), bound;
    int i;
    if (duffid_la_factor_prepare(n, R, scale, U, Rinv) != 0) {
        return 1;
    }
    for (i = 0; i < n * n; i++) {
        sum += Rinv[i] * Rinv[i];
    }
    bound = R_SQRT((duffid_real)n * sum);
    if (!(bound <= COND_SINGULAR)) { /* also NaN */
        return 1;
    }
    duffid_la_factor_unknowns(n, R, rows, overlap, scale, Rinv, theta, rse);
    return 0;
}

/* engine._alone: per unknown, whether changing it alone reduces the prediction error of theta
 * on the rows held in the p x p factor R of [A D] by at least share of what their own solution
 * reduces it by: (c_i . r)^2 >= share |c_i|^2 |r[0..n-1]|^2, with c_i the factor's column i and
 * r = R [theta; -1] (none when theta is not finite) */
static void alone(const duffid_real *R, int n, const duffid_real *theta, duffid_real share, int *confirmed)
{
    const int p = n + 1;
    duffid_real r[MAX_AUG], gain = RC(0.0);
    int i, k, finite = 1;
    for (i = 0; i < n; i++) {
        finite = finite && is_finite(theta[i]);
        confirmed[i] = 0;
    }
    if (!finite) {
        return;
    }
    for (k = 0; k < n; k++) {
        duffid_real sum = RC(0.0);
        for (i = k; i < n; i++) {
            sum += R[k * p + i] * theta[i];
        }
        r[k] = sum - R[k * p + n];
        gain += r[k] * r[k];
    }
    for (i = 0; i < n; i++) {
        duffid_real dot = RC(0.0), norm2 = RC(0.0);
        for (k = 0; k <= i; k++) {
            dot += R[k * p + i] * r[k];
            norm2 += R[k * p + i] * R[k * p + i];
        }
        confirmed[i] = dot * dot >= share * norm2 * gain;
    }
}

/* OnlineIdentifier._restart: equation e's data contradict its estimate; its parameters are
 * marked changed (an unknown in departed, or any for the right-hand side) or uncertain; the
 * departed unknowns are lines in time from then on (as many as the block's factors hold) */
static void restart(duffid_estimator *est, int e, const int *departed)
{
    equation_t *eq = &est->eq[e];
    const int n = est->m.blocks[e].n_unknowns;
    int i, k, any = 0;
    for (i = 0; i < n; i++) {
        any |= departed[i];
    }
    for (i = 0; i < est->n_params; i++) {
        const duffid_parameter *q = &est->m.params[i];
        for (k = 0; k < q->n_shares; k++) {
            if (q->shares[k].block == e) {
                const int hit = q->shares[k].unknown >= 0 ? departed[q->shares[k].unknown] : any;
                est->changed_now[i] = est->changed_now[i] == 1 || hit ? 1 : 0;
            }
        }
    }
    for (i = 0; i < n; i++) {
        if (departed[i] && !eq->drifting[i] && eq->n_line < eq->line_cap) {
            eq->drifting[i] = 1;
            eq->n_line++;
        }
    }
    clear_factors(est, e);
    singular(eq, n);
    clear_change(eq, n);
    eq->resume = eq->recent_resume = eq->origin = est->n + est->target;
}

/* KernelBank.within: the normalised entry of order d of channel c with row r's kernel times
 * the samples' age s (in reference lengths): (s w)^(d) = s w^(d) + d w^(d-1), the moments one
 * power up and the kernel of one order lower (kernel_entries' cache, for this L) */
static duffid_real within_entry(const duffid_estimator *est, const duffid_real *moments, int r, int d, int c)
{
    const int i = r * N_ORD + d;
    const duffid_real *mom = moments + c * (est->degree + 1), *poly = est->poly + est->k_at[i];
    duffid_real sum = RC(0.0);
    int k;
    for (k = 0; k < est->k_count[i]; k++) {
        sum += poly[k] * mom[est->k_first[i] + k + 1];
    }
    if (d > 0) {
        const duffid_real *lower = est->poly + est->k_at[i - 1];
        duffid_real part = RC(0.0);
        for (k = 0; k < est->k_count[i - 1]; k++) {
            part += lower[k] * mom[est->k_first[i - 1] + k];
        }
        sum += (duffid_real)d * part;
    }
    return sum * est->entry_scale[i];
}

/* DriftLine.rows' S: row `row` of block b's column of unknown u with every sample's term
 * weighted by its age, times the reference length (t_ref KernelBank.within, assembled), from
 * the window's moments (est->mom) or their difference at half the rate (est->dmom) */
static duffid_real timed_entry(const duffid_estimator *est, const duffid_real *moments, const block_t *b, int u,
                               int row)
{
    const int part = row / est->n_rows, r = row % est->n_rows;
    duffid_real sum = RC(0.0);
    int k;
    for (k = 0; k < b->n_terms; k++) {
        const term_t *t = &est->m.terms[b->term0 + k];
        if (t->unknown == u && t->part == part) {
            sum += t->coef * within_entry(est, moments, r, t->order, t->channel);
        }
    }
    return sum * (duffid_real)est->capacity * est->cfg.dt;
}

/* OnlineIdentifier._drift_probe: row probe_row of the m rows B_copy ([A, the lines, D] at time
 * t, column after column) into the drift probe of equation e, its rates tested; returns 1 when
 * it restarted the equation. The rates need no full inverse: in the factor [[R11, R12], [0,
 * R22]] of the columns [A, t A_i], the inverse's rows of the rates are [0, R22^-1]. */
static int drift_probe(duffid_estimator *est, int e, int m, duffid_real t, duffid_real overlap)
{
    equation_t *eq = &est->eq[e];
    const int n = est->m.blocks[e].n_unknowns, P = eq->probe_n, np_ = n + P, p = np_ + 1, nl = eq->n_line;
    const int r = eq->probe_row;
    const duffid_real band = RC(DUFFID_LOSS_FACTOR) * est->max_uncertainty;
    const duffid_real *R = eq->R_probe;
    duffid_real row[MAX_AUG], theta[MAX_AUG], inv[(MAX_LINE / 2) * (MAX_LINE / 2)], dof, gain = RC(0.0);
    int departed[MAX_UNK], i, k, any = 0, singular_ = 0;
    if (P == 0) {
        return 0;
    }
    eq->probe_row = r + 1 < m ? r + 1 : 0; /* one row a sample, in turn */
    for (i = 0; i < n; i++) {
        row[i] = est->B_copy[i * m + r];
    }
    for (i = 0; i < P; i++) { /* DriftLine.rows: t A_i - S_i */
        row[n + i] = t * row[i] - timed_entry(est, est->mom, &est->m.blocks[e], i, r);
    }
    row[np_] = est->B_copy[nl * m + r];
    duffid_la_qr_accumulate(eq->R_probe, p, est->sqrt_lam, row, 1);
    eq->rows_probe = est->lam * eq->rows_probe + RC(1.0);
    eq->times_probe = est->lam * eq->times_probe + t;
    for (i = 0; i < n; i++) {
        departed[i] = 0;
        eq->drift_shift[i] = RC(0.0);
    }
    dof = eq->rows_probe - (duffid_real)np_;
    for (i = 0; i < np_; i++) {
        singular_ |= R[i * p + i] == RC(0.0);
    }
    if (dof > RC(0.0) && !singular_ && duffid_la_upper_inverse(P, R + n * p + n, p, inv) == 0) {
        const duffid_real sigma = R_FABS(R[np_ * p + np_]) * R_SQRT(overlap / dof);
        /* from the rows' mean time to now (half a window after the newest rows) */
        const duffid_real span = R_FABS(t + RC(0.5) * overlap * est->dt - eq->times_probe / eq->rows_probe);
        for (i = np_ - 1; i >= 0; i--) { /* back substitution */
            duffid_real sum = R[i * p + np_];
            for (k = i + 1; k < np_; k++) {
                sum -= R[i * p + k] * theta[k];
            }
            theta[i] = sum / R[i * p + i];
        }
        for (k = n; k < np_; k++) { /* the lines' gain over constants: the right-hand side's rows n.. */
            gain += R[k * p + np_] * R[k * p + np_];
        }
        for (i = 0; i < P; i++) {
            const int c = n + i;
            const duffid_real rate = theta[c], end = theta[i] + rate * t;
            duffid_real norm2 = RC(0.0), dot = RC(0.0), col2 = RC(0.0), bias;
            int confirmed;
            for (k = i; k < P; k++) { /* the rate's standard error: row i of R22^-1 */
                norm2 += inv[i * P + k] * inv[i * P + k];
            }
            for (k = n; k <= c; k++) { /* alone: its column orthogonal to the constants (_alone) */
                dot += R[k * p + c] * R[k * p + np_];
                col2 += R[k * p + c] * R[k * p + c];
            }
            confirmed = dot * dot >= RC(DUFFID_CHANGE_ALONE_SHARE) * col2 * gain;
            /* the drift beyond DUFFID_DRIFT_BIAS_SIGMAS errors to now of a rate confirmed alone: a
             * bias of the constants (a line's value is that of now already) */
            bias = rate * rate - RC(DUFFID_DRIFT_BIAS_SIGMAS) * RC(DUFFID_DRIFT_BIAS_SIGMAS) * sigma * sigma * norm2;
            eq->drift_shift[i] = confirmed && bias > RC(0.0) && !eq->drifting[i] ? span * R_SQRT(bias) : RC(0.0);
            /* ... and the line's end further from the accumulated value than that may move */
            departed[i] = R_FABS(rate) > RC(DUFFID_DRIFT_SIGMAS) * sigma * R_SQRT(norm2) &&
                          R_FABS(end - eq->theta[i]) > band * R_FABS(end) &&
                          confirmed && NOMINAL(eq)[i] <= est->max_uncertainty && !eq->drifting[i];
            any |= departed[i];
        }
    }
    if (any) {
        count_up(&eq->probed, est->settle_count);
    } else {
        eq->probed = 0;
    }
    if (eq->probed >= est->settle_count) {
        restart(est, e, departed);
        return 1;
    }
    return 0;
}

/* OnlineIdentifier._constant_entries: the entries of a constant channel (1) in the rows of a
 * window of L intervals (after kernel_entries for L): its moments are the quadrature's power
 * sums, sum_i phi_j(i) = (L + 1) (L) ... (L + 1 - j) / ((j + 1) N^j) plus the end corrections */
static const duffid_real *constant_entries(duffid_estimator *est, long L)
{
    if (est->one_L != L) {
        const int D1 = est->degree + 1;
        duffid_real fact[MAX_POW], mom[MAX_POW], falling = (duffid_real)(L + 1);
        int j, k, m, r;
        corrections(est, L);
        for (j = 0; j < D1; j++) {
            if (j > 0) {
                falling *= (duffid_real)(L + 1 - j) * est->inv_cap;
            }
            fact[j] = falling / (duffid_real)(j + 1);
            for (m = 0; m < est->corr_n; m++) {
                fact[j] += est->corr_w[j * MAX_CORR + m];
            }
        }
        for (k = 0; k < D1; k++) { /* the power moments, as moments_push */
            const duffid_real *st = est->stirling + k * D1;
            duffid_real sum = k == 0 ? st[0] * fact[0] : RC(0.0);
            for (j = 1; j <= k; j++) {
                sum += st[j] * fact[j];
            }
            mom[k] = sum;
        }
        for (r = 0; r < est->n_rows; r++) { /* order 0 (no raw term) */
            const int at = est->k_at[r * N_ORD], first = est->k_first[r * N_ORD];
            duffid_real sum = RC(0.0);
            for (k = 0; k < est->k_count[r * N_ORD]; k++) {
                sum += est->poly[at + k] * mom[first + k];
            }
            est->one_E[r] = sum * est->entry_scale[r * N_ORD];
        }
        est->one_L = L;
    }
    return est->one_E;
}

/* OnlineIdentifier._offset_probe: row off_row of the m rows B ([A, the lines, D], column after
 * column) with a constant's entry into the offset probe of equation e (window of L intervals);
 * marks the unknowns that the constant moves. In the factor [[R11, R12], [0, r]] of [A, 1] the
 * constant is c = R[n][n+1] / R[n][n] and it moves the unknowns by -R11^-1 R12 c. */
static void offset_probe(duffid_estimator *est, int e, int m, long L)
{
    equation_t *eq = &est->eq[e];
    const int n = est->m.blocks[e].n_unknowns, nl = eq->n_line, p = n + 2, r = eq->off_row;
    const duffid_real *R = eq->R_off;
    duffid_real row[MAX_UNK + 2], plain[MAX_UNK], shift[MAX_UNK], dof, constant, error;
    int i, k, varies, singular_ = 0;
    if (!eq->off_on) {
        return;
    }
    eq->off_row = r + 1 < m ? r + 1 : 0; /* one row a sample, in turn */
    for (i = 0; i < n; i++) {
        row[i] = est->B[i * m + r];
    }
    row[n] = constant_entries(est, L)[r];
    row[n + 1] = est->B[nl * m + r];
    {
        duffid_real pair[2]; /* the accumulation overwrites its rows */
        pair[0] = row[n];
        pair[1] = row[n + 1];
        duffid_la_qr_accumulate(eq->R_var, 2, est->sqrt_lam, pair, 1);
    }
    duffid_la_qr_accumulate(eq->R_off, p, est->sqrt_lam, row, 1);
    eq->rows_off = est->lam * eq->rows_off + RC(1.0);
    for (i = 0; i < n; i++) {
        eq->off_moved[i] = 0;
    }
    dof = eq->rows_off - (duffid_real)(n + 1);
    for (i = 0; i <= n; i++) {
        singular_ |= R[i * p + i] == RC(0.0);
    }
    /* the rows' right-hand side beyond a constant, relative to its constant part */
    varies = R_FABS(eq->R_var[3]) > RC(DUFFID_FORCE_VARIATION) * R_FABS(eq->R_var[1]);
    if (!(dof > RC(0.0)) || !varies || singular_) {
        return;
    }
    constant = R[n * p + n + 1] / R[n * p + n];
    error = R_FABS(R[(n + 1) * p + n + 1]) * R_SQRT((duffid_real)L / dof) / R_FABS(R[n * p + n]);
    if (!(R_FABS(constant) > RC(DUFFID_OFFSET_SIGMAS) * error)) {
        return;
    }
    for (i = n - 1; i >= 0; i--) { /* back substitutions: the plain solution and R11^-1 R12 */
        duffid_real sum = R[i * p + n + 1], sum2 = R[i * p + n];
        for (k = i + 1; k < n; k++) {
            sum -= R[i * p + k] * plain[k];
            sum2 -= R[i * p + k] * shift[k];
        }
        plain[i] = sum / R[i * p + i];
        shift[i] = sum2 / R[i * p + i];
    }
    for (i = 0; i < n; i++) {
        eq->off_moved[i] = R_FABS(shift[i] * constant) > est->max_uncertainty * R_FABS(plain[i]);
    }
}

/* the change test of _robust_solve after the accumulated solution of equation e was updated
 * with the m rows B_copy: the recent solution, the departures that matter, the triggers */
static void change_test(duffid_estimator *est, int e, int m, duffid_real fit, duffid_real t)
{
    equation_t *eq = &est->eq[e];
    const int n = est->m.blocks[e].n_unknowns, nl = eq->n_line, p = nl + 1;
    duffid_real theta[MAX_UNK], rse[MAX_UNK], then_store[MAX_UNK], then_rse_store[MAX_UNK];
    const duffid_real *then = eq->theta, *then_rse = NOMINAL(eq); /* the residual's errors (BATCH_WINDOWS) */
    const int noisy = est->n_noise > 0 && !est->defer;
    int departed[MAX_UNK], drifted[MAX_UNK], confirmed[MAX_UNK];
    int i, any = 0, any_drift = 0;
    if (est->n < eq->recent_resume) { /* the recent estimate restarted after a surprise */
        return;
    }
    duffid_la_qr_accumulate(eq->R_recent, p, est->sqrt_lam_recent, est->B_copy, m);
    eq->rows_recent = est->lam_recent * eq->rows_recent + (duffid_real)m;
    eq->times_recent = est->lam_recent * eq->times_recent + (duffid_real)m * t;
    if (noisy) {
        noise_forget(est->noise_Gw, nl, est->lam_recent, eq->noise_G_recent);
    }
    if (nl == n) {
        if (recent_solution(n, eq->R_recent, eq->rows_recent, est->last_L, est->scale, est->U, est->Rinv, theta,
                            rse) != 0) {
            for (i = 0; i < n; i++) {
                theta[i] = R_NAN;
            }
        } else {
            if (noisy) { /* ... with its rows' noise's bias (row_noise) */
                duffid_real bias[MAX_UNK];
                noise_shift_of(n, p, eq->R_recent, eq->noise_G_recent, est->noise_w, bias);
                for (i = 0; i < n; i++) {
                    rse[i] = bias[i] != RC(0.0) ? duffid_la_hypot(rse[i], R_FABS(bias[i] / theta[i])) : rse[i];
                }
            }
        }
    } else { /* both lines where the recent rows are (their mean time) */
        const duffid_real mean = eq->rows_recent > RC(0.0) ? eq->times_recent / eq->rows_recent : RC(0.0);
        duffid_real unused[MAX_UNK];
        if (recent_solution(nl, eq->R_recent, eq->rows_recent, est->last_L, est->scale, est->U, est->Rinv,
                            eq->line_recent, unused) != 0) {
            for (i = 0; i < nl; i++) {
                eq->line_recent[i] = R_NAN;
            }
            eq->line_recent_sigma = R_INF;
        } else {
            eq->line_recent_sigma = line_inverse(est, nl, eq->R_recent, eq->rows_recent, est->last_L,
                                                 eq->line_recent_inv);
        }
        line_at(eq, n, mean, eq->line_recent, eq->line_recent_inv, eq->line_recent_sigma, theta, rse);
        line_at(eq, n, mean, eq->line, eq->line_inv, eq->line_sigma, then_store, then_rse_store);
        then = then_store;
        then_rse = then_rse_store;
    }
    alone(eq->R_recent, nl, nl == n ? eq->theta : eq->line, RC(DUFFID_CHANGE_ALONE_SHARE), confirmed);
    for (i = 0; i < n; i++) { /* engine._departure and OnlineIdentifier._departed */
        const duffid_real combined = duffid_la_hypot(then_rse[i] * R_FABS(then[i]), rse[i] * R_FABS(theta[i]));
        const int ok = is_finite(then[i]) && is_finite(theta[i]) && is_finite(combined) && combined > RC(0.0);
        eq->departure[i] = ok ? R_FABS(theta[i] - then[i]) / combined : RC(0.0);
        /* beyond the band a published value may move: significant (departed) or, lasting the
         * recent memory, a share of that (drifted) */
        const int wide = R_FABS(theta[i] - then[i]) > RC(DUFFID_LOSS_FACTOR) * est->max_uncertainty * R_FABS(then[i]) &&
                         confirmed[i]; /* ... and confirmed alone (CHANGE_ALONE_SHARE) */
        departed[i] = wide && eq->departure[i] > est->change_threshold;
        drifted[i] = wide && eq->departure[i] > RC(DUFFID_CHANGE_DRIFT_SHARE) * est->change_threshold;
        any |= departed[i];
        any_drift |= drifted[i];
    }
    if (any) {
        count_up(&eq->departed, est->settle_count);
    } else {
        eq->departed = 0;
    }
    if (any_drift) {
        count_up(&eq->drifted, est->memory);
    } else {
        eq->drifted = 0;
    }
    if (eq->residual > RC(DUFFID_CHANGE_SURPRISE) * fit) { /* false while either is NaN */
        count_up(&eq->surprised, est->settle_count);
    } else {
        eq->surprised = 0;
    }
    if (eq->departed >= est->settle_count) {
        restart(est, e, departed);
    } else if (eq->drifted >= est->memory) {
        restart(est, e, drifted);
    } else if (eq->surprised >= est->settle_count) { /* the recent estimate starts afresh after it */
        memset(eq->R_recent, 0, (size_t)(p * p) * sizeof(duffid_real));
        memset(eq->noise_G_recent, 0, (size_t)(nl * p) * sizeof(duffid_real));
        eq->rows_recent = eq->times_recent = RC(0.0);
        for (i = 0; i < n; i++) {
            eq->departure[i] = RC(0.0);
        }
        eq->departed = eq->surprised = eq->drifted = 0;
        eq->recent_resume = est->n + est->target;
    }
}

/* OnlineIdentifier._robust_step + _robust_solve; returns the window length L */
/* DriftLine.rows: a block's rows [A, D] (B, column after column, m rows) become [A, t A_i
 * (its drifting unknowns), D] */
static void line_rows(const duffid_estimator *est, const block_t *b, const equation_t *eq, int m, duffid_real t,
                      const duffid_real *moments, duffid_real *B)
{
    const int n = b->n_unknowns;
    int i, k = n;
    memcpy(B + eq->n_line * m, B + n * m, (size_t)m * sizeof(duffid_real));
    for (i = 0; i < n; i++) {
        if (eq->drifting[i]) {
            int r;
            for (r = 0; r < m; r++) {
                B[k * m + r] = t * B[i * m + r] - timed_entry(est, moments, b, i, r);
            }
            k++;
        }
    }
}

/* DriftLine.rows without S for the rows' noise [dA dD] (B, m rows): [dA, t dA_i, dD] (the
 * newest time's: the window is short against the time) */
static void noise_line_rows(const block_t *b, const equation_t *eq, int m, duffid_real t, duffid_real *B)
{
    const int n = b->n_unknowns;
    int i, r, k = n;
    memcpy(B + eq->n_line * m, B + n * m, (size_t)m * sizeof(duffid_real));
    for (i = 0; i < n; i++) {
        if (eq->drifting[i]) {
            for (r = 0; r < m; r++) {
                B[k * m + r] = t * B[i * m + r];
            }
            k++;
        }
    }
}

/* the rows' change at half the rate under theta (engine.RATE_NOISE): q = D_d - A_d theta for
 * the rows [A_d, D_d] (B, m rows, n columns and D_d after them); 0 when theta is not finite */
static int rate_column(const duffid_real *B, int m, int n, const duffid_real *theta, duffid_real *q)
{
    int i, r;
    for (i = 0; i < n; i++) {
        if (!is_finite(theta[i])) {
            return 0;
        }
    }
    for (r = 0; r < m; r++) {
        duffid_real sum = B[n * m + r];
        for (i = 0; i < n; i++) {
            sum -= B[i * m + r] * theta[i];
        }
        q[r] = sum;
    }
    return 1;
}

static long robust_step(duffid_estimator *est)
{
    const int64_t old_start = est->start;
    long L = moments_push(est, est->target);
    const int noisy = est->n_noise > 0 && !est->defer; /* the rows' noise (deferred runs: values only) */
    int full, rated, e, i;
    jumps_step(est, old_start);
    if (est->regrow) { /* after duffid_hold: the previous output until the window is full */
        if (L < est->target) {
            return -1;
        }
        est->regrow = 0;
    }
    if (L == 0) {
        return 0;
    }
    est->last_L = (duffid_real)L;
    if (est->rows_skipped) {
        return L;
    }
    kernel_entries(est, L);
    rated = est->rate_ok;
    if (rated) {
        rate_entries(est);
    }
    full = L >= est->target;
    for (e = 0; e < est->n_eq; e++) {
        equation_t *eq = &est->eq[e];
        const block_t *b = &est->m.blocks[e];
        const int n = b->n_unknowns, p = n + 1, m = b->n_parts * est->n_rows, nl = eq->n_line;
        if (full && est->n < eq->resume) { /* a window that holds samples from before the change */
            continue;
        }
        assemble(est, b, est->E, est->n_rows, 0, est->B);
        if (rated) {
            assemble(est, b, est->E_rate, est->n_rows, 0, est->B_rate);
        }
        if (noisy) {
            assemble(est, b, est->E, est->n_rows, 1, est->B_noise);
        }
        if (est->n_jumps > 0 && !est->defer) {
            jump_column(est, b);
        }
#if DUFFID_SINGLE /* the rounding of the rows the solution rests on: their average */
        eq->rounding = full ? (est->lam * eq->rows * eq->rounding + (duffid_real)m * est->rounding) /
                                  (est->lam * eq->rows + (duffid_real)m)
                            : est->rounding;
#endif
        if (full) {
            const duffid_real t = (duffid_real)(est->n - eq->origin) * est->dt; /* the rows' time */
            duffid_real previous[MAX_UNK], fit;
            int scored;
            if (nl > n) { /* a block with lines: the rows [A, t A_i - S_i (the lines), D] */
                line_rows(est, b, eq, m, t, est->mom, est->B);
                if (rated) {
                    line_rows(est, b, eq, m, t, est->dmom, est->B_rate);
                }
                if (noisy) {
                    noise_line_rows(b, eq, m, t, est->B_noise);
                }
            }
            if (est->defer) { /* duffid_defer_solutions: the rows only (no lines: no change test, no
                               * jumps' errors: the values only) */
                for (i = 0; i < n; i++) {
                    eq->jump_shift[i] = eq->rate_shift[i] = eq->noise_shift[i] = RC(0.0);
                }
                if (eq->rows == RC(0.0)) { /* R held the growing window's factor (below) */
                    memset(eq->R, 0, (size_t)(p * p) * sizeof(duffid_real));
                }
                duffid_la_qr_accumulate(eq->R, n + 1, est->sqrt_lam, est->B, m);
                eq->rows = est->lam * eq->rows + (duffid_real)m;
                continue;
            }
            for (i = 0; i < nl; i++) {
                previous[i] = nl > n ? eq->line[i] : eq->theta[i];
            }
            fit = relative_fit(eq->R, nl, previous);
            eq->residual = relative_residual(est->B, m, nl, previous);
            if (est->change_threshold > RC(0.0)) {
                memcpy(est->B_copy, est->B, (size_t)(m * (nl + 1)) * sizeof(duffid_real));
            }
            offset_probe(est, e, m, L); /* before the rows B are factored away */
            if (est->n_jumps > 0) { /* A^T J with the rows' forgetting (JUMP_ERROR) */
                jump_product(est->B, est->jump_J, m, nl, est->lam, eq->jump_v);
            } else if (est->lam != RC(1.0)) {
                for (i = 0; i < nl; i++) {
                    eq->jump_v[i] *= est->lam;
                }
            }
            if (rated && rate_column(est->B_rate, m, nl, previous, est->rate_q)) { /* A^T Q (RATE_NOISE) */
                jump_product(est->B, est->rate_q, m, nl, est->lam, eq->rate_v);
            } else if (est->lam != RC(1.0)) {
                for (i = 0; i < nl; i++) {
                    eq->rate_v[i] *= est->lam;
                }
            }
            scored = add_score(est, eq, m, nl, previous); /* BATCH_WINDOWS */
            duffid_la_qr_accumulate(eq->R, nl + 1, est->sqrt_lam, est->B, m);
            eq->rows = est->lam * eq->rows + (duffid_real)m;
            if (scored) {
                close_block(est, eq, nl, DUFFID_BATCH_WINDOWS * est->target);
            }
            if (noisy) { /* this sample's rows' noise (noise_Gw), into the accumulated and the recent */
                noise_product(est->B_noise, m, nl, est->noise_Gw);
                noise_forget(est->noise_Gw, nl, est->lam, eq->noise_G);
            }
            if (nl > n) {
                line_solve(est, eq, n, m, t, (duffid_real)L);
            } else if (solve_plain(est, eq, n, eq->R, accumulated_rows(eq->rows, n, m, (duffid_real)L),
                                   (duffid_real)L) == 0) {
                for (i = 0; i < n * n; i++) { /* R^-1 = U^-1 / scale row-wise (U: the solve's workspace) */
                    est->U[i] = est->Rinv[i] / est->scale[i / n];
                }
                batch_means(eq, n, RC(0.0), est->U);
                with_rounding(eq, n, NOMINAL(eq));
            }
            {
                duffid_real shift[MAX_LINE];
                int k = n;
                jump_shift(nl, nl + 1, eq->R, eq->jump_v, shift);
                for (i = 0; i < n; i++) { /* the lines' values now */
                    eq->jump_shift[i] = shift[i] + (nl > n && eq->drifting[i] ? shift[k++] * t : RC(0.0));
                }
                jump_shift(nl, nl + 1, eq->R, eq->rate_v, shift);
                for (i = 0, k = n; i < n; i++) {
                    eq->rate_shift[i] = shift[i] + (nl > n && eq->drifting[i] ? shift[k++] * t : RC(0.0));
                }
                if (noisy) { /* the rows' noise's bias (row_noise): none where it is infinite */
                    int finite = 1;
                    noise_shift_of(nl, nl + 1, eq->R, eq->noise_G, est->noise_w, shift);
                    for (i = 0; i < nl; i++) {
                        finite &= is_finite(shift[i]);
                    }
                    for (i = 0, k = n; i < n; i++) {
                        eq->noise_shift[i] = !finite ? R_INF
                                             : shift[i] + (nl > n && eq->drifting[i] ? shift[k++] * t : RC(0.0));
                    }
                }
            }
            if (est->change_threshold > RC(0.0) && !drift_probe(est, e, m, t, (duffid_real)L)) {
                change_test(est, e, m, fit, t);
            }
        } else if (est->defer) { /* a growing window's factor, solved once asked (resolve) */
            for (i = 0; i < n; i++) {
                eq->jump_shift[i] = eq->rate_shift[i] = eq->noise_shift[i] = RC(0.0);
            }
            memset(eq->R, 0, (size_t)(p * p) * sizeof(duffid_real));
            duffid_la_qr_accumulate(eq->R, p, RC(1.0), est->B, m);
        } else {
            for (i = 0; i < p * p; i++) {
                est->W[i] = RC(0.0);
            }
            if (est->n_jumps > 0) { /* A^T J of these rows alone */
                duffid_real v[MAX_UNK] = {RC(0.0)};
                jump_product(est->B, est->jump_J, m, n, RC(1.0), v);
                if (rated) { /* these rows, for A^T Q once the unknowns are known */
                    memcpy(est->B_copy, est->B, (size_t)(m * p) * sizeof(duffid_real));
                }
                duffid_la_qr_accumulate(est->W, p, RC(1.0), est->B, m);
                jump_shift(n, p, est->W, v, eq->jump_shift);
            } else {
                if (rated) { /* these rows, for A^T Q once the unknowns are known */
                    memcpy(est->B_copy, est->B, (size_t)(m * p) * sizeof(duffid_real));
                }
                duffid_la_qr_accumulate(est->W, p, RC(1.0), est->B, m);
                for (i = 0; i < n; i++) {
                    eq->jump_shift[i] = RC(0.0);
                }
            }
            solve_factor(est, eq, n, est->W, (duffid_real)m, RC(1.0));
            if (noisy) { /* these rows' noise alone (row_noise) */
                noise_product(est->B_noise, m, n, est->noise_Gw);
                noise_shift_of(n, p, est->W, est->noise_Gw, est->noise_w, eq->noise_shift);
            }
            if (rated && rate_column(est->B_rate, m, n, eq->theta, est->rate_q)) { /* RATE_NOISE */
                duffid_real v[MAX_UNK] = {RC(0.0)};
                jump_product(est->B_copy, est->rate_q, m, n, RC(1.0), v);
                jump_shift(n, p, est->W, v, eq->rate_shift);
            } else {
                for (i = 0; i < n; i++) {
                    eq->rate_shift[i] = RC(0.0);
                }
            }
        }
    }
    return L;
}
#if !DUFFID_SINGLE /* the paper method needs double precision (duffid_check_config) */
/* ------------------------------------------------------------------ paper method */
/* identification.Integrators.push: returns y (levels 0..depth, n_in each) */
static const duffid_real *integrators_push(integrators_t *it, const duffid_real *u, duffid_real h, int adams)
{
    const size_t n = (size_t)(it->depth + 1) * (size_t)it->n_in;
    const int m = it->n_in;
    int k, i;
    memcpy(it->p2, it->p1, n * sizeof(duffid_real));
    memcpy(it->p1, it->y, n * sizeof(duffid_real));
    for (i = 0; i < m; i++) {
        it->y[i] = u[i];
    }
    for (k = 1; k <= it->depth; k++) {
        duffid_real *y = it->y + k * m;
        const duffid_real *y_lo = it->y + (k - 1) * m;
        const duffid_real *p1 = it->p1 + k * m, *p1_lo = it->p1 + (k - 1) * m, *p2_lo = it->p2 + (k - 1) * m;
        for (i = 0; i < m; i++) {
            if (it->count == 0) {
                y[i] = RC(0.0);
            } else if (it->count == 1 || !adams) {
                y[i] = p1[i] + RC(0.5) * h * (y_lo[i] + p1_lo[i]);
            } else {
                y[i] = p1[i] + h / RC(12.0) * (RC(5.0) * y_lo[i] + RC(8.0) * p1_lo[i] - p2_lo[i]);
            }
        }
    }
    if (it->count < 2) {
        it->count++;
    }
    return it->y;
}

/* identification.equilibrated_condition (the Jacobi iteration warm-started from the block's
 * previous sample) */
static duffid_real equilibrated_condition(duffid_estimator *est, equation_t *eq, const duffid_real *A, int n)
{
    duffid_real hi, lo;
    duffid_real col[MAX_UNK], row[MAX_UNK], sq[MAX_UNK];
    int i, j;
    for (j = 0; j < n; j++) {
        duffid_real sum = RC(0.0);
        for (i = 0; i < n; i++) {
            sum += A[i * n + j] * A[i * n + j];
        }
        col[j] = R_SQRT(sum);
    }
    for (i = 0; i < n; i++) {
        for (j = 0; j < n; j++) {
            sq[j] = A[i * n + j] * A[i * n + j];
        }
        row[i] = R_SQRT(duffid_la_pairwise_sum(sq, n, 1));
    }
    for (i = 0; i < n; i++) {
        if (!(col[i] > RC(0.0) && row[i] > RC(0.0))) {
            eq->warm = 0;
            return R_INF;
        }
    }
    for (i = 0; i < n; i++) {
        duffid_real rn;
        for (j = 0; j < n; j++) {
            est->Aw[i * n + j] = A[i * n + j] / col[j];
            sq[j] = est->Aw[i * n + j] * est->Aw[i * n + j];
        }
        rn = R_SQRT(duffid_la_pairwise_sum(sq, n, 1));
        for (j = 0; j < n; j++) {
            est->Aw[i * n + j] /= rn;
        }
    }
    duffid_la_singular_range(n, est->Aw, eq->V, eq->warm, &hi, &lo);
    eq->warm = hi == hi && lo > RC(0.0);
    if (hi != hi) {
        return R_NAN;
    }
    if (!(lo > RC(0.0))) {
        return R_INF;
    }
    return hi / lo;
}

/* OnlineIdentifier._paper_step; returns the window length (samples since the first) */
static long paper_step(duffid_estimator *est)
{
    const duffid_real dt = est->cfg.dt;
    const duffid_real tau = (duffid_real)est->n * dt;
    const duffid_real tau2 = tau * tau;
    const int n_ch = est->n_ch, adams = est->cfg.quadrature == DUFFID_ADAMS3;
    const int fixed_sign = est->cfg.sign_in_numerator;
    const duffid_real weight = R_EXP(-est->cfg.gamma * tau);
    int e, c, p, u, i;
    for (c = 0; c < n_ch; c++) {
        est->u_in[c] = est->g[c];
        est->u_in[n_ch + c] = tau * est->g[c];
        est->u_in[2 * n_ch + c] = tau2 * est->g[c];
    }
    for (e = 0; e < est->n_eq; e++) {
        equation_t *eq = &est->eq[e];
        const block_t *b = &est->m.blocks[e];
        const int n = b->n_unknowns, m = 3 * n_ch;
        const duffid_real *y = integrators_push(&eq->reg, est->u_in, dt, adams);
        duffid_real delta, deltas[MAX_UNK], in[MAX_UNK + 1];
        const duffid_real *z;
        /* E[p, order, channel] of eqs. (16)-(17); Y[k, j, c] = y[k * m + j * n_ch + c] */
        for (p = 0; p < n; p++) {
            for (c = 0; c < n_ch; c++) {
                duffid_real *Ep = est->E + (size_t)p * N_ORD * (size_t)n_ch;
                Ep[2 * n_ch + c] = y[p * m + 2 * n_ch + c] - RC(4.0) * y[(p + 1) * m + n_ch + c] +
                                     RC(2.0) * y[(p + 2) * m + c];
                Ep[1 * n_ch + c] = y[(p + 1) * m + 2 * n_ch + c] - RC(2.0) * y[(p + 2) * m + n_ch + c];
                Ep[c] = y[(p + 2) * m + 2 * n_ch + c];
            }
        }
        assemble(est, b, est->E, n, 0, est->B); /* one part: the paper method refuses joint blocks */
        for (p = 0; p < n; p++) {
            for (u = 0; u < n; u++) {
                est->Ap[p * n + u] = est->B[u * n + p];
            }
            est->Dp[p] = est->B[n * n + p];
        }
        memcpy(est->W, est->Ap, (size_t)(n * n) * sizeof(duffid_real));
        delta = duffid_la_det(n, est->W);
        for (i = 0; i < n; i++) {
            memcpy(est->W, est->Ap, (size_t)(n * n) * sizeof(duffid_real));
            for (p = 0; p < n; p++) {
                est->W[p * n + i] = est->Dp[p];
            }
            deltas[i] = duffid_la_det(n, est->W);
        }
        for (i = 0; i < n; i++) {
            duffid_real num = fixed_sign ? deltas[i] * sign_of(delta) : R_FABS(deltas[i]);
            in[i] = weight * num;
        }
        in[n] = weight * R_FABS(delta);
        z = integrators_push(&eq->det, in, dt, adams) + 2 * (n + 1);
        if (z[n] > RC(0.0)) { /* eq. (19): filtered |Delta_i| / |Delta|, signs of the current sample */
            for (i = 0; i < n; i++) {
                duffid_real ratio = z[i] / z[n];
                eq->theta[i] = fixed_sign ? ratio : sign_of(deltas[i]) * sign_of(delta) * ratio;
            }
        } else {
            for (i = 0; i < n; i++) {
                eq->theta[i] = R_NAN;
            }
        }
        eq->cond = equilibrated_condition(est, eq, est->Ap, n);
    }
    return (long)est->n;
}

#endif

/* ------------------------------------------------------------------ combination */
/* Chain/EquationModel.combine_solutions into est->canon / est->canon_rse (canonical order):
 * a forced block's unknowns are absolute values; an unforced block's are ratios to its
 * scale, found by its rules from a block already on a known scale (passes until none
 * progresses). Relative errors of products add in quadrature. */
/* engine._published_error: unknown u's standard error with its jumps' bias (JUMP_ERROR), its
 * rows' change at half the rate beyond DUFFID_RATE_NOISE standard errors and the drift probe's
 * drift to now (DUFFID_DRIFT_BIAS_SIGMAS) and the rows' noise's bias (row_noise), in
 * quadrature; without the last three: with_rate 0 */
static duffid_real published_rse(const equation_t *eq, int u, int with_rate)
{
    const duffid_real rse = eq->rse[u];
    duffid_real jump, change, rate, drift, noise;
    if (eq->jump_shift[u] == RC(0.0) &&
        ((eq->rate_shift[u] == RC(0.0) && eq->drift_shift[u] == RC(0.0) && eq->noise_shift[u] == RC(0.0)) ||
         !with_rate)) {
        return rse;
    }
    jump = eq->jump_shift[u] != RC(0.0) ? RC(DUFFID_JUMP_ERROR) * R_FABS(eq->jump_shift[u] / eq->theta[u]) : RC(0.0);
    change = eq->rate_shift[u] != RC(0.0) && with_rate ? R_FABS(eq->rate_shift[u] / eq->theta[u]) : RC(0.0);
    drift = eq->drift_shift[u] != RC(0.0) && with_rate ? R_FABS(eq->drift_shift[u] / eq->theta[u]) : RC(0.0);
    noise = eq->noise_shift[u] != RC(0.0) && with_rate ? R_FABS(eq->noise_shift[u] / eq->theta[u]) : RC(0.0);
    rate = change * change - RC(DUFFID_RATE_NOISE) * RC(DUFFID_RATE_NOISE) * rse * rse;
    rate = rate <= RC(0.0) ? RC(0.0) : rate; /* np.maximum: a NaN stays */
    return R_SQRT(rse * rse + jump * jump + rate + drift * drift + noise * noise);
}

/* one pass of the combination with or without the quadrature's bias into errors */
static void combine_pass(duffid_estimator *est, int with_rate, duffid_real *errors)
{
    const rt_model *m = &est->m;
    const int n = est->n_eq;
    int known[MAX_EQ];
    duffid_real s_val[MAX_EQ], s_err[MAX_EQ];
    int i, progress = 1, n_canon = est->n_params;
    for (i = 0; i < n; i++) {
        known[i] = m->blocks[i].forced;
        s_val[i] = RC(1.0);
        s_err[i] = RC(0.0);
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
                const duffid_rule *rule = &m->rules[m->blocks[i].rule0 + r];
                const duffid_real ratio = est->eq[i].theta[rule->unknown];
                const int j = rule->other;
                if (ratio == RC(0.0) || !known[j]) {
                    continue;
                }
                {
                    duffid_real abs_val = s_val[j] * est->eq[j].theta[rule->other_unknown];
                    duffid_real abs_err = duffid_la_hypot(s_err[j], published_rse(&est->eq[j], rule->other_unknown, with_rate));
                    s_val[i] = abs_val / ratio;
                    s_err[i] = duffid_la_hypot(abs_err, published_rse(&est->eq[i], rule->unknown, with_rate));
                    known[i] = 1;
                    progress = 1;
                    break;
                }
            }
        }
    }
    for (i = 0; i < n_canon; i++) {
        const duffid_parameter *q = &m->params[i];
        duffid_real val = R_NAN, err = R_INF;
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
                    err = duffid_la_hypot(s_err[j], published_rse(&est->eq[j], u, with_rate));
                    break;
                }
            }
        }
        est->canon[i] = val;
        errors[i] = err;
    }
}

static void combine(duffid_estimator *est)
{
    const rt_model *m = &est->m;
    int i, n_canon = est->n_params;
    combine_pass(est, 1, est->canon_rse);
    combine_pass(est, 0, est->canon_steady);
    /* OnlineIdentifier._shares: the largest share over the blocks with the term */
    for (i = 0; i < n_canon; i++) {
        const duffid_parameter *q = &m->params[i];
        duffid_real share = R_NAN;
        int k;
        for (k = 0; k < q->n_shares; k++) {
            const int j = q->shares[k].block, u = q->shares[k].unknown;
            duffid_real v = u >= 0 ? est->eq[j].share[u] : est->eq[j].rhs_share;
            if (is_finite(v) && !(v <= share)) {
                share = v;
            }
        }
        est->canon_share[i] = share;
    }
}

static duffid_real combined_condition(const duffid_estimator *est)
{
    duffid_real cond = est->eq[0].cond;
    int e;
    for (e = 1; e < est->n_eq; e++) {
        cond = max_builtin(cond, est->eq[e].cond);
    }
    return cond;
}

/* identification.auto_window with the model's linear_natural_frequencies of the estimate:
 * the eigenvalues of M^-1 K (np.linalg.solve, then eigvals): periods lowest natural periods in
 * samples, never fewer than current nor more than limit (limit, too, when undefined) */
static duffid_real natural_window(duffid_estimator *est, long current, duffid_real periods, duffid_real limit)
{
    const rt_model *m = &est->m;
    const int n = est->n_dof;
    duffid_real *M = est->lin, *K = est->lin + n * n;
    duffid_real wr[DUFFID_MAX_DOF], wi[DUFFID_MAX_DOF], best = R_INF, samples;
    int i;
    if (!m->c.linear) {
        return limit;
    }
    memset(est->lin, 0, (size_t)(2 * n * n) * sizeof(duffid_real));
    for (i = 0; i < m->c.n_mass; i++) {
        const duffid_linear *l = &m->mass[i];
        M[l->row * n + l->col] += l->param >= 0 ? (duffid_real)l->coef * est->canon[l->param] : (duffid_real)l->coef;
    }
    for (i = 0; i < m->c.n_stiffness; i++) {
        const duffid_linear *l = &m->stiffness[i];
        K[l->row * n + l->col] += l->param >= 0 ? (duffid_real)l->coef * est->canon[l->param] : (duffid_real)l->coef;
    }
    for (i = 0; i < 2 * n * n; i++) {
        if (!is_finite(est->lin[i])) {
            return limit; /* LinAlgError / singular inertia in Python */
        }
    }
    if (duffid_la_solve(n, M, K, n) != 0) {
        return limit;
    }
    if (duffid_la_eigenvalues(n, K, wr, wi) != 0) {
        return limit;
    }
    for (i = 0; i < n; i++) {
        duffid_real omega = R_SQRT(R_FABS(wr[i]));
        if (is_finite(omega) && omega > RC(0.0) && omega < best) {
            best = omega;
        }
    }
    if (!is_finite(best)) {
        return limit;
    }
    samples = round_half_even(periods * RC(2.0) * PI / best / est->dt);
    if (samples < (duffid_real)current) {
        samples = (duffid_real)current;
    }
    if (!(samples <= limit)) {
        samples = limit;
    }
    return samples;
}

/* OnlineIdentifier._capped: max_window holds fewer than DUFFID_MIN_WINDOW_PERIODS lowest
 * natural periods of the estimate (0 when they are not defined) */
static int capped(duffid_estimator *est)
{
    const duffid_real longest = natural_window(est, 0, RC(DUFFID_MIN_WINDOW_PERIODS), R_INF);
    return is_finite(longest) && longest > (duffid_real)est->capacity;
}

/* OnlineIdentifier._window_spans: a fixed window, or an auto window whose longest length holds
 * DUFFID_MIN_WINDOW_PERIODS natural periods: of the estimate once its masses and linear
 * stiffnesses are steady, those it was fixed from afterwards */
static int window_spans(duffid_estimator *est, long window)
{
    int i, unknown = 0;
    if (!est->auto_window) {
        return 1;
    }
    if (est->window_fixed) {
        return !est->window_capped;
    }
    for (i = 0; i < est->n_params; i++) {
        if (est->m.params[i].period && est->steady[i] < est->settle_count) {
            if (est->status[i] != DUFFID_STATUS_NOT_EXCITED) {
                return 0; /* not yet determined */
            }
            unknown = 1; /* not excited: no period tells what the window spans */
        }
    }
    if (unknown) {
        return window >= DUFFID_MIN_UNCHECKED_SAMPLES;
    }
    return !capped(est);
}

/* ------------------------------------------------------------------ publication */
static int window_ok(const duffid_estimator *est, duffid_real cond, long L)
{
    return cond <= est->max_condition && (duffid_real)L * est->dt >= est->min_time - RC(1e-12) &&
           est->n >= MIN_SAMPLES;
}

/* identification._next_status */
static int next_status(int status, int64_t settled, int64_t unsettled, int64_t settle, int good, duffid_real share)
{
    if (settled >= settle) {
        return DUFFID_STATUS_PUBLISHED;
    }
    if (status == DUFFID_STATUS_PUBLISHED) {
        return unsettled >= settle ? DUFFID_STATUS_LOST : DUFFID_STATUS_PUBLISHED;
    }
    if (good && share < RC(DUFFID_MIN_SHARE)) {
        return DUFFID_STATUS_NOT_EXCITED;
    }
    return status == DUFFID_STATUS_LOST || status == DUFFID_STATUS_CHANGED ? status : DUFFID_STATUS_UNCERTAIN;
}

/* OnlineIdentifier._window_known: masses and linear stiffnesses steady (or no longer excited
 * after they were), the rest steady or not excited */
static int window_known(const duffid_estimator *est)
{
    int i;
    for (i = 0; i < est->n_params; i++) {
        int needed = est->m.params[i].period && !is_finite(est->period_seen[i]);
        if (!(est->steady[i] >= est->settle_count || (est->status[i] == DUFFID_STATUS_NOT_EXCITED && !needed))) {
            return 0;
        }
    }
    return 1;
}

/* OnlineIdentifier._after_publish: remember the period parameters' steady values while the
 * window grows; once the window is known, fix it at window_periods natural periods of the
 * estimate (never shorter than now), a period parameter no longer excited taken at its
 * remembered value */
static void fix_window(duffid_estimator *est, long window)
{
    duffid_real saved[DUFFID_MAX_PARAMS];
    int i;
    for (i = 0; i < est->n_params; i++) {
        if (est->m.params[i].period && est->steady[i] >= est->settle_count) {
            est->period_seen[i] = est->canon[i];
        }
    }
    if (!window_known(est)) {
        return;
    }
    for (i = 0; i < est->n_params; i++) {
        saved[i] = est->canon[i];
        if (est->m.params[i].period && est->steady[i] < est->settle_count) {
            est->canon[i] = est->period_seen[i];
        }
    }
    est->window_fixed = 1;
    set_target(est, (long)natural_window(est, window, est->cfg.window_periods, (duffid_real)est->capacity));
    /* the longest window must hold DUFFID_MIN_WINDOW_PERIODS lowest natural periods */
    est->window_capped = capped(est);
    for (i = 0; i < est->n_params; i++) {
        est->canon[i] = saved[i];
    }
}

/* the model's is_physical: the sign its term needs (canonical index i) */
static int is_physical(const duffid_estimator *est, int i, duffid_real v)
{
    const int allowed = est->m.params[i].physical;
    if (v > RC(0.0)) {
        return (allowed & DUFFID_ALLOW_POSITIVE) != 0;
    }
    if (v < RC(0.0)) {
        return (allowed & DUFFID_ALLOW_NEGATIVE) != 0;
    }
    if (v == RC(0.0)) {
        return (allowed & DUFFID_ALLOW_ZERO) != 0;
    }
    return allowed == ANY_SIGN; /* NaN: only a parameter without a rule is "physical" */
}

/* the public value of canonical value v (models' from_canonical) */
static duffid_real public_value(const duffid_estimator *est, int i, duffid_real v)
{
    if (!est->m.publics[i].reciprocal) {
        return v;
    }
    return v != RC(0.0) ? RC(1.0) / v : R_INF;
}

static void publish(duffid_estimator *est, long window, duffid_output *out)
{
    const int np = est->n_params;
    duffid_real cond, worst = RC(0.0);
    int i, ok = 1, good;
    combine(est);
    cond = combined_condition(est);
    good = window_ok(est, cond, window);
    if (est->cfg.method == DUFFID_PAPER) {
        for (i = 0; i < np; i++) {
            duffid_real v = est->canon[i];
            est->held[i] = public_value(est, i, est->canon[est->m.publics[i].canonical]);
            ok &= is_finite(v) && is_physical(est, i, v);
        }
        ok = ok && good;
        worst = R_NAN;
        for (i = 0; i < np; i++) {
            est->status[i] = ok ? DUFFID_STATUS_PUBLISHED : DUFFID_STATUS_UNCERTAIN;
        }
    } else {
        duffid_real trusted[DUFFID_MAX_PARAMS];
        const int full = window >= est->target;
        const duffid_real tol = RC(0.5) * est->max_uncertainty;
        int spanned, spans;
        /* the first full windows' rows rest on one window's samples until they span another:
         * their standard errors are not credible before (as after a change) */
        if (full && est->spanned_from < 0) {
            est->spanned_from = est->n + (int64_t)est->target;
        }
        spanned = est->spanned_from >= 0 && est->n >= est->spanned_from; /* a value not yet published waits */
        spans = window_spans(est, window); /* before this sample's counts */
        for (i = 0; i < np; i++) { /* restarted by the change test */
            if (est->changed_now[i] >= 0) { /* a value it had is changed */
                const int had_value = est->status[i] == DUFFID_STATUS_PUBLISHED || est->status[i] == DUFFID_STATUS_LOST ||
                                      est->status[i] == DUFFID_STATUS_CHANGED;
                est->status[i] = est->changed_now[i] && had_value ? DUFFID_STATUS_CHANGED : DUFFID_STATUS_UNCERTAIN;
                est->settled[i] = est->unsettled[i] = est->steady[i] = 0;
                est->anchor[i] = est->value[i] = R_NAN;
                est->fresh[i] = 1;
                /* the rows after a change start a window later and rest on one window's samples
                 * until they span another: their standard errors are not credible before */
                est->credible_from[i] = est->n + 2 * (int64_t)est->target;
                est->changed_now[i] = -1;
            }
        }
        for (i = 0; i < np; i++) { /* canonical order */
            duffid_real v = est->canon[i];
            duffid_real relative = (is_finite(v) && v != RC(0.0)) ? est->canon_rse[i] : R_INF;
            /* ... without the quadrature's bias: what the window rule and the growth go by */
            duffid_real steady_relative = (is_finite(v) && v != RC(0.0)) ? est->canon_steady[i] : R_INF;
            int small, large, determined, steady;
            if (est->nominal[i] > RC(0.0) && is_finite(relative)) { /* the user's prior size */
                relative = relative * R_FABS(v) / (R_FABS(v) > est->nominal[i] ? R_FABS(v) : est->nominal[i]);
            }
            if (est->nominal[i] > RC(0.0) && is_finite(steady_relative)) {
                steady_relative = steady_relative * R_FABS(v) /
                                  (R_FABS(v) > est->nominal[i] ? R_FABS(v) : est->nominal[i]);
            }
            worst = max_builtin(worst, relative);
            {
                const int physical = is_physical(est, i, v);
                const int excited = est->canon_share[i] >= RC(DUFFID_MIN_SHARE) || est->nominal[i] > RC(0.0);
                /* a held value is withdrawn, too, once the estimate has moved away from it */
                const int moved = est->status[i] == DUFFID_STATUS_PUBLISHED &&
                                  !(R_FABS(v - est->value[i]) <=
                                    RC(DUFFID_LOSS_FACTOR) * est->max_uncertainty * R_FABS(est->value[i]));
                /* a value that an unknown constant force would move is not publishable */
                int offset = 0, k;
                for (k = 0; k < est->m.params[i].n_shares; k++) {
                    const duffid_source *src = &est->m.params[i].shares[k];
                    offset |= src->unknown >= 0 && est->eq[src->block].off_moved[src->unknown];
                }
                determined = good && excited && physical && relative <= est->max_uncertainty && !offset;
                steady = good && excited && physical && steady_relative <= est->max_uncertainty && !offset;
                /* ... and only while the window spans the plant's dynamics (_window_spans) */
                small = determined && spans;
                /* ... not for its error before the full windows' rows span a window (not credible yet) */
                large = moved || offset ||
                        !(good && physical && (relative <= RC(DUFFID_LOSS_FACTOR) * est->max_uncertainty || (full && !spanned)));
            }
            if (steady) {
                count_up(&est->steady[i], est->settle_count);
            } else {
                est->steady[i] = 0;
            }
            if (!(is_finite(v) && R_FABS(v - est->anchor[i]) <= tol * R_FABS(est->anchor[i]))) {
                est->anchor[i] = v;
                est->anchored[i] = est->n;
            }
            /* n - anchored >= GROWTH_STEADY (1/4) x window, in integers */
            if (small && ((full && !est->fresh[i] && (spanned || est->status[i] == DUFFID_STATUS_PUBLISHED)) ||
                          (4 * (est->n - est->anchored[i]) >= (int64_t)window && est->n >= est->credible_from[i]))) {
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
            trusted[i] = est->settled[i] >= est->settle_count ? v : R_NAN;
            if (is_finite(trusted[i])) {
                est->value[i] = v;
            }
            if (est->status[i] == DUFFID_STATUS_PUBLISHED) {
                est->fresh[i] = 0;
            }
        }
        for (i = 0; i < np; i++) {
            int c = est->m.publics[i].canonical;
            duffid_real v = public_value(est, i, trusted[c]);
            if (est->status[c] != DUFFID_STATUS_PUBLISHED) {
                est->held[i] = R_NAN;
            } else if (is_finite(v)) {
                est->held[i] = v;
            }
            ok &= est->status[c] == DUFFID_STATUS_PUBLISHED;
        }
    }
    if (out != NULL) {
        out->t = (duffid_real)est->n * est->dt;
        for (i = 0; i < np; i++) { /* the entries after np keep reset's NaN and UNCERTAIN */
            out->parameters[i] = est->held[i];
            out->status[i] = est->status[est->cfg.method == DUFFID_PAPER ? i : est->m.publics[i].canonical];
        }
        out->n_parameters = np;
        out->identified = ok;
        out->condition = cond;
        out->uncertainty = worst;
        out->window = (duffid_real)window * est->dt;
        out->residual = R_NAN;
        for (i = 0; i < est->n_eq; i++) { /* the largest over the equations */
            if (is_finite(est->eq[i].residual) && !(est->eq[i].residual <= out->residual)) {
                out->residual = est->eq[i].residual;
            }
        }
        for (i = 0; i < np; i++) {
            const int c = est->m.publics[i].canonical;
            out->std_errors[i] = est->cfg.method == DUFFID_ROBUST && is_finite(est->held[i])
                                     ? R_FABS(est->canon_rse[c] * est->held[i])
                                     : R_NAN;
        }
        for (i = 0; i < np; i++) {
            out->current[i] = est->cfg.method == DUFFID_PAPER
                                  ? est->held[i]
                                  : (good ? public_value(est, i, est->canon[est->m.publics[i].canonical]) : R_NAN);
        }
    }
    if (est->cfg.method == DUFFID_ROBUST && est->auto_window && !est->window_fixed) {
        fix_window(est, window);
    }
}

/* ------------------------------------------------------------------ outliers */
static void guard_threshold(const duffid_estimator *est, duffid_real *threshold)
{
    int j;
    for (j = 0; j < est->n_dof; j++) {
        duffid_real step = is_finite(est->g_step[j]) ? est->g_step[j] : RC(0.0);
        duffid_real scale = RC(1.2533141373155003) * est->g_mean[j];
        duffid_real range = RC(DUFFID_OUTLIER_RANGE) * (est->g_hi[j] - est->g_lo[j]);
        scale = step > scale ? step : scale;
        scale = range > scale ? range : scale;
        threshold[j] = RC(DUFFID_OUTLIER_SIGMAS) * scale;
    }
}

static duffid_real guard_prediction(const duffid_estimator *est, int j)
{
    const int n = est->n_dof;
    return RC(3.0) * est->gh[j] - RC(3.0) * est->gh[n + j] + est->gh[2 * n + j];
}

/* _OutlierGuard._accept (threshold NULL: no clipping) */
static void guard_accept(duffid_estimator *est, const duffid_real *x, const duffid_real *threshold)
{
    const int n = est->n_dof;
    int j;
    for (j = 0; j < n; j++) {
        if (est->g_count >= 3) {
            duffid_real r = R_FABS(x[j] - guard_prediction(est, j));
            if (threshold != NULL && threshold[j] < r) {
                r = threshold[j];
            }
            est->g_mean[j] = est->g_count == 3 ? r : est->g_mean[j] + (r - est->g_mean[j]) / RC(DUFFID_OUTLIER_MEMORY);
        }
        if (est->g_count >= 1) {
            duffid_real d = R_FABS(x[j] - est->gh[j]);
            if (d > RC(0.0) && d < est->g_step[j]) {
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

/* _OutlierGuard._replace: column j of held sample i is a glitch, replaced by value */
static void guard_replace(duffid_estimator *est, int i, int j, duffid_real value)
{
    duffid_real *held = est->p_x + i * est->n_dof;
    est->outlier_first_value = i == 1 ? est->outlier_value : R_NAN; /* replaced just before (i = 0) */
    est->outlier_first_replaced_by = i == 1 ? est->outlier_replaced_by : R_NAN;
    est->outliers++;
    est->outlier_t = (duffid_real)(est->p_k + i) * est->cfg.dt;
    est->outlier_column = j;
    est->outlier_value = held[j];
    est->outlier_replaced_by = value;
    held[j] = value;
}

static void process(duffid_estimator *est, const duffid_real *x, const duffid_real *f);

/* _OutlierGuard._release: the held samples accepted and processed, in order */
static void guard_release(duffid_estimator *est)
{
    int i;
    const int held = est->pending;
    est->pending = 0;
    for (i = 0; i < held; i++) {
        guard_accept(est, est->p_x + i * est->n_dof, est->p_threshold);
        process(est, est->p_x + i * est->n_dof, est->p_f + i * est->n_forces);
    }
}

/* ------------------------------------------------------------------ update */
/* OnlineIdentifier._restart_window: the window restarts with the next sample; with regrow the
 * previous output is reported until it is full again */
static void restart_window(duffid_estimator *est, int regrow)
{
    int i;
    const size_t moments = (size_t)(est->degree + 1) * (size_t)est->n_ch * sizeof(duffid_real);
    const size_t all = (size_t)(est->degree + 1) * (size_t)est->n_mom * sizeof(duffid_real);
    est->has_last_x = 0;
    memset(est->last_x, 0, sizeof est->last_x);
    memset(est->sgn, 0, sizeof est->sgn);
    memset(est->acc, 0, all); /* SlidingMoments.reset (the rows' noise's too) */
    memset(est->shadow, 0, SHADOWS * all);
    memset(est->acc_alt, 0, moments);
    memset(est->shadow_alt, 0, SHADOWS * moments);
    est->rate_ok = 0;
    est->start = est->n + 1;
    jumps_reset(est);
    for (i = 0; i < SHADOWS; i++) {
        est->shadow_from[i] = i == 0 ? est->n + 1 : -1;
    }
    est->poly_L = -1;
    est->one_L = -1;
    est->corr_L = -1;
    est->leave_i = -1;
    est->regrow = regrow;
}

/* OnlineIdentifier._force_jumps: whether a force jumped between the previous sample processed
 * and f (DUFFID_JUMP_FACTOR); updates the running scales */
static int force_jumps(duffid_estimator *est, const duffid_real *f)
{
    int j, jumped = 0;
    const int had_prev = est->has_f_prev, had_change = est->has_f_change, had_candidate = est->has_jump_candidate;
    duffid_real delta[DUFFID_MAX_FORCES];
    est->has_jump = est->has_jump_candidate = 0;
    for (j = 0; j < est->n_forces; j++) {
        const duffid_real change = R_FABS(f[j] - est->f_prev[j]);
        delta[j] = f[j] - est->f_prev[j];
        est->f_peak[j] = max_builtin(est->f_peak[j], R_FABS(f[j]));
        est->jump[j] = RC(0.0);
        if (had_prev && had_candidate && est->jump_candidate[j] != RC(0.0) &&
            change <= RC(DUFFID_JUMP_ISOLATION) * R_FABS(est->jump_candidate[j])) {
            est->jump[j] = est->jump_candidate[j]; /* the previous sample's jump was isolated */
            est->has_jump = 1;
        }
        est->jump_candidate[j] = RC(0.0);
        if (had_prev && !had_change) { /* the first change sets the scale */
            est->f_change[j] = change;
        } else if (had_prev) {
            if (change > RC(DUFFID_JUMP_FACTOR) * est->f_change[j] && change > RC(DUFFID_JUMP_RANGE) * est->f_peak[j]) {
                jumped = 1;
                est->jump_candidate[j] = delta[j];
            }
            est->f_change[j] = est->f_change[j] + (change - est->f_change[j]) / RC(DUFFID_OUTLIER_MEMORY);
        }
        est->f_prev[j] = f[j];
    }
    est->has_jump_candidate = jumped;
    est->has_f_change = had_prev;
    est->has_f_prev = 1;
    return jumped;
}

/* OnlineIdentifier._process: one sample into the estimator, its output into est->last */
static void process(duffid_estimator *est, const duffid_real *x, const duffid_real *f)
{
    long window;
    if (est->cfg.method == DUFFID_ROBUST && force_jumps(est, f) && est->cfg.jump_restart) {
        /* once full windows have been accumulated, the previous output until the window is
         * full again; before, a growing window's solutions are its own: it grows anew */
        int e, accumulated = 0;
        for (e = 0; e < est->n_eq; e++) {
            accumulated |= est->eq[e].rows > RC(0.0);
        }
        restart_window(est, accumulated);
    }
    est->n++;
    evaluate_channels(est, x, f);
#if DUFFID_SINGLE
    window = robust_step(est);
#else
    window = est->cfg.method == DUFFID_ROBUST ? robust_step(est) : paper_step(est);
#endif
    if (window > 0 && est->defer) { /* solved once asked (resolve) */
        est->deferred = window;
    } else if (window >= 0) { /* else held (duffid_hold): est->last stays */
        est->deferred = 0;
        publish(est, window, &est->last);
    }
}

/* The solve and publication that duffid_defer_solutions postponed, for the rows accumulated so
 * far (what the last sample would have given); 1 when there was one. */
static int resolve(duffid_estimator *est)
{
    int e;
    if (!est->deferred) {
        return 0;
    }
    for (e = 0; e < est->n_eq; e++) {
        equation_t *eq = &est->eq[e];
        const int n = est->m.blocks[e].n_unknowns, m = est->m.blocks[e].n_parts * est->n_rows;
        if (est->deferred < est->target) { /* a growing window: R is its rows' factor alone */
            solve_factor(est, eq, n, eq->R, (duffid_real)m, RC(1.0));
        } else if (eq->rows > RC(0.0)) {
            solve_factor(est, eq, n, eq->R, accumulated_rows(eq->rows, n, m, (duffid_real)est->deferred),
                         (duffid_real)est->deferred);
        }
    }
    publish(est, est->deferred, &est->last);
    est->deferred = 0;
    return 1;
}

int duffid_defer_solutions(duffid_estimator *est, int defer)
{
    if (est == NULL) {
        return DUFFID_ERR_ARGUMENT;
    }
    if (defer && (est->cfg.method != DUFFID_ROBUST || est->change_threshold > RC(0.0) ||
                  (est->auto_window && !est->window_fixed))) {
        return DUFFID_ERR_CONFIG;
    }
    if (defer < 0 || defer > DUFFID_MAX_ROW_STRIDE) {
        return DUFFID_ERR_ARGUMENT;
    }
    if (defer && est->defer && defer != est->defer && est->n >= 0) {
        return DUFFID_ERR_CONFIG; /* the rows' stride is the run's */
    }
    if (!defer && est->defer && est->n >= 0) {
        /* a deferred run does not keep what per-sample solutions need (the alternating sums of
         * the half-rate rows, moments_push): its solution is the final one (duffid_reset starts afresh) */
        resolve(est);
        return DUFFID_ERR_CONFIG;
    }
    est->defer = defer;
    return DUFFID_OK;
}

/* the outlier guard's history (identification._OutlierGuard.reset, its findings kept) */
static void guard_reset(duffid_estimator *est)
{
    int i;
    memset(est->gh, 0, sizeof est->gh);
    est->g_count = 0;
    for (i = 0; i < DUFFID_MAX_DOF; i++) {
        est->g_mean[i] = RC(0.0);
        est->g_lo[i] = R_INF;
        est->g_hi[i] = -R_INF;
        est->g_step[i] = R_INF;
    }
}

int duffid_hold(duffid_estimator *est)
{
    if (est == NULL) {
        return DUFFID_ERR_ARGUMENT;
    }
    if (est->cfg.method != DUFFID_ROBUST) {
        duffid_reset(est);
        return DUFFID_OK;
    }
    if (est->received < 0) {
        return DUFFID_OK;
    }
    if (est->pending) {
        duffid_flush(est, NULL);
    }
    guard_reset(est);
    restart_window(est, 1);
    est->has_f_prev = est->has_jump_candidate = 0; /* the next sample does not follow the previous one */
    return DUFFID_OK;
}

/* OnlineIdentifier._reported */
static void report(const duffid_estimator *est, duffid_output *out)
{
    if (out == NULL) {
        return;
    }
    *out = est->last;
    out->t = (duffid_real)est->received * est->dt;
    out->outliers = est->outliers;
    out->outlier_t = est->outlier_t;
    out->outlier_column = est->outlier_column;
    out->outlier_value = est->outlier_value;
    out->outlier_replaced_by = est->outlier_replaced_by;
    out->outlier_first_value = est->outlier_first_value;
    out->outlier_first_replaced_by = est->outlier_first_replaced_by;
}

int duffid_update(duffid_estimator *est, const duffid_real *x, const duffid_real *f, duffid_output *out)
{
    duffid_real threshold[DUFFID_MAX_DOF];
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
    if (est->pending == 1) { /* _OutlierGuard.admit: was the held sample a glitch? */
        const int n = est->n_dof;
        int pair = 0;
        for (j = 0; j < n; j++) {
            const duffid_real ahead = RC(6.0) * est->gh[j] - RC(8.0) * est->gh[n + j] + RC(3.0) * est->gh[2 * n + j];
            const int agree = R_FABS(x[j] - ahead) <= est->p_threshold[j];
            if (est->p_suspect[j] && agree) { /* the quadratic through n-2, n-1, n+1 */
                guard_replace(est, 0, j, (RC(3.0) * est->gh[j] - est->gh[n + j] + x[j]) / RC(3.0));
            }
            est->p_pair[j] = est->p_suspect[j] && !agree;
            pair |= est->p_pair[j];
        }
        if (pair) { /* a glitch of two samples, or the motion: the next one tells */
            memcpy(est->p_x + n, x, (size_t)n * sizeof(duffid_real));
            memcpy(est->p_f + est->n_forces, f, (size_t)est->n_forces * sizeof(duffid_real));
            est->pending = 2;
            report(est, out);
            return DUFFID_OK;
        }
        guard_release(est);
    } else if (est->pending == 2) {
        const int n = est->n_dof;
        for (j = 0; j < n; j++) {
            const duffid_real ahead = RC(10.0) * est->gh[j] - RC(15.0) * est->gh[n + j] + RC(6.0) * est->gh[2 * n + j];
            if (est->p_pair[j] && R_FABS(x[j] - ahead) <= est->p_threshold[j]) {
                /* the quadratic through n-3, n-2 and n+1 at n-1 and n */
                guard_replace(est, 0, j, RC(-0.5) * est->gh[n + j] + RC(4.0) / RC(3.0) * est->gh[j] + x[j] / RC(6.0));
                guard_replace(est, 1, j, RC(-0.5) * est->gh[n + j] + est->gh[j] + RC(0.5) * x[j]);
            }
        }
        guard_release(est);
    }
    if (est->g_count >= MIN_SAMPLES) {
        guard_threshold(est, threshold);
        for (j = 0; j < est->n_dof; j++) {
            est->p_suspect[j] = R_FABS(x[j] - guard_prediction(est, j)) > threshold[j];
            suspect |= est->p_suspect[j];
        }
        if (suspect) { /* held back (one sample, two for a glitch that may last two) */
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
    int any;
    if (est == NULL) {
        return 0;
    }
    any = est->pending != 0;
    if (any) {
        guard_release(est);
    }
    any |= resolve(est);
    if (any) {
        report(est, out);
    }
    return any;
}

int duffid_run(duffid_estimator *est, long n, const duffid_real *x, const duffid_real *f, duffid_output *out,
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
    return est->m.publics[i].name;
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
