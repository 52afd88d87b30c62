/*
 * duffid_estimator.h - portable C99 core of duffid's online algebraic identifier.
 *
 * A port of duffid.identification.engine.OnlineIdentifier (methods "robust" and "paper") for
 * the models Duffing1 (m x'' + b x' + k x + kp x^3 = f) and Duffing2 (the wall-m1-m2
 * chain of the paper, force on m1), optionally with an unknown constant offset force
 * per degree of freedom. On the same samples it reports the same estimates as the
 * Python class (to rounding; see tests/test_estimator_c.py).
 *
 * Design rules:
 *   - one real type, duffid_real (duffid_model.h): double, or float when every file is
 *     compiled with -DDUFFID_REAL=float; libc + libm only, no global or static mutable
 *     state: any number of estimators can run at once (one per duffid_estimator);
 *   - all memory is sized from the configuration and the model (its channels, unknowns,
 *     parameters, the window and the rows) and handed over once, either by the caller
 *     (duffid_memory_size + duffid_init, for targets without a heap) or by one malloc
 *     (duffid_create / duffid_destroy); duffid_update never allocates;
 *   - fixed work per sample: O(unknowns^2) for the least squares, O(degree x channels) for the
 *     sliding moments, no SVD, no power function and no 64-bit division per sample;
 *   - no variable-length arrays; small stack arrays are bounded by the maxima (DUFFID_MAX_*).
 *
 * Typical use:
 *     duffid_config cfg;
 *     duffid_estimator *est;
 *     char msg[256];
 *     duffid_default_config(&cfg, DUFFID_DUFFING1, DUFFID_ROBUST, 1e-3);
 *     if (duffid_create(&est, &cfg, msg, sizeof msg) != DUFFID_OK) { puts(msg); ... }
 *     for (each sample) { duffid_update(est, x, f, &out); ... out.parameters[0] ... }
 *     duffid_destroy(est);
 */
#ifndef DUFFID_ESTIMATOR_H
#define DUFFID_ESTIMATOR_H

#include <stddef.h>

#include "duffid_model.h"
#include "duffid_options.h"

