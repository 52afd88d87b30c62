/* duffid's online identifier as a discrete-time co-simulation model of the shared FMI
 * glue (fmus/common), FMI 2.0 and 3.0: DuffingEstimator1 (inputs x, f), DuffingEstimator2
 * (inputs x1, x2, f1), DuffingCircuitEstimator (inputs q, u: the Duffing1 core with L = m,
 * R = b, C = 1/k, a = kp) and the estimator of any chain or of the user's own equations
 * (the model DUFFID_GENERATED: its description is the generated file estimator_model.c,
 * duffid.identification.c_core.model_source, compiled in with a duffid_build.h that selects it).
 *
 * The variable table (names, start values, causality, variability) comes from the
 * generated header estimator_fmu_config.h (duffid.fmu.estimator, from the one table of
 * duffid.fmu.estimator_table), which also selects the model (ESTIMATOR_MODEL), gives its
 * sizes (ESTIMATOR_N_DOF displacements, ESTIMATOR_N_FORCES forces, ESTIMATOR_N_PARAMS
 * parameters) and sets ESTIMATOR_IDENTIFIER and ESTIMATOR_TOKEN. Layout, by value reference:
 *
 *   0                        time
 *   1 .. n_dof               displacements (inputs)
 *   then n_forces            forces (inputs; none for a force-free equation)
 *   then n_params            estimates (outputs, NaN unless published)
 *   then 4                   identified (Boolean), condition, uncertainty, window_length
 *   then n_params            <name>_status (Integer, DUFFID_STATUS_*)
 *   then 1                   outliers (Integer: isolated displacement outliers excluded)
 *   then N_OPTIONS           options (fixed parameters; codes are Integer, see below)
 *   then n_params            optional prior sizes <name>_nominal (0: none)
 *   then 1                   sample_period [s]
 *   then n_params            <name>_std_error (outputs, NaN unless published)
 *   then 1                   residual (output: the window's relative prediction error)
 *   then 2                   enable, reset (Boolean inputs: duffid_hold, duffid_reset)
 *
 * Semantics: each doStep(t, h) consumes one sample, the inputs set for time t; h must
 * equal the parameter sample_period (relative difference up to 1e-9), the record's
 * sampling period. Any other step fails with Discard and a logged error naming both values,
 * also a whole multiple of the period: the samples in between are not known to the FMU
 * (holding or interpolating the input would invent them). The first doStep builds the
 * estimator (one allocation; the options are read then: an option left at its start value
 * keeps duffid_default_config's default of the chosen method, exactly as identify() does).
 * The estimator lives in one flat block of memory: the FMU state is a byte copy of it
 * (duffid_relocate fixes its internal pointers after a restore).
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "duffid_estimator.h"
#include "fmu_instance.h"
#include "fmu_model.h"
#include "estimator_fmu_config.h"

#define N_DOF ESTIMATOR_N_DOF
#define N_FORCES ESTIMATOR_N_FORCES
#define N_PARAMS ESTIMATOR_N_PARAMS
typedef char estimator_size_check[(N_DOF >= 1 && N_DOF <= DUFFID_MAX_DOF && N_FORCES >= 0 &&
                                   N_FORCES <= DUFFID_MAX_FORCES && N_PARAMS >= 1 &&
                                   N_PARAMS <= DUFFID_MAX_PARAMS) ? 1 : -1];

/* Bit i set: public parameter i is the reciprocal of the core's (the circuit's C = 1/k); its
 * estimate is output as 1/value (0 -> +Inf, as duffid.models.chain.DuffingCircuit) and its
 * prior size <name>_nominal given as the reciprocal of the core's. */
#ifndef ESTIMATOR_RECIPROCAL_MASK
#define ESTIMATOR_RECIPROCAL_MASK 0
#endif
#define RECIPROCAL(i) ((ESTIMATOR_RECIPROCAL_MASK >> (i)) & 1)

