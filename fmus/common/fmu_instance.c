/* Version-independent FMU instance (see fmu_instance.h). */
#include "fmu_instance.h"

#include <math.h>
#include <stddef.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define SNAPSHOT_MAGIC 0x44554646u /* "DUFF" */
/* Format of the FMU state (part of its identity: a state of another format is refused). */
#define SNAPSHOT_FORMAT "duffid-fmu-state-2"
#define MAX_STEPS_PER_CALL 1000000UL

/* ------------------------------------------------------------------ logging */

void fmu_log(Instance *inst, FmuStatus status, const char *category, const char *fmt, ...)
{
    char message[1024];
    va_list args;
    if (inst == NULL || inst->log == NULL) return;
    if (status < FMU_DISCARD && !inst->logging_on) return; /* errors are always logged */
    va_start(args, fmt);
    vsnprintf(message, sizeof message, fmt, args);
    va_end(args);
    inst->log(inst, status, category, message);
}

static void log_error(Instance *inst, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

static void log_error(Instance *inst, const char *fmt, ...)
{
    char message[1024];
    va_list args;
    if (inst == NULL || inst->log == NULL) return;
    va_start(args, fmt);
    vsnprintf(message, sizeof message, fmt, args);
    va_end(args);
    inst->log(inst, FMU_ERROR, "logStatusError", message);
}

const char *mode_name(Mode mode)
{
    switch (mode) {
    case MODE_INSTANTIATED: return "Instantiated";
    case MODE_INITIALIZATION: return "Initialization Mode";
    case MODE_EVENT: return "Event Mode";
    case MODE_CONTINUOUS_TIME: return "Continuous-Time Mode";
    case MODE_STEP: return "Step Mode";
    case MODE_STEP_FAILED: return "Step Failed";
    case MODE_TERMINATED: return "Terminated";
    case MODE_ERROR: return "Error";
    }
    return "unknown";
}

FmuStatus fmu_check(Instance *inst, const char *function, int allowed_modes)
{
    if (inst == NULL) return FMU_ERROR; /* nothing to log to */
    if (!(inst->mode & allowed_modes)) {
        if (inst->mode == MODE_STEP_FAILED && inst->terminate_requested)
            log_error(inst, "%s must not be called after the FMU asked to end the simulation (at t = %.17g): "
                      "terminate, reset or free it", function, inst->time);
        else
            log_error(inst, "%s must not be called in state %s", function, mode_name(inst->mode));
        return FMU_ERROR;
    }
    return FMU_OK;
}

int fmu_null_arg(Instance *inst, const char *function, const char *argument, const void *p, size_t n)
{
    if (n > 0 && p == NULL) {
        log_error(inst, "%s: argument %s must not be NULL", function, argument);
        return 1;
    }
    return 0;
}

/* ------------------------------------------------------------------ lifetime */

static void set_start_values(Instance *inst)
{
    const ModelInfo *m = inst->model;
    size_t i;
    for (i = 0; i < m->n_vars; i++) inst->vars[i] = isnan(m->start[i]) ? 0.0 : m->start[i];
    for (i = 0; i < m->n_states; i++) inst->yscale[i] = 0.0;
    inst->time = 0.0;
    inst->start_time = 0.0;
    inst->stop_time = 0.0;
    inst->stop_time_defined = 0;
    inst->tolerance = m->default_tolerance > 0 ? m->default_tolerance : 1e-8;
    inst->h_next = 0.0;
    inst->terminate_requested = 0;
    inst->terminate_time = 0.0;
    inst->dirty = 1;
    inst->mode = MODE_INSTANTIATED;
}

Instance *instance_new(const ModelInfo *model, const char *name, const char *token,
                       const char *resource_location, int fmi_version, InterfaceKind kind, int logging_on,
                       LogFunction log, void *log_env, void (*log_callback)(void))
{
    Instance tmp, *inst;
    size_t n, i;
    memset(&tmp, 0, sizeof tmp);
    tmp.model = model;
    tmp.name = (char *)(name ? name : "?");
    tmp.log = log;
    tmp.log_env = log_env;
    tmp.log_callback = log_callback;
    tmp.logging_on = 1;
    tmp.fmi_version = fmi_version;
    if (name == NULL || name[0] == '\0') {
        log_error(&tmp, "instanceName must be a non-empty string");
        return NULL;
    }
    if (token == NULL || strcmp(token, model->instantiation_token) != 0) {
        log_error(&tmp, "instantiation token %s does not match this FMU's %s",
                  token ? token : "(NULL)", model->instantiation_token);
        return NULL;
    }
    if (!(model->interfaces & (kind == KIND_CO_SIMULATION ? INTERFACE_CO_SIMULATION : INTERFACE_MODEL_EXCHANGE))) {
        log_error(&tmp, "this FMU does not provide %s",
                  kind == KIND_CO_SIMULATION ? "Co-Simulation" : "Model Exchange");
        return NULL;
    }
    inst = (Instance *)calloc(1, sizeof(Instance));
    if (inst == NULL) return NULL;
    *inst = tmp;
    inst->name = (char *)malloc(strlen(name) + 1);
    if (resource_location != NULL) {
        inst->resource_location = (char *)malloc(strlen(resource_location) + 1);
        if (inst->resource_location != NULL) strcpy(inst->resource_location, resource_location);
    }
    n = model->n_states;
    inst->vars = (double *)calloc(model->n_vars ? model->n_vars : 1, sizeof(double));
    inst->work = (double *)calloc(model->n_work ? model->n_work : 1, sizeof(double));
    inst->iwork = (long long *)calloc(model->n_iwork ? model->n_iwork : 1, sizeof(long long));
    inst->y = (double *)calloc(13 * (n ? n : 1), sizeof(double));
    inst->saved = (double *)calloc(model->n_vars ? model->n_vars : 1, sizeof(double));
    if (inst->name == NULL || inst->vars == NULL || inst->work == NULL || inst->iwork == NULL ||
        inst->y == NULL || inst->saved == NULL || (resource_location != NULL && inst->resource_location == NULL)) {
        log_error(inst, "out of memory");
        instance_free(inst);
        return NULL;
    }
    strcpy(inst->name, name);
    n = n ? n : 1;
    inst->y1 = inst->y + n;
    inst->ytmp = inst->y + 2 * n;
    inst->err = inst->y + 3 * n;
    inst->yscale = inst->y + 4 * n;
    for (i = 0; i < 7; i++) inst->k[i] = inst->y + (5 + i) * n;
    inst->kind = kind;
    inst->logging_on = logging_on;
    set_start_values(inst);
    if (model->instantiate != NULL && model->instantiate(inst) != 0) {
        instance_free(inst);
        return NULL;
    }
    return inst;
}

static void free_model_data(Instance *inst)
{
    if (inst->model->free_data != NULL) inst->model->free_data(inst);
    inst->model_data = NULL;
}

void instance_free(Instance *inst)
{
    if (inst == NULL) return;
    free_model_data(inst);
    free(inst->name);
    free(inst->resource_location);
    free(inst->vars);
    free(inst->work);
    free(inst->iwork);
    free(inst->y);
    free(inst->saved);
    free(inst);
}

FmuStatus instance_reset(Instance *inst)
{
    free_model_data(inst);
    set_start_values(inst);
    if (inst->model->instantiate != NULL && inst->model->instantiate(inst) != 0) {
        inst->mode = MODE_ERROR;
        return FMU_ERROR;
    }
    return FMU_OK;
}

/* ------------------------------------------------------------------ evaluation */

/* Nonzero when variable vr may hold a non-finite value (ModelInfo.non_finite). */
static int may_be_non_finite(const ModelInfo *m, size_t vr)
{
    return m->non_finite != NULL && m->non_finite[vr];
}

static int first_non_finite(const Instance *inst)
{
    size_t i;
    for (i = 0; i < inst->model->n_vars; i++) {
        if (inst->model->non_finite_outputs && inst->model->causality[i] == CAUSALITY_OUTPUT) continue;
        if (may_be_non_finite(inst->model, i)) continue;
        if (!isfinite(inst->vars[i])) return (int)i;
    }
    return -1;
}

/* Evaluates the model if needed; on failure logs and returns nonzero (vars may be partial). */
static int evaluate(Instance *inst, const char *function)
{
    int rc, bad;
    if (!inst->dirty) return 0;
    inst->n_evaluations++;
    rc = inst->model->evaluate(inst);
    if (rc != 0) {
        log_error(inst, "%s: the model equations could not be evaluated at t = %.17g "
                  "(nonlinear solver or function failure, code %d)", function, inst->time, rc);
        return 1;
    }
    bad = first_non_finite(inst);
    if (bad >= 0) {
        log_error(inst, "%s: variable %s is not finite (%g) at t = %.17g", function,
                  inst->model->names[bad], inst->vars[bad], inst->time);
        return 1;
    }
    inst->dirty = 0;
    return 0;
}

FmuStatus fmu_evaluate(Instance *inst, const char *function)
{
    if (evaluate(inst, function) != 0) {
        inst->mode = MODE_ERROR;
        return FMU_ERROR;
    }
    return FMU_OK;
}

FmuStatus fmu_setup(Instance *inst, int tolerance_defined, double tolerance, double start_time,
                    int stop_time_defined, double stop_time)
{
    if (tolerance_defined) {
        if (!(tolerance > 0.0) || !isfinite(tolerance)) {
            log_error(inst, "tolerance must be a positive number, got %g", tolerance);
            return FMU_ERROR;
        }
        inst->tolerance = tolerance;
    }
    if (!isfinite(start_time)) {
        log_error(inst, "startTime must be finite, got %g", start_time);
        return FMU_ERROR;
    }
    if (stop_time_defined && !(stop_time >= start_time)) {
        log_error(inst, "stopTime %g is before startTime %g", stop_time, start_time);
        return FMU_ERROR;
    }
    inst->start_time = start_time;
    inst->time = start_time;
    inst->stop_time = stop_time;
    inst->stop_time_defined = stop_time_defined;
    inst->dirty = 1;
    return FMU_OK;
}

FmuStatus fmu_enter_initialization(Instance *inst)
{
    if (inst->model->enter_initialization != NULL && inst->model->enter_initialization(inst) != 0) {
        inst->mode = MODE_ERROR;
        return FMU_ERROR;
    }
    inst->mode = MODE_INITIALIZATION;
    inst->dirty = 1;
    return FMU_OK;
}

FmuStatus fmu_terminate(Instance *inst)
{
    if (inst->model->terminate != NULL && inst->model->terminate(inst) != 0) {
        inst->mode = MODE_ERROR;
        return FMU_ERROR;
    }
    inst->mode = MODE_TERMINATED;
    return FMU_OK;
}

FmuStatus fmu_exit_initialization(Instance *inst)
{
    size_t i;
    if (inst->model->exit_initialization != NULL && inst->model->exit_initialization(inst) != 0) {
        inst->mode = MODE_ERROR;
        return FMU_ERROR;
    }
    inst->dirty = 1;
    if (evaluate(inst, "exit initialization mode") != 0) {
        inst->mode = MODE_ERROR;
        return FMU_ERROR;
    }
    for (i = 0; i < inst->model->n_states; i++)
        inst->yscale[i] = fabs(inst->vars[inst->model->state_vr[i]]);
    inst->h_next = 0.0;
    inst->mode = inst->kind == KIND_CO_SIMULATION ? MODE_STEP : MODE_EVENT;
    return FMU_OK;
}

/* ------------------------------------------------------------------ variables */

static int set_allowed(const Instance *inst, size_t vr)
{
    const ModelInfo *m = inst->model;
    int modes = 0;
    switch (m->causality[vr]) {
    case CAUSALITY_PARAMETER:
        modes = MODE_INSTANTIATED | MODE_INITIALIZATION;
        if (m->variability[vr] == VARIABILITY_TUNABLE) modes |= MODE_EVENT | MODE_STEP;
        break;
    case CAUSALITY_INPUT:
        modes = MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS_TIME | MODE_STEP;
        break;
    default:
        if (m->settable_start[vr]) modes = MODE_INSTANTIATED | MODE_INITIALIZATION;
    }
    return modes & inst->mode;
}

static int var_type(const ModelInfo *m, size_t vr)
{
    return m->types != NULL ? m->types[vr] : VARTYPE_FLOAT64;
}

static const char *type_name(int type)
{
    return type == VARTYPE_INTEGER ? "an Integer" : type == VARTYPE_BOOLEAN ? "a Boolean" : "a Float64";
}

/* Nonzero (logged) unless every reference is a variable of the type. */
static int check_refs(Instance *inst, const char *function, int type, const unsigned vr[], size_t nvr)
{
    size_t i;
    for (i = 0; i < nvr; i++) {
        if (vr[i] >= inst->model->n_vars) {
            log_error(inst, "%s: unknown value reference %u", function, vr[i]);
            return 1;
        }
        if (var_type(inst->model, vr[i]) != type) {
            log_error(inst, "%s: variable %s (value reference %u) is not %s variable", function,
                      inst->model->names[vr[i]], vr[i], type_name(type));
            return 1;
        }
    }
    return 0;
}

static void store(Instance *inst, unsigned vr, double v)
{
    if (inst->vars[vr] != v) inst->dirty = 1;
    inst->vars[vr] = v;
}

FmuStatus fmu_get_float64(Instance *inst, const char *function, const unsigned vr[], size_t nvr,
                          double value[])
{
    size_t i;
    if (fmu_null_arg(inst, function, "valueReferences", vr, nvr) ||
        fmu_null_arg(inst, function, "values", value, nvr))
        return FMU_ERROR;
    if (check_refs(inst, function, VARTYPE_FLOAT64, vr, nvr)) return FMU_ERROR;
    if (inst->mode != MODE_INSTANTIATED && inst->mode != MODE_ERROR && evaluate(inst, function) != 0) {
        inst->mode = MODE_ERROR;
        return FMU_ERROR;
    }
    for (i = 0; i < nvr; i++) value[i] = inst->vars[vr[i]];
    return FMU_OK;
}

FmuStatus fmu_set_float64(Instance *inst, const char *function, const unsigned vr[], size_t nvr,
                          const double value[])
{
    size_t i;
    if (fmu_null_arg(inst, function, "valueReferences", vr, nvr) ||
        fmu_null_arg(inst, function, "values", value, nvr))
        return FMU_ERROR;
    if (check_refs(inst, function, VARTYPE_FLOAT64, vr, nvr)) return FMU_ERROR;
    for (i = 0; i < nvr; i++) { /* all or nothing */
        if (!set_allowed(inst, vr[i])) {
            log_error(inst, "%s: variable %s (value reference %u) cannot be set in state %s",
                      function, inst->model->names[vr[i]], vr[i], mode_name(inst->mode));
            return FMU_ERROR;
        }
        if (!isfinite(value[i]) && !may_be_non_finite(inst->model, vr[i])) {
            log_error(inst, "%s: value %g of variable %s (value reference %u) is not finite; rejected",
                      function, value[i], inst->model->names[vr[i]], vr[i]);
            return FMU_ERROR;
        }
    }
    for (i = 0; i < nvr; i++) store(inst, vr[i], value[i]);
    return FMU_OK;
}

/* Checks of a get (and evaluation); nonzero on failure (logged). */
static int get_checks(Instance *inst, const char *function, int type, const unsigned vr[], size_t nvr,
                      const void *value)
{
    if (fmu_null_arg(inst, function, "valueReferences", vr, nvr) ||
        fmu_null_arg(inst, function, "values", value, nvr) || check_refs(inst, function, type, vr, nvr))
        return 1;
    if (inst->mode != MODE_INSTANTIATED && inst->mode != MODE_ERROR && evaluate(inst, function) != 0) {
        inst->mode = MODE_ERROR;
        return 1;
    }
    return 0;
}

/* Checks of a set (all or nothing); nonzero on failure (logged). */
static int set_checks(Instance *inst, const char *function, int type, const unsigned vr[], size_t nvr,
                      const void *value)
{
    size_t i;
    if (fmu_null_arg(inst, function, "valueReferences", vr, nvr) ||
        fmu_null_arg(inst, function, "values", value, nvr) || check_refs(inst, function, type, vr, nvr))
        return 1;
    for (i = 0; i < nvr; i++) {
        if (!set_allowed(inst, vr[i])) {
            log_error(inst, "%s: variable %s (value reference %u) cannot be set in state %s",
                      function, inst->model->names[vr[i]], vr[i], mode_name(inst->mode));
            return 1;
        }
    }
    return 0;
}

FmuStatus fmu_get_int(Instance *inst, const char *function, int type, const unsigned vr[], size_t nvr,
                      int value[])
{
    size_t i;
    if (get_checks(inst, function, type, vr, nvr, value)) return FMU_ERROR;
    for (i = 0; i < nvr; i++) value[i] = (int)inst->vars[vr[i]];
    return FMU_OK;
}

FmuStatus fmu_set_int(Instance *inst, const char *function, int type, const unsigned vr[], size_t nvr,
                      const int value[])
{
    size_t i;
    if (set_checks(inst, function, type, vr, nvr, value)) return FMU_ERROR;
    for (i = 0; i < nvr; i++)
        store(inst, vr[i], type == VARTYPE_BOOLEAN ? (value[i] != 0 ? 1.0 : 0.0) : (double)value[i]);
    return FMU_OK;
}

FmuStatus fmu_get_bool8(Instance *inst, const char *function, const unsigned vr[], size_t nvr,
                        unsigned char value[])
{
    size_t i;
    if (get_checks(inst, function, VARTYPE_BOOLEAN, vr, nvr, value)) return FMU_ERROR;
    for (i = 0; i < nvr; i++) value[i] = inst->vars[vr[i]] != 0.0 ? 1u : 0u;
    return FMU_OK;
}

FmuStatus fmu_set_bool8(Instance *inst, const char *function, const unsigned vr[], size_t nvr,
                        const unsigned char value[])
{
    size_t i;
    if (set_checks(inst, function, VARTYPE_BOOLEAN, vr, nvr, value)) return FMU_ERROR;
    for (i = 0; i < nvr; i++) store(inst, vr[i], value[i] != 0 ? 1.0 : 0.0);
    return FMU_OK;
}

FmuStatus fmu_no_variables(Instance *inst, const char *function, const unsigned vr[], size_t nvr)
{
    if (fmu_null_arg(inst, function, "valueReferences", vr, nvr)) return FMU_ERROR;
    if (nvr > 0) {
        log_error(inst, "%s: unknown value reference %u (this FMU has no variable of this type)",
                  function, vr[0]);
        return FMU_ERROR;
    }
    return FMU_OK;
}

FmuStatus fmu_set_time(Instance *inst, const char *function, double time)
{
    if (!isfinite(time)) {
        log_error(inst, "%s: time %g is not finite", function, time);
        return FMU_ERROR;
    }
    if (time != inst->time) inst->dirty = 1;
    inst->time = time;
    return FMU_OK;
}

static int check_nx(Instance *inst, const char *function, size_t nx)
{
    if (nx != inst->model->n_states) {
        log_error(inst, "%s: expected %lu continuous states, got %lu", function,
                  (unsigned long)inst->model->n_states, (unsigned long)nx);
        return 1;
    }
    return 0;
}

FmuStatus fmu_set_states(Instance *inst, const char *function, const double x[], size_t nx)
{
    size_t i;
    if (check_nx(inst, function, nx) || fmu_null_arg(inst, function, "continuousStates", x, nx))
        return FMU_ERROR;
    for (i = 0; i < nx; i++) {
        if (!isfinite(x[i])) {
            log_error(inst, "%s: state %s = %g is not finite; rejected", function,
                      inst->model->names[inst->model->state_vr[i]], x[i]);
            return FMU_ERROR;
        }
    }
    for (i = 0; i < nx; i++) inst->vars[inst->model->state_vr[i]] = x[i];
    inst->dirty = 1;
    return FMU_OK;
}

FmuStatus fmu_get_states(Instance *inst, const char *function, double x[], size_t nx)
{
    size_t i;
    if (check_nx(inst, function, nx) || fmu_null_arg(inst, function, "continuousStates", x, nx))
        return FMU_ERROR;
    for (i = 0; i < nx; i++) x[i] = inst->vars[inst->model->state_vr[i]];
    return FMU_OK;
}

FmuStatus fmu_get_derivatives(Instance *inst, const char *function, double dx[], size_t nx)
{
    size_t i;
    if (check_nx(inst, function, nx) || fmu_null_arg(inst, function, "derivatives", dx, nx))
        return FMU_ERROR;
    if (evaluate(inst, function) != 0) {
        inst->mode = MODE_ERROR;
        return FMU_ERROR;
    }
    for (i = 0; i < nx; i++) dx[i] = inst->vars[inst->model->derivative_vr[i]];
    return FMU_OK;
}

FmuStatus fmu_get_nominals(Instance *inst, const char *function, double nominals[], size_t nx)
{
    size_t i;
    if (check_nx(inst, function, nx) || fmu_null_arg(inst, function, "nominals", nominals, nx))
        return FMU_ERROR;
    for (i = 0; i < nx; i++) nominals[i] = 1.0;
    return FMU_OK;
}

/* ------------------------------------------------------------------ integrator */

/* Derivatives at (t, y) into dy; nonzero on failure (logged). */
static int rhs(Instance *inst, double t, const double *y, double *dy)
{
    const ModelInfo *m = inst->model;
    size_t i;
    for (i = 0; i < m->n_states; i++) inst->vars[m->state_vr[i]] = y[i];
    inst->time = t;
    inst->dirty = 1;
    if (evaluate(inst, "fmiDoStep") != 0) return 1;
    for (i = 0; i < m->n_states; i++) dy[i] = inst->vars[m->derivative_vr[i]];
    return 0;
}

/* Weighted RMS norm with the error scale of the integrator: the local error of a step may
 * be a tenth of the tolerance, relative to the largest magnitude each state has had. */
static double wrms(const Instance *inst, const double *v, const double *y0, const double *y1)
{
    size_t i, n = inst->model->n_states;
    double sum = 0.0, tol = 0.1 * inst->tolerance;
    for (i = 0; i < n; i++) {
        double s = fmax(fmax(fabs(y0[i]), y1 ? fabs(y1[i]) : 0.0), inst->yscale[i]);
        double sc = tol * s + 1e-6 * tol;
        double r = v[i] / sc;
        sum += r * r;
    }
    return n ? sqrt(sum / (double)n) : 0.0;
}

/* Dormand-Prince 5(4) with FSAL and step-size control, inputs held, from t0 to t1. */
static int integrate(Instance *inst, double t0, double t1)
{
    static const double c2 = 1.0 / 5, c3 = 3.0 / 10, c4 = 4.0 / 5, c5 = 8.0 / 9;
    static const double a21 = 1.0 / 5;
    static const double a31 = 3.0 / 40, a32 = 9.0 / 40;
    static const double a41 = 44.0 / 45, a42 = -56.0 / 15, a43 = 32.0 / 9;
    static const double a51 = 19372.0 / 6561, a52 = -25360.0 / 2187, a53 = 64448.0 / 6561,
                        a54 = -212.0 / 729;
    static const double a61 = 9017.0 / 3168, a62 = -355.0 / 33, a63 = 46732.0 / 5247,
                        a64 = 49.0 / 176, a65 = -5103.0 / 18656;
    static const double a71 = 35.0 / 384, a73 = 500.0 / 1113, a74 = 125.0 / 192,
                        a75 = -2187.0 / 6784, a76 = 11.0 / 84;
    static const double e1 = 71.0 / 57600, e3 = -71.0 / 16695, e4 = 71.0 / 1920,
                        e5 = -17253.0 / 339200, e6 = 22.0 / 525, e7 = -1.0 / 40;
    const ModelInfo *m = inst->model;
    size_t i, n = m->n_states;
    double t = t0, h, h_prop, err;
    double *y = inst->y, *y1 = inst->y1, *yt = inst->ytmp, *ev = inst->err, **k = inst->k;
    unsigned long steps = 0;
    int last;

    for (i = 0; i < n; i++) y[i] = inst->vars[m->state_vr[i]];
    if (n == 0) { /* algebraic model: nothing to integrate */
        inst->time = t1;
        inst->dirty = 1;
        return evaluate(inst, "fmiDoStep");
    }
    if (rhs(inst, t, y, k[0])) return 1;
    h_prop = inst->h_next;
    if (!(h_prop > 0.0)) { /* Hairer's starting step */
        double d0 = wrms(inst, y, y, NULL), d1 = wrms(inst, k[0], y, NULL), d2, h0, h1;
        h0 = (d0 < 1e-5 || d1 < 1e-5) ? 1e-6 : 0.01 * d0 / d1;
        h0 = fmin(h0, t1 - t0);
        for (i = 0; i < n; i++) yt[i] = y[i] + h0 * k[0][i];
        if (rhs(inst, t + h0, yt, k[1])) return 1;
        for (i = 0; i < n; i++) ev[i] = (k[1][i] - k[0][i]) / h0;
        d2 = wrms(inst, ev, y, NULL);
        h1 = fmax(d1, d2) <= 1e-15 ? fmax(1e-6, h0 * 1e-3) : pow(0.01 / fmax(d1, d2), 0.2);
        h_prop = fmin(100.0 * h0, h1);
    }
    for (;;) {
        h = h_prop;
        last = 0;
        if (t + h >= t1 - 1e-13 * fmax(1.0, fabs(t1))) {
            h = t1 - t;
            last = 1;
        }
        for (i = 0; i < n; i++) yt[i] = y[i] + h * a21 * k[0][i];
        if (rhs(inst, t + c2 * h, yt, k[1])) return 1;
        for (i = 0; i < n; i++) yt[i] = y[i] + h * (a31 * k[0][i] + a32 * k[1][i]);
        if (rhs(inst, t + c3 * h, yt, k[2])) return 1;
        for (i = 0; i < n; i++) yt[i] = y[i] + h * (a41 * k[0][i] + a42 * k[1][i] + a43 * k[2][i]);
        if (rhs(inst, t + c4 * h, yt, k[3])) return 1;
        for (i = 0; i < n; i++)
            yt[i] = y[i] + h * (a51 * k[0][i] + a52 * k[1][i] + a53 * k[2][i] + a54 * k[3][i]);
        if (rhs(inst, t + c5 * h, yt, k[4])) return 1;
        for (i = 0; i < n; i++)
            yt[i] = y[i] + h * (a61 * k[0][i] + a62 * k[1][i] + a63 * k[2][i] + a64 * k[3][i] +
                                a65 * k[4][i]);
        if (rhs(inst, t + h, yt, k[5])) return 1;
        for (i = 0; i < n; i++)
            y1[i] = y[i] + h * (a71 * k[0][i] + a73 * k[2][i] + a74 * k[3][i] + a75 * k[4][i] +
                                a76 * k[5][i]);
        if (rhs(inst, t + h, y1, k[6])) return 1;
        for (i = 0; i < n; i++)
            ev[i] = h * (e1 * k[0][i] + e3 * k[2][i] + e4 * k[3][i] + e5 * k[4][i] + e6 * k[5][i] +
                         e7 * k[6][i]);
        err = wrms(inst, ev, y, y1);
        if (!isfinite(err)) err = 1e10;
        if (err <= 1.0) { /* accept */
            double *swap = k[0];
            k[0] = k[6];
            k[6] = swap;
            for (i = 0; i < n; i++) {
                y[i] = y1[i];
                if (fabs(y[i]) > inst->yscale[i]) inst->yscale[i] = fabs(y[i]);
            }
            t = last ? t1 : t + h;
            inst->n_steps++;
            if (!last || h >= h_prop) /* a clamped last step says nothing about the next */
                h_prop = h * (err == 0.0 ? 5.0 : fmin(5.0, fmax(0.2, 0.9 * pow(err, -0.2))));
            if (last) break;
        } else {
            inst->n_rejected++;
            h_prop = h * fmax(0.2, 0.9 * pow(err, -0.2));
        }
        if (h_prop < 1e-14 * fmax(1.0, fabs(t))) {
            log_error(inst, "fmiDoStep: step size %g too small at t = %.17g", h_prop, t);
            return 1;
        }
        if (++steps > MAX_STEPS_PER_CALL) {
            log_error(inst, "fmiDoStep: more than %lu integration steps in one communication step "
                      "(stiff model?) at t = %.17g", MAX_STEPS_PER_CALL, t);
            return 1;
        }
    }
    inst->h_next = h_prop;
    for (i = 0; i < n; i++) inst->vars[m->state_vr[i]] = y[i];
    inst->time = t1;
    inst->dirty = 1;
    return evaluate(inst, "fmiDoStep");
}

FmuStatus fmu_do_step(Instance *inst, const char *function, double current_time, double h)
{
    const ModelInfo *m = inst->model;
    int rc;
    if (!isfinite(h) || !(h > 0.0)) {
        log_error(inst, "%s: communicationStepSize must be positive and finite, got %g", function, h);
        return FMU_ERROR;
    }
    if (!isfinite(current_time) ||
        fabs(current_time - inst->time) > 1e-10 * fmax(1.0, fabs(inst->time))) {
        log_error(inst, "%s: currentCommunicationPoint %.17g does not match the FMU's time %.17g",
                  function, current_time, inst->time);
        return FMU_ERROR;
    }
    if (inst->stop_time_defined && current_time + h > inst->stop_time * (1.0 + 1e-12) + 1e-12) {
        log_error(inst, "%s: step to %.17g goes past stopTime %.17g", function, current_time + h,
                  inst->stop_time);
        return FMU_ERROR;
    }
    memcpy(inst->saved, inst->vars, m->n_vars * sizeof(double));
    inst->time = current_time;
    inst->terminate_requested = 0;
    if (m->do_step != NULL) {
        rc = m->do_step(inst, current_time, h);
        if (rc == 0 && inst->terminate_requested) {
            /* the time reached, within the step; within rounding of its end: the end */
            double reached = inst->terminate_time, tol = 1e-9 * h;
            if (!(reached >= current_time - tol && reached <= current_time + h + tol)) {
                log_error(inst, "%s: the model asked to end the simulation at t = %.17g, outside the step from "
                          "%.17g to %.17g", function, reached, current_time, current_time + h);
                rc = 1;
            } else {
                inst->terminate_time = reached >= current_time + h - tol ? current_time + h
                                                                           : fmax(reached, current_time);
            }
        }
        if (rc == 0) {
            inst->time = inst->terminate_requested ? inst->terminate_time : current_time + h;
            inst->dirty = 1;
            rc = evaluate(inst, function);
        }
    } else {
        rc = integrate(inst, current_time, current_time + h);
    }
    if (rc != 0) { /* back to the last successful time */
        memcpy(inst->vars, inst->saved, m->n_vars * sizeof(double));
        inst->time = current_time;
        inst->dirty = 1;
        inst->h_next = 0.0;
        inst->terminate_requested = 0;
        inst->mode = MODE_STEP_FAILED;
        fmu_log(inst, FMU_DISCARD, "logStatusDiscard", "%s: step from t = %.17g discarded", function,
                current_time);
        return FMU_DISCARD;
    }
    if (inst->terminate_requested) { /* the variables are those of the time reached */
        inst->h_next = 0.0;
        inst->mode = MODE_STEP_FAILED;
        fmu_log(inst, FMU_OK, "logAll", "%s: the model asks to end the simulation at t = %.17g", function,
                inst->time);
        return FMU_OK;
    }
    inst->time = current_time + h;
    return FMU_OK;
}

void fmu_request_termination(Instance *inst, double reached)
{
    inst->terminate_requested = 1;
    inst->terminate_time = reached;
}

/* ------------------------------------------------------------------ FMU state */

/* A snapshot (and its serialized form: the same bytes) is checked in full before it is used:
 * the header (magic, kind, counts, sizes), a checksum over every byte after it, the FMU's
 * identity (model identifier, instantiation token and SNAPSHOT_FORMAT), the glue's own fields
 * (mode, times, tolerance, the variables' types and finiteness) and the model's invariants
 * (ModelInfo.check_state). A snapshot that fails is refused with an error message and the
 * instance is left as it was. Layout: see SNAPSHOT_CHECKSUM_OFFSET in fmu_instance.h. */
typedef struct Snapshot {
    unsigned magic;
    unsigned kind;
    unsigned long long checksum;   /* fmu_state_checksum of the bytes after this field */
    unsigned long long identity;   /* fmu_state_checksum of identifier, token and format */
    unsigned long long n_vars, n_states, size, model_bytes;
    int mode, stop_time_defined;
    double time, start_time, stop_time, tolerance, h_next;
    double data[1]; /* n_vars values, n_states error scales, then model_bytes of model data */
} Snapshot;

typedef char snapshot_layout_check[(offsetof(Snapshot, checksum) == SNAPSHOT_CHECKSUM_OFFSET &&
                                    offsetof(Snapshot, identity) == SNAPSHOT_CHECKSUM_OFFSET + 8) ? 1 : -1];

unsigned long long fmu_state_checksum(unsigned long long hash, const void *bytes, size_t size)
{
    const unsigned char *p = (const unsigned char *)bytes;
    size_t i;
    for (i = 0; i < size; i++) {
        hash ^= p[i];
        hash *= 1099511628211ULL; /* FNV-1a, 64 bits */
    }
    return hash;
}

static unsigned long long identity_of(const ModelInfo *m)
{
    unsigned long long h = FMU_STATE_CHECKSUM_SEED;
    h = fmu_state_checksum(h, m->model_identifier, strlen(m->model_identifier) + 1);
    h = fmu_state_checksum(h, m->instantiation_token, strlen(m->instantiation_token) + 1);
    return fmu_state_checksum(h, SNAPSHOT_FORMAT, sizeof SNAPSHOT_FORMAT);
}

static unsigned long long checksum_of(const Snapshot *s)
{
    const char *from = (const char *)s + SNAPSHOT_CHECKSUM_OFFSET + 8;
    return fmu_state_checksum(FMU_STATE_CHECKSUM_SEED, from, (size_t)s->size - (SNAPSHOT_CHECKSUM_OFFSET + 8));
}

static size_t snapshot_size(const ModelInfo *m, unsigned long long model_bytes)
{
    return sizeof(Snapshot) + (m->n_vars + m->n_states) * sizeof(double) + (size_t)model_bytes;
}

static size_t model_state_size(const Instance *inst)
{
    return inst->model->state_size != NULL ? inst->model->state_size(inst) : 0;
}

/* The header: magic, kind and sizes (enough to know how many bytes the snapshot has). */
static int snapshot_valid(Instance *inst, const char *function, const Snapshot *s, size_t size)
{
    const ModelInfo *m = inst->model;
    if (s == NULL || size < sizeof(Snapshot) || s->magic != SNAPSHOT_MAGIC || s->n_vars != m->n_vars ||
        s->n_states != m->n_states || s->model_bytes > (unsigned long long)size ||
        s->size != snapshot_size(m, s->model_bytes) || size < s->size || s->kind != (unsigned)inst->kind ||
        (m->state_size == NULL && s->model_bytes != 0)) {
        log_error(inst, "%s: not an FMU state of this FMU (header)", function);
        return 0;
    }
    return 1;
}

static int is_single_mode(int mode)
{
    return mode > 0 && mode <= MODE_ERROR && (mode & (mode - 1)) == 0;
}

/* The modes an instance of this kind passes through (Error excluded: not restorable). */
static int modes_of_kind(InterfaceKind kind)
{
    return kind == KIND_CO_SIMULATION
               ? MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP | MODE_STEP_FAILED | MODE_TERMINATED
               : MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS_TIME | MODE_TERMINATED;
}

/* Everything: header, checksum, identity, the glue's fields and the model's invariants. */
static int snapshot_usable(Instance *inst, const char *function, const Snapshot *s, size_t size)
{
    const ModelInfo *m = inst->model;
    const double *vars = s->data, *scales = s->data + m->n_vars;
    char reason[256];
    size_t i;
    if (!snapshot_valid(inst, function, s, size)) return 0;
    if (s->checksum != checksum_of(s)) {
        log_error(inst, "%s: the FMU state is corrupted (checksum mismatch); rejected", function);
        return 0;
    }
    if (s->identity != identity_of(m)) {
        log_error(inst, "%s: the FMU state was saved by another FMU or build (not %s, token %s, format %s); "
                  "rejected", function, m->model_identifier, m->instantiation_token, SNAPSHOT_FORMAT);
        return 0;
    }
    reason[0] = '\0';
    if (!is_single_mode(s->mode) || !(s->mode & modes_of_kind(inst->kind)))
        snprintf(reason, sizeof reason, "mode %d is not a state of the FMI state machine of this instance", s->mode);
    else if ((s->stop_time_defined != 0 && s->stop_time_defined != 1) || !isfinite(s->time) ||
             !isfinite(s->start_time) || (s->stop_time_defined && !(isfinite(s->stop_time) &&
                                                                     s->stop_time >= s->start_time)) ||
             !(s->tolerance > 0.0 && isfinite(s->tolerance)) || !(s->h_next >= 0.0 && isfinite(s->h_next)))
        snprintf(reason, sizeof reason, "time, stop time, tolerance or step size out of range");
    /* the variables: whole numbers and 0/1 where typed so, and finite wherever evaluation
     * requires it (the rule of first_non_finite) */
    for (i = 0; reason[0] == '\0' && i < m->n_vars; i++) {
        int type = m->types != NULL ? m->types[i] : VARTYPE_FLOAT64;
        double v = vars[i];
        int may_be_nan = may_be_non_finite(m, i) ||
                         (m->non_finite_outputs && m->causality[i] == CAUSALITY_OUTPUT && type == VARTYPE_FLOAT64);
        if ((type == VARTYPE_INTEGER && !(v == floor(v) && fabs(v) <= 2147483647.0)) ||
            (type == VARTYPE_BOOLEAN && v != 0.0 && v != 1.0) || (!isfinite(v) && !may_be_nan))
            snprintf(reason, sizeof reason, "variable %s = %g is not a valid value", m->names[i], v);
    }
    for (i = 0; reason[0] == '\0' && i < m->n_states; i++)
        if (!(scales[i] >= 0.0 && isfinite(scales[i])))
            snprintf(reason, sizeof reason, "error scale %g of state %s is not valid", scales[i],
                     m->names[m->state_vr[i]]);
    if (reason[0] == '\0' && m->check_state != NULL) {
        Instance view = *inst; /* the instance as the state would leave it (model data aside) */
        view.vars = (double *)vars;
        view.mode = (Mode)s->mode;
        view.time = s->time;
        view.start_time = s->start_time;
        view.stop_time = s->stop_time;
        view.stop_time_defined = s->stop_time_defined;
        view.tolerance = s->tolerance;
        view.h_next = s->h_next;
        if (m->check_state(&view, (const void *)(scales + m->n_states), (size_t)s->model_bytes, reason,
                           sizeof reason) != 0 && reason[0] == '\0')
            snprintf(reason, sizeof reason, "the model data is not valid");
    }
    if (reason[0] != '\0') {
        log_error(inst, "%s: the FMU state is inconsistent (%s); rejected", function, reason);
        return 0;
    }
    return 1;
}

/* Nonzero (logged) when the model cannot save its state (ModelInfo.no_fmu_state). */
static int state_refused(Instance *inst, const char *function)
{
    if (!inst->model->no_fmu_state) return 0;
    log_error(inst, "%s: this FMU cannot save or restore its state (canGetAndSetFMUstate=false)", function);
    return 1;
}

FmuStatus fmu_get_state(Instance *inst, const char *function, void **state)
{
    const ModelInfo *m = inst->model;
    Snapshot *s;
    size_t model_bytes;
    if (state_refused(inst, function)) return FMU_ERROR;
    model_bytes = model_state_size(inst);
    if (fmu_null_arg(inst, function, "FMUState", state, 1)) return FMU_ERROR;
    if (*state != NULL) {
        s = (Snapshot *)*state;
        if (!snapshot_valid(inst, function, s, s->size)) return FMU_ERROR;
        if (s->model_bytes != model_bytes) { /* model data changed size: a new snapshot */
            free(s);
            *state = NULL;
        }
    }
    if (*state == NULL) {
        s = (Snapshot *)calloc(1, snapshot_size(m, model_bytes));
        if (s == NULL) {
            log_error(inst, "%s: out of memory", function);
            return FMU_ERROR;
        }
    }
    s->magic = SNAPSHOT_MAGIC;
    s->kind = (unsigned)inst->kind;
    s->identity = identity_of(m);
    s->n_vars = m->n_vars;
    s->n_states = m->n_states;
    s->model_bytes = model_bytes;
    s->size = snapshot_size(m, model_bytes);
    s->mode = (int)inst->mode;
    s->stop_time_defined = inst->stop_time_defined;
    s->time = inst->time;
    s->start_time = inst->start_time;
    s->stop_time = inst->stop_time;
    s->tolerance = inst->tolerance;
    s->h_next = inst->h_next;
    memcpy(s->data, inst->vars, m->n_vars * sizeof(double));
    memcpy(s->data + m->n_vars, inst->yscale, m->n_states * sizeof(double));
    if (model_bytes > 0) m->save_state(inst, (void *)(s->data + m->n_vars + m->n_states));
    s->checksum = checksum_of(s);
    *state = s;
    return FMU_OK;
}

FmuStatus fmu_set_state(Instance *inst, const char *function, const void *state)
{
    const ModelInfo *m = inst->model;
    const Snapshot *s = (const Snapshot *)state;
    if (state_refused(inst, function)) return FMU_ERROR;
    if (fmu_null_arg(inst, function, "FMUState", state, 1)) return FMU_ERROR;
    if (!snapshot_usable(inst, function, s, (size_t)s->size)) return FMU_ERROR;
    if (m->load_state != NULL &&
        m->load_state(inst, (const void *)(s->data + m->n_vars + m->n_states), (size_t)s->model_bytes) != 0) {
        log_error(inst, "%s: the model data of the FMU state could not be restored", function);
        return FMU_ERROR;
    }
    inst->mode = (Mode)s->mode;
    inst->stop_time_defined = s->stop_time_defined;
    inst->time = s->time;
    inst->start_time = s->start_time;
    inst->stop_time = s->stop_time;
    inst->tolerance = s->tolerance;
    inst->h_next = s->h_next;
    inst->terminate_requested = 0; /* not part of the state: a restored state asks nothing */
    memcpy(inst->vars, s->data, m->n_vars * sizeof(double));
    memcpy(inst->yscale, s->data + m->n_vars, m->n_states * sizeof(double));
    inst->dirty = 1;
    return FMU_OK;
}

FmuStatus fmu_free_state(Instance *inst, const char *function, void **state)
{
    (void)inst;
    (void)function;
    if (state == NULL || *state == NULL) return FMU_OK;
    free(*state);
    *state = NULL;
    return FMU_OK;
}

FmuStatus fmu_serialized_size(Instance *inst, const char *function, const void *state, size_t *size)
{
    if (state_refused(inst, function)) return FMU_ERROR;
    if (fmu_null_arg(inst, function, "FMUState", state, 1) ||
        fmu_null_arg(inst, function, "size", size, 1))
        return FMU_ERROR;
    if (!snapshot_valid(inst, function, (const Snapshot *)state, ((const Snapshot *)state)->size))
        return FMU_ERROR;
    *size = (size_t)((const Snapshot *)state)->size;
    return FMU_OK;
}

FmuStatus fmu_serialize(Instance *inst, const char *function, const void *state, char *bytes,
                        size_t size)
{
    const Snapshot *s = (const Snapshot *)state;
    if (state_refused(inst, function)) return FMU_ERROR;
    if (fmu_null_arg(inst, function, "FMUState", state, 1) ||
        fmu_null_arg(inst, function, "serializedState", bytes, 1))
        return FMU_ERROR;
    if (!snapshot_valid(inst, function, s, s->size)) return FMU_ERROR;
    if (size < s->size) {
        log_error(inst, "%s: buffer of %lu bytes is too small (%llu needed)", function,
                  (unsigned long)size, s->size);
        return FMU_ERROR;
    }
    memcpy(bytes, s, (size_t)s->size);
    return FMU_OK;
}

FmuStatus fmu_deserialize(Instance *inst, const char *function, const char *bytes, size_t size,
                          void **state)
{
    Snapshot header;
    void *copy;
    if (state_refused(inst, function)) return FMU_ERROR;
    if (fmu_null_arg(inst, function, "serializedState", bytes, 1) ||
        fmu_null_arg(inst, function, "FMUState", state, 1))
        return FMU_ERROR;
    if (size < sizeof(Snapshot)) {
        log_error(inst, "%s: not an FMU state of this FMU (%lu bytes)", function, (unsigned long)size);
        return FMU_ERROR;
    }
    memcpy(&header, bytes, sizeof header);
    if (!snapshot_valid(inst, function, &header, size)) return FMU_ERROR;
    copy = malloc((size_t)header.size); /* aligned for the checks of the model data */
    if (copy == NULL) {
        log_error(inst, "%s: out of memory", function);
        return FMU_ERROR;
    }
    memcpy(copy, bytes, (size_t)header.size);
    if (!snapshot_usable(inst, function, (const Snapshot *)copy, (size_t)header.size)) {
        free(copy);
        return FMU_ERROR;
    }
    if (*state != NULL) free(*state);
    *state = copy;
    return FMU_OK;
}