#ifdef __cplusplus
extern "C" {
#endif

#define DUFFID_VERSION "0.1.0"

/* The maxima (DUFFID_MAX_*, DUFFID_MAX_ROWS), the return codes (DUFFID_OK, DUFFID_ERR_*), the
 * model codes, the parameter statuses (DUFFID_STATUS_*) and the publication constants (DUFFID_MIN_SHARE,
 * DUFFID_LOSS_FACTOR, DUFFID_GROWTH_STEADY, DUFFID_MIN_SAMPLES, DUFFID_OUTLIER_*) are in
 * duffid_facts.h (via duffid_model.h), generated from duffid.identification.c_facts. */

/* Models (their codes DUFFID_DUFFING1, DUFFID_DUFFING2, DUFFID_GENERATED: duffid_facts.h, from
 * duffid.models.registry). Public parameter order; offsets c1 [c2] are appended when
 * duffid_config.offset is set:
 *   DUFFID_DUFFING1   m, b, k, kp;                       inputs x[0], f[0]
 *   DUFFID_DUFFING2   m1, b1, k1, kp1, b2, k2, kp2, m2;  inputs x[0..1], f[0]
 *   DUFFID_GENERATED  the model described by the file compiled in with -DDUFFID_GENERATED_MODEL
 *                     (duffid_model.h: any Chain or the user's equations, its channels generated
 *                     by CasADi); offset must be 0 (the description has its offsets). */

/* Methods. */
#define DUFFID_ROBUST 0
#define DUFFID_PAPER 1

/* Row kernel families of the robust method (duffid.identification.regressors.row_exponents). */
#define DUFFID_ROWS_INTEGRALS 0
#define DUFFID_ROWS_BERNSTEIN 1
#define DUFFID_ROWS_PAPER 2

/* Status of a parameter (duffid.identification.engine.STATUSES, in this order):
 *   UNCERTAIN    not (yet) determined well enough;
 *   PUBLISHED    its relative standard error stayed at most max_uncertainty for settle s:
 *                the value is output;
 *   NOT_EXCITED  its term carries less than DUFFID_MIN_SHARE of the force balance;
 *   LOST         it was published and since then its error has been above
 *                DUFFID_LOSS_FACTOR x max_uncertainty (or its value non-physical) for settle
 *                s: the value is withdrawn (NaN).
 *   CHANGED      the recent data contradict the value it had (the change test: the estimate
 *                over the recent change_memory s departs from the accumulated one by more
 *                than change_threshold combined standard errors and by more than a published
 *                value may move, DUFFID_LOSS_FACTOR x max_uncertainty, for settle s, or by
 *                DUFFID_CHANGE_DRIFT_SHARE of those standard errors and that band for the
 *                recent estimate's memory (a drift); either counts an unknown only while
 *                changing it alone (the others kept at the accumulated values) reduces the
 *                accumulated estimate's prediction error on the recent rows by at least
 *                DUFFID_CHANGE_ALONE_SHARE of what the recent estimate reduces it by (a bias
 *                that moves with the excitation moves the unknowns jointly); after a
 *                window whose prediction error was DUFFID_CHANGE_SURPRISE times that of the
 *                accumulated rows, the recent estimate starts afresh; or the drift probe,
 *                a line in time for every unknown over the accumulated rows, one row of
 *                each sample in turn, finds a determined unknown's rate beyond
 *                DUFFID_DRIFT_SIGMAS standard errors, the line's end beyond that band from
 *                the accumulated value and the rate explaining the lines' gain alone, for
 *                settle s): the least squares
 *                restart with the first window after the change, the value is withdrawn
 *                until it is determined again from rows that span a window (the equation's other parameters, and those
 *                that had no value, are UNCERTAIN meanwhile); from then on the departed
 *                unknowns are lines in time (their rates more unknowns, at most
 *                DUFFID_MAX_LINE_UNKNOWNS in a block; the value is the line's newest), so
 *                that a drift is followed rather than restarted again and again. A published value is also
 *                withdrawn (LOST) once the estimate has moved from it by more than
 *                DUFFID_LOSS_FACTOR x max_uncertainty for settle s.
 * A growing window's estimate is published once it has stayed within max_uncertainty / 2
 * of one value while the window grew by this share of its length (full windows' need not).
 * Without a prior size, only a physical value (mass > 0, damping >= 0) whose term carries
 * at least DUFFID_MIN_SHARE of the force balance is published. */

/* Isolated displacement outliers (duffid.identification.engine.OUTLIER_*): a sample further than
 * DUFFID_OUTLIER_SIGMAS robust standard deviations (never less than the quantisation
 * step nor DUFFID_OUTLIER_RANGE of the range covered) from the quadratic through the three
 * samples before it is held back one sample; if the next sample agrees with the samples
 * before it, the held one is replaced by the quadratic through its neighbours and counted.
 * If the next one is off too, both are held; if the third agrees, the two were one glitch
 * and are replaced by the quadratic through the two samples before and the one after.
 * Meanwhile the previous output is repeated. */

/* Quadrature of the paper method's integrators. */
#define DUFFID_ADAMS3 0
#define DUFFID_TRAPEZOID 1

/*
 * Configuration. duffid_default_config fills it with the defaults of
 * duffid.identification.engine (_ROBUST_DEFAULTS / _PAPER_DEFAULTS); change fields afterwards.
 * Fields of the other method are ignored.
 */
typedef struct duffid_config {
    int model;              /* DUFFID_DUFFING1, DUFFID_DUFFING2 or DUFFID_GENERATED */
    int method;             /* DUFFID_ROBUST or DUFFID_PAPER */
    int offset;             /* 1: an unknown constant force per DOF (c1, c2) */
    duffid_real dt;              /* sampling period [s], > 0 */
    /* Optional prior sizes in public order (the option "nominal" in Python), 0 = none
     * (default: every scale comes from the data). A parameter with a prior is trustworthy
     * when its standard error is below max_uncertainty x max(|estimate|, |nominal|). */
    duffid_real nominal[DUFFID_MAX_PARAMS];
    /* The options (duffid_options.h, generated from duffid.identification.options.OPTIONS:
     * names, defaults, ranges and meanings in one place). */
#define DUFFID_DECLARE_OPTION(kind, name, default_value, minimum, maximum, methods, valid) \
    DUFFID_CTYPE_##kind name;
    DUFFID_OPTIONS(DUFFID_DECLARE_OPTION)
#undef DUFFID_DECLARE_OPTION
} duffid_config;

/* Result of one update. */
typedef struct duffid_output {
    duffid_real t;                              /* time of the sample, n * dt [s] */
    duffid_real parameters[DUFFID_MAX_PARAMS];  /* public order; NaN unless published */
    int n_parameters;
    int identified;                        /* 1 when every parameter is published */
    duffid_real condition;                      /* largest condition number over the equations */
    duffid_real uncertainty;                    /* largest relative standard error (robust), NaN (paper) */
    duffid_real window;                         /* window length [s] */
    duffid_real current[DUFFID_MAX_PARAMS];     /* public order: the solution at this sample, trusted
                                            * or not (robust: NaN while the window is not
                                            * usable; paper: as parameters). An input to the
                                            * checks of duffid.identification.trust, never a published value. */
    int status[DUFFID_MAX_PARAMS];         /* public order: DUFFID_STATUS_* (robust; paper:
                                            * PUBLISHED while identified, else UNCERTAIN) */
    long outliers;                         /* isolated displacement outliers excluded so far */
    duffid_real outlier_t;                      /* the latest: time [s], displacement index, */
    int outlier_column;                    /* value measured and value used (NaN before any) */
    duffid_real outlier_value, outlier_replaced_by;
    duffid_real outlier_first_value;            /* the latest glitch lasted two samples: the first's */
    duffid_real outlier_first_replaced_by;      /* (at outlier_t - dt, same column); NaN otherwise */
    duffid_real std_errors[DUFFID_MAX_PARAMS];  /* public order: standard error of each published
                                            * value (its unit), NaN where none is published */
    duffid_real residual;                       /* the window's one-step prediction error relative to
                                            * its force balance (robust; NaN while none) */
} duffid_output;

typedef struct duffid_estimator duffid_estimator;

/* Defaults for a model and method. Returns DUFFID_ERR_ARGUMENT for an unknown model. */
int duffid_default_config(duffid_config *cfg, int model, int method, duffid_real dt);

/* Validate a configuration; on error writes a message (if msg != NULL). */
int duffid_check_config(const duffid_config *cfg, char *msg, size_t msg_size);

/* Bytes of memory an estimator with this configuration needs (0: invalid configuration): the
 * estimator and its model's tables, the ring buffer of the window ((window / dt + 2) x channels
 * reals, robust method) and its workspace, all sized to the model. */
size_t duffid_memory_size(const duffid_config *cfg);

/* Build an estimator in caller-provided memory of at least duffid_memory_size(cfg)
 * bytes (any alignment). *est points into memory; nothing is allocated. */
int duffid_init(duffid_estimator **est, void *memory, size_t size, const duffid_config *cfg,
                char *msg, size_t msg_size);

/* Adopt a byte copy of an estimator's memory: memory holds, from its first
 * DUFFID-aligned (8-byte) address on, a copy of an estimator built by duffid_init
 * (copied from the estimator pointer on). Fixes the internal pointers and returns the
 * estimator (the copy is caller memory: never duffid_destroy it); NULL for NULL. This is
 * how FMU states are restored: copying the memory block is the estimator's state. */
duffid_estimator *duffid_relocate(void *memory);

/* Check a byte copy of an estimator's memory (8-byte aligned, size bytes, as adopted by
 * duffid_relocate) before adopting it: a valid configuration, the structure duffid_init
 * builds for it, and every count, index and buffer position within its bounds. DUFFID_OK,
 * else an error code and a message naming the field. Allocates one scratch estimator. */
int duffid_check_state(const void *memory, size_t size, char *msg, size_t msg_size);

/* Same, with one malloc; release with duffid_destroy. */
int duffid_create(duffid_estimator **est, const duffid_config *cfg, char *msg, size_t msg_size);
void duffid_destroy(duffid_estimator *est);

/* Forget all samples (start a new identification). */
void duffid_reset(duffid_estimator *est);

/* The output of the latest sample: what duffid_update reported for it. Returns the number of
 * samples received (0: none yet, and *out is then meaningless). Reads the estimator's fields
 * only, so it also works on a byte copy that duffid_check_state passed. */
long duffid_latest_output(const duffid_estimator *est, duffid_output *out);

/* The next sample does not follow the previous one (the plant was not excited or a sensor
 * saturated; the samples in between are not given: the estimator FMUs' enable input). A
 * sample held back as a suspect outlier is processed first; the window restarts with the next
 * sample, while the least squares accumulated so far, the statuses and the published values
 * are kept and reported unchanged until the window is full again (robust method; the paper
 * method's integrals cannot skip samples: it is reset). OnlineIdentifier.hold. */
int duffid_hold(duffid_estimator *est);

/* Process the samples held back as a suspect outlier (the end of a record), and the solve that
 * duffid_defer_solutions postponed. Returns 1 and fills out (if not NULL) when there was
 * either, 0 otherwise. */
int duffid_flush(duffid_estimator *est, duffid_output *out);

/* A batch that wants the final solution only (the checks of identify re-run the estimator on
 * noisy copies, at half the rate, with offsets): with defer = 1, a sample whose window is full
 * only adds its rows to the least squares; the solve and the publication wait for
 * duffid_flush, which gives the solution of all the rows accumulated, equal to what the last
 * sample would have given. With defer = s > 1 (at most DUFFID_MAX_ROW_STRIDE), only every s-th
 * sample whose window is full adds its rows (the first full one, then every s-th): a different
 * estimator over the same samples, for the noisy copies that measure its spread
 * (assessment.ROW_STRIDE); the samples between only move the window (DUFFID_ERR_CONFIG when
 * the stride changes after the first sample). The statuses and published values then rest on that one
 * publication: for final solutions only, never for a sample-by-sample output. Robust method
 * without the change test (change_threshold = 0) and with a fixed window only (else
 * DUFFID_ERR_CONFIG: both need every sample's solution). Not for a real-time loop. defer = 0
 * turns it off before the first sample (and after duffid_reset); once samples were deferred,
 * the run does not keep what per-sample solutions need: defer = 0 then solves as duffid_flush
 * does and returns DUFFID_ERR_CONFIG. */
int duffid_defer_solutions(duffid_estimator *est, int defer);

/* Consume one sample: displacements x[n_dof] and forces f[n_forces]. out may be NULL.
 * A non-finite sample returns DUFFID_ERR_SAMPLE and leaves the state unchanged. */
int duffid_update(duffid_estimator *est, const duffid_real *x, const duffid_real *f, duffid_output *out);

/* Consume n samples: x[n * n_dof] and f[n * n_forces], row by row; out[n] receives every
 * output (out may be NULL). Stops at the first non-finite sample with DUFFID_ERR_SAMPLE,
 * its index in *failed (if failed != NULL), the state as after the sample before it. */
int duffid_run(duffid_estimator *est, long n, const duffid_real *x, const duffid_real *f, duffid_output *out,
               long *failed);

/* Introspection. */
int duffid_n_parameters(const duffid_estimator *est);
int duffid_n_dof(const duffid_estimator *est);
int duffid_n_forces(const duffid_estimator *est);
const char *duffid_parameter_name(const duffid_estimator *est, int i); /* NULL if out of range */
long duffid_capacity(const duffid_estimator *est);  /* robust: buffer length in samples */
const duffid_config *duffid_get_config(const duffid_estimator *est);

/* sizeof(duffid_config) and sizeof(duffid_output), for bindings that check their layout. */
size_t duffid_config_size(void);
size_t duffid_output_size(void);

#ifdef __cplusplus
}
#endif

#endif /* DUFFID_ESTIMATOR_H */