/* Public value of the core's parameter i. */
static double public_value(int i, double value)
{
    if (!RECIPROCAL(i)) return value;
    return value == 0.0 ? INFINITY : 1.0 / value;
}

/* Options, in value-reference order after the outputs: the method, then the option table
 * of duffid_options.h (generated from duffid.identification.options.OPTIONS). */
enum {
    OPT_METHOD, /* 0 robust, 1 paper */
#define DUFFID_OPTION_ENUM(kind, name, default_value, minimum, maximum, methods, valid) OPT_##name,
    DUFFID_FMU_OPTIONS(DUFFID_OPTION_ENUM)
#undef DUFFID_OPTION_ENUM
    N_OPTIONS
};

#define VR_X 1
#define VR_F (1 + N_DOF)
#define VR_EST (VR_F + N_FORCES)
#define VR_IDENTIFIED (VR_EST + N_PARAMS)
#define VR_CONDITION (VR_IDENTIFIED + 1)
#define VR_UNCERTAINTY (VR_IDENTIFIED + 2)
#define VR_WINDOW_LENGTH (VR_IDENTIFIED + 3)
#define VR_STATUS (VR_IDENTIFIED + 4)
#define VR_OUTLIERS (VR_STATUS + N_PARAMS)
#define VR_OPT (VR_OUTLIERS + 1)
#define VR_NOMINAL (VR_OPT + N_OPTIONS)
#define VR_SAMPLE_PERIOD (VR_NOMINAL + N_PARAMS)
#define VR_STD_ERROR (VR_SAMPLE_PERIOD + 1)
#define VR_RESIDUAL (VR_STD_ERROR + N_PARAMS)
#define VR_ENABLE (VR_RESIDUAL + 1)
#define VR_RESET (VR_ENABLE + 1)
#define N_VARS_EXPECTED (VR_RESET + 1)

typedef char estimator_layout_check[(N_VARS_EXPECTED == ESTIMATOR_N_VARS) ? 1 : -1];

#define DT_RTOL 1e-9

/* Model data (Instance.model_data). */
typedef struct EstData {
    int started;              /* the first doStep built the estimator */
    int have_out;             /* out holds the result of the last sample */
    double dt;                /* sampling period fixed by the first doStep */
    duffid_config cfg;
    duffid_output out;
    void *mem;                /* estimator memory (calloc, kept across resets of the data) */
    size_t mem_size;
    duffid_estimator *est;    /* inside mem */
} EstData;

/* Header of the model data in an FMU state, followed by est_bytes of estimator memory. */
typedef struct EstState {
    unsigned long long est_bytes;
    int started, have_out;
    double dt;
    duffid_config cfg;
    duffid_output out;
} EstState;

static int evaluate(Instance *inst)
{
    const EstData *d = (const EstData *)inst->model_data;
    double *v = inst->vars;
    int i;
    if (d != NULL && d->have_out) {
        for (i = 0; i < N_PARAMS; i++) v[VR_EST + i] = public_value(i, d->out.parameters[i]);
        for (i = 0; i < N_PARAMS; i++) v[VR_STATUS + i] = (double)d->out.status[i];
        v[VR_OUTLIERS] = (double)(d->out.outliers < INT32_MAX ? d->out.outliers : INT32_MAX); /* an Integer */
        v[VR_IDENTIFIED] = d->out.identified ? 1.0 : 0.0;
        v[VR_CONDITION] = d->out.condition;
        v[VR_UNCERTAINTY] = d->out.uncertainty;
        v[VR_WINDOW_LENGTH] = d->out.window;
        for (i = 0; i < N_PARAMS; i++) { /* relative errors are the same for a reciprocal */
            const double value = d->out.parameters[i];
            v[VR_STD_ERROR + i] = RECIPROCAL(i) ? d->out.std_errors[i] / fabs(value) * fabs(public_value(i, value))
                                                : d->out.std_errors[i];
        }
        v[VR_RESIDUAL] = d->out.residual;
    } else {
        for (i = 0; i < N_PARAMS; i++) v[VR_EST + i] = NAN;
        for (i = 0; i < N_PARAMS; i++) v[VR_STATUS + i] = (double)DUFFID_STATUS_UNCERTAIN;
        v[VR_OUTLIERS] = 0.0;
        v[VR_IDENTIFIED] = 0.0;
        v[VR_CONDITION] = NAN;
        v[VR_UNCERTAINTY] = NAN;
        v[VR_WINDOW_LENGTH] = NAN;
        for (i = 0; i < N_PARAMS; i++) v[VR_STD_ERROR + i] = NAN;
        v[VR_RESIDUAL] = NAN;
    }
    return 0;
}

static EstData *data_of(Instance *inst)
{
    if (inst->model_data == NULL) inst->model_data = calloc(1, sizeof(EstData));
    return (EstData *)inst->model_data;
}

/* Ensures at least size bytes of estimator memory (allocates only when it grows). */
static int reserve(Instance *inst, EstData *d, size_t size)
{
    void *mem;
    if (d->mem != NULL && d->mem_size >= size) return 0;
    mem = calloc(1, size);
    if (mem == NULL) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "out of memory (%lu bytes for the estimator)",
                (unsigned long)size);
        return 1;
    }
    free(d->mem);
    d->mem = mem;
    d->mem_size = size;
    d->est = NULL;
    return 0;
}

/* An option coded as a small non-negative integer: its value, or -1 (reason in msg). */
static int coded_option(const Instance *inst, int option, int max_value, char *msg, size_t msg_size)
{
    double v = inst->vars[VR_OPT + option];
    if (!(v >= 0.0 && v <= (double)max_value && v == floor(v))) {
        snprintf(msg, msg_size, "parameter %s must be an integer in 0 .. %d, got %g",
                 inst->model->names[VR_OPT + option], max_value, v);
        return -1;
    }
    return (int)v;
}

/* The configuration from the parameters: method defaults, then every option or nominal
 * value that differs from its start value; nonzero with the reason in msg. */
static int config_of(const Instance *inst, double dt, duffid_config *cfg, char *msg, size_t msg_size)
{
    const double *v = inst->vars, *start = inst->model->start;
    int method = coded_option(inst, OPT_METHOD, 1, msg, msg_size), i, code;
    char reason[256];
#define CHANGED(opt) (v[VR_OPT + (opt)] != start[VR_OPT + (opt)])
    if (method < 0) return 1;
    duffid_default_config(cfg, ESTIMATOR_MODEL, method == 0 ? DUFFID_ROBUST : DUFFID_PAPER, dt);
    for (i = 0; i < N_PARAMS; i++)
        if (v[VR_NOMINAL + i] != start[VR_NOMINAL + i])
            cfg->nominal[i] = RECIPROCAL(i) ? 1.0 / fabs(v[VR_NOMINAL + i]) : v[VR_NOMINAL + i];
    /* a REAL option is taken as it is (duffid_check_config checks its range); a CODE option
     * must be a whole number in its range first (the only code without a maximum, n_rows, is
     * bounded by the core's DUFFID_MAX_ROWS) */
#define SET_REAL(name, maximum) cfg->name = v[VR_OPT + OPT_##name];
#define SET_CODE(name, maximum)                                                              \
    if ((code = coded_option(inst, OPT_##name, (maximum) >= 0 ? (maximum) : DUFFID_MAX_ROWS, msg, \
                             msg_size)) < 0)                                                 \
        return 1;                                                                            \
    cfg->name = code;
#define DUFFID_SET_OPTION(kind, name, default_value, minimum, maximum, methods, valid) \
    if (CHANGED(OPT_##name)) {                                                          \
        SET_##kind(name, maximum)                                                       \
    }
    DUFFID_FMU_OPTIONS(DUFFID_SET_OPTION)
#undef DUFFID_SET_OPTION
#undef SET_CODE
#undef SET_REAL
#undef CHANGED
    if (duffid_check_config(cfg, reason, sizeof reason) != DUFFID_OK) {
        snprintf(msg, msg_size, "invalid estimator parameters: %s", reason);
        return 1;
    }
    return 0;
}

/* config_of, logging the reason of a failure. */
static int make_config(Instance *inst, double dt, duffid_config *cfg)
{
    char msg[512];
    if (config_of(inst, dt, cfg, msg, sizeof msg) != 0) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "%s", msg);
        return 1;
    }
    return 0;
}

static int start_estimator(Instance *inst, EstData *d, double h)
{
    duffid_config cfg;
    char msg[256];
    if (make_config(inst, h, &cfg) != 0) return 1;
    if (reserve(inst, d, duffid_memory_size(&cfg)) != 0) return 1;
    if (duffid_init(&d->est, d->mem, d->mem_size, &cfg, msg, sizeof msg) != DUFFID_OK) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "the estimator could not be built: %s", msg);
        return 1;
    }
    if (duffid_n_dof(d->est) != N_DOF || duffid_n_forces(d->est) != N_FORCES ||
        duffid_n_parameters(d->est) != N_PARAMS) { /* a model compiled in that is not the table's */
        fmu_log(inst, FMU_ERROR, "logStatusError", "the estimator's model has %d displacements, %d forces and %d "
                "parameters; this FMU's variables are for %d, %d and %d", duffid_n_dof(d->est),
                duffid_n_forces(d->est), duffid_n_parameters(d->est), N_DOF, N_FORCES, N_PARAMS);
        return 1;
    }
    d->cfg = cfg;
    d->dt = h;
    d->started = 1;
    d->have_out = 0;
    return 0;
}

static int do_step(Instance *inst, double t, double h)
{
    EstData *d = data_of(inst);
    double x[N_DOF], f[N_FORCES > 0 ? N_FORCES : 1] = {0.0}, period = inst->vars[VR_SAMPLE_PERIOD];
    duffid_output out;
    int i;
    if (d == NULL) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "out of memory");
        return 1;
    }
    if (!(period > 0.0 && isfinite(period))) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "parameter sample_period must be positive, got %.17g", period);
        return 1;
    }
    if (fabs(h - period) > DT_RTOL * period) {
        double ratio = h / period;
        fmu_log(inst, FMU_ERROR, "logStatusError",
                "communicationStepSize %.17g at t = %.17g differs from the parameter sample_period %.17g: "
                "each doStep consumes one sample; set sample_period to the record's sampling period and "
                "step by it%s", h, t, period,
                fabs(ratio - floor(ratio + 0.5)) <= 1e-9 * ratio && ratio > 1.5
                    ? " (a step of several periods is refused: the samples in between are not known)" : "");
        return 1;
    }
    if (d->started && fabs(d->dt - period) > DT_RTOL * period) { /* a state saved with another period */
        fmu_log(inst, FMU_ERROR, "logStatusError", "the estimator runs at the sample period %.17g of its restored "
                "FMU state, not at the parameter sample_period %.17g", d->dt, period);
        return 1;
    }
    if (!d->started && start_estimator(inst, d, period) != 0) return 1;
    if (inst->vars[VR_RESET] != 0.0) { /* a new identification starts with this sample */
        duffid_reset(d->est);
        d->have_out = 0;
    }
    if (inst->vars[VR_ENABLE] == 0.0) { /* skipped: the outputs hold, the window restarts after it */
        duffid_hold(d->est);
        return 0;
    }
    for (i = 0; i < N_DOF; i++) x[i] = inst->vars[VR_X + i];
    for (i = 0; i < N_FORCES; i++) f[i] = inst->vars[VR_F + i];
    if (duffid_update(d->est, x, f, &out) != DUFFID_OK) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "sample at t = %.17g is not finite; rejected", t);
        return 1;
    }
    if (out.outliers > (d->have_out ? d->out.outliers : 0)) {
        if (out.outlier_first_value == out.outlier_first_value) { /* a glitch of two samples: its first */
            fmu_log(inst, FMU_WARNING, "logStatusWarning",
                    "x%d = %.17g at t = %.17g excluded as an isolated outlier (replaced by %.17g)",
                    out.outlier_column + 1, out.outlier_first_value, out.outlier_t - d->dt,
                    out.outlier_first_replaced_by);
        }
        fmu_log(inst, FMU_WARNING, "logStatusWarning",
                "x%d = %.17g at t = %.17g excluded as an isolated outlier (replaced by %.17g)",
                out.outlier_column + 1, out.outlier_value, out.outlier_t, out.outlier_replaced_by);
    }
    d->out = out;
    d->have_out = 1;
    return 0;
}

static void free_data(Instance *inst)
{
    EstData *d = (EstData *)inst->model_data;
    if (d == NULL) return;
    free(d->mem);
    free(d);
    inst->model_data = NULL;
}

static size_t est_bytes(const EstData *d)
{
    if (d == NULL || !d->started || d->est == NULL) return 0;
    return d->mem_size - (size_t)((const char *)d->est - (const char *)d->mem);
}

static size_t state_size(const Instance *inst)
{
    return sizeof(EstState) + est_bytes((const EstData *)inst->model_data);
}

static void save_state(const Instance *inst, void *bytes)
{
    const EstData *d = (const EstData *)inst->model_data;
    EstState h;
    memset(&h, 0, sizeof h);
    h.est_bytes = est_bytes(d);
    if (d != NULL) {
        h.started = d->started;
        h.have_out = d->have_out;
        h.dt = d->dt;
        h.cfg = d->cfg;
        h.out = d->out;
    }
    memcpy(bytes, &h, sizeof h);
    if (h.est_bytes > 0) memcpy((char *)bytes + sizeof h, d->est, (size_t)h.est_bytes);
}

static int same_bits(double a, double b)
{
    return memcmp(&a, &b, sizeof a) == 0;
}

/* Nonzero when two configurations are equal, field by field (bits of the doubles). */
static int same_config(const duffid_config *a, const duffid_config *b)
{
    int i, same = a->model == b->model && a->method == b->method && a->offset == b->offset &&
                  same_bits(a->dt, b->dt);
    for (i = 0; i < DUFFID_MAX_PARAMS; i++) same = same && same_bits(a->nominal[i], b->nominal[i]);
#define SAME_REAL(name) same = same && same_bits(a->name, b->name);
#define SAME_CODE(name) same = same && a->name == b->name;
#define DUFFID_SAME_OPTION(kind, name, default_value, minimum, maximum, methods, valid) SAME_##kind(name)
    DUFFID_OPTIONS(DUFFID_SAME_OPTION)
#undef DUFFID_SAME_OPTION
#undef SAME_CODE
#undef SAME_REAL
    return same;
}

/* Nonzero when two outputs are equal, field by field (bits of the doubles). */
static int same_output(const duffid_output *a, const duffid_output *b)
{
    int i, same = same_bits(a->t, b->t) && a->n_parameters == b->n_parameters && a->identified == b->identified &&
                  same_bits(a->condition, b->condition) && same_bits(a->uncertainty, b->uncertainty) &&
                  same_bits(a->window, b->window) && a->outliers == b->outliers &&
                  same_bits(a->outlier_t, b->outlier_t) && a->outlier_column == b->outlier_column &&
                  same_bits(a->outlier_value, b->outlier_value) &&
                  same_bits(a->outlier_replaced_by, b->outlier_replaced_by) && same_bits(a->residual, b->residual) &&
                  same_bits(a->outlier_first_value, b->outlier_first_value) &&
                  same_bits(a->outlier_first_replaced_by, b->outlier_first_replaced_by);
    for (i = 0; i < DUFFID_MAX_PARAMS; i++)
        same = same && same_bits(a->parameters[i], b->parameters[i]) && same_bits(a->current[i], b->current[i]) &&
               a->status[i] == b->status[i] && same_bits(a->std_errors[i], b->std_errors[i]);
    return same;
}

/* Every invariant of the model data of an FMU state (the header here, the estimator memory
 * by duffid_check_state): a started estimator belongs to a stepping instance, runs at the
 * state's sample_period with the configuration of the state's parameters, and the last
 * output is the estimator's own; nothing is changed. */
static int check_state(const Instance *inst, const void *bytes, size_t size, char *msg, size_t msg_size)
{
    EstState h;
    duffid_config cfg;
    duffid_output latest;
    const duffid_estimator *est;
    long received;
    if (size < sizeof h) {
        snprintf(msg, msg_size, "model data of %lu bytes is too short", (unsigned long)size);
        return 1;
    }
    memcpy(&h, bytes, sizeof h);
    if (h.est_bytes != (unsigned long long)(size - sizeof h)) {
        snprintf(msg, msg_size, "estimator memory of %llu bytes in %lu bytes of model data", h.est_bytes,
                 (unsigned long)size);
        return 1;
    }
    if ((h.started != 0 && h.started != 1) || (h.have_out != 0 && h.have_out != 1) ||
        (!h.started && (h.est_bytes != 0 || h.have_out))) {
        snprintf(msg, msg_size, "flags started = %d, have_out = %d with %llu bytes of estimator", h.started,
                 h.have_out, h.est_bytes);
        return 1;
    }
    if (!h.started) return 0;
    if (!(inst->mode & (MODE_STEP | MODE_STEP_FAILED | MODE_TERMINATED))) {
        snprintf(msg, msg_size, "a started estimator in state %s", mode_name(inst->mode));
        return 1;
    }
    if (!same_bits(h.dt, inst->vars[VR_SAMPLE_PERIOD])) {
        snprintf(msg, msg_size, "sampling period %.17g, parameter sample_period %.17g", h.dt,
                 inst->vars[VR_SAMPLE_PERIOD]);
        return 1;
    }
    if (config_of(inst, h.dt, &cfg, msg, msg_size) != 0) return 1;
    if (!same_config(&h.cfg, &cfg)) {
        snprintf(msg, msg_size, "the estimator's configuration is not that of the state's parameters");
        return 1;
    }
    if (duffid_check_state((const char *)bytes + sizeof h, (size_t)h.est_bytes, msg, msg_size) != DUFFID_OK)
        return 1;
    est = (const duffid_estimator *)((const char *)bytes + sizeof h);
    if (!same_config(duffid_get_config(est), &cfg)) {
        snprintf(msg, msg_size, "the estimator memory's configuration is not that of the state's parameters");
        return 1;
    }
    received = duffid_latest_output(est, &latest);
    if (h.have_out != (received > 0) || (h.have_out && !same_output(&h.out, &latest))) {
        snprintf(msg, msg_size, "the last output is not the estimator's (%ld samples received)", received);
        return 1;
    }
    return 0;
}

static int load_state(Instance *inst, const void *bytes, size_t size)
{
    EstState h;
    EstData *d;
    char *base;
    if (size < sizeof h) return 1;
    memcpy(&h, bytes, sizeof h);
    if (size != sizeof h + (size_t)h.est_bytes || (h.started && h.est_bytes == 0)) return 1;
    d = data_of(inst);
    if (d == NULL) return 1;
    if (h.started) {
        if (reserve(inst, d, (size_t)h.est_bytes + 8u) != 0) return 1;
        base = (char *)(((uintptr_t)d->mem + 7u) & ~(uintptr_t)7u);
        memcpy(base, (const char *)bytes + sizeof h, (size_t)h.est_bytes);
        d->est = duffid_relocate(d->mem);
    }
    d->started = h.started;
    d->have_out = h.have_out;
    d->dt = h.dt;
    d->cfg = h.cfg;
    d->out = h.out;
    return 0;
}

const ModelInfo fmu_model_info = {
    DUFFID_DISCRETE_MODEL_FIELDS(estimator, ESTIMATOR_IDENTIFIER, ESTIMATOR_TOKEN, ESTIMATOR_N_VARS),
};
