/* duffid's adaptive controller as a discrete-time co-simulation model of the shared FMI
 * glue (fmus/common): AdaptiveController1 (1 DOF) and AdaptiveController2 (2 DOF),
 * FMI 2.0 and 3.0.
 *
 * The variable table and the value references of its groups come from the generated
 * header controller_fmu_config.h (duffid.control.controller_fmu): CONTROLLER_DOFS, CONTROLLER_VR_*.
 *
 * Semantics: the outputs at initialisation are the controller's start (the force over
 * [t0, t0 + h)); each doStep(t, h) consumes the inputs set for t and gives the outputs at
 * t + h (the force over [t + h, t + 2h)). h must equal the parameter sample_period
 * (otherwise Discard, logged). The estimate inputs may be NaN (the glue's non_finite
 * flag); every other input is rejected when not finite. The controller is a plain struct
 * (duffid_ctrl): the FMU state holds a byte copy of it.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "duffid_controller.h"
#include "fmu_instance.h"
#include "fmu_model.h"
#include "controller_fmu_config.h"

#define N_DOF CONTROLLER_DOFS
#define N_PARAMS (N_DOF == 1 ? 4 : 8)

/* Model data (Instance.model_data); no pointers, so the FMU state is a byte copy. */
typedef struct CtrlData {
    int started;            /* the first doStep latched the parameters */
    duffid_ctrl ctrl;
    duffid_ctrl_output out; /* outputs at the instance's time */
} CtrlData;

static CtrlData *data_of(Instance *inst)
{
    if (inst->model_data == NULL) inst->model_data = calloc(1, sizeof(CtrlData));
    return (CtrlData *)inst->model_data;
}

static void make_config(const Instance *inst, duffid_ctrl_config *cfg)
{
    const double *v = inst->vars;
    int i;
    memset(cfg, 0, sizeof *cfg);
    cfg->dofs = N_DOF;
    /* every scalar parameter of the table (duffid_ctrl_params.h), then the nominal values */
#define CTRL_READ_REAL(field, NAME) cfg->field = v[CONTROLLER_VR_##NAME];
#define CTRL_READ_INT(field, NAME) cfg->field = (int)v[CONTROLLER_VR_##NAME];
#define CTRL_READ_BOOL(field, NAME) cfg->field = v[CONTROLLER_VR_##NAME] != 0.0;
#define CTRL_READ(kind, field, NAME, name, rule, lo, hi, text) CTRL_READ_##kind(field, NAME)
    DUFFID_CTRL_PARAMETERS(CTRL_READ)
#undef CTRL_READ
#undef CTRL_READ_BOOL
#undef CTRL_READ_INT
#undef CTRL_READ_REAL
    for (i = 0; i < N_PARAMS; i++) cfg->nominal[i] = v[CONTROLLER_VR_NOMINAL + i];
}

/* (Re)starts the controller from the parameters at the start time; nonzero (logged) on
 * an invalid configuration. */
static int start(Instance *inst, CtrlData *d)
{
    duffid_ctrl_config cfg;
    char msg[256];
    make_config(inst, &cfg);
    if (duffid_ctrl_init(&d->ctrl, &cfg, inst->start_time, &d->out, msg, sizeof msg) != DUFFID_CTRL_OK) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "invalid controller parameters: %s", msg);
        return 1;
    }
    return 0;
}

static int evaluate(Instance *inst)
{
    CtrlData *d = data_of(inst);
    double *v = inst->vars;
    int i;
    if (d == NULL) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "out of memory");
        return 1;
    }
    if (!d->started && start(inst, d) != 0) return 1; /* parameters may still change */
    v[CONTROLLER_VR_F] = d->out.f;
    v[CONTROLLER_VR_F_SAMPLE] = d->out.f_sample;
    v[CONTROLLER_VR_PHASE] = (double)d->out.phase;
    v[CONTROLLER_VR_X_REF] = d->out.x_ref;
    for (i = 0; i < N_DOF; i++) v[CONTROLLER_VR_V_HAT + i] = d->out.v_hat[i];
    v[CONTROLLER_VR_SATURATED] = d->out.saturated ? 1.0 : 0.0;
    v[CONTROLLER_VR_SWITCH_TIME] = d->out.switch_time;
    for (i = 0; i < N_PARAMS; i++) v[CONTROLLER_VR_USED + i] = d->out.used[i];
    return 0;
}

static int do_step(Instance *inst, double t, double h)
{
    CtrlData *d = data_of(inst);
    duffid_ctrl_input in;
    duffid_ctrl_output out;
    int i, rc;
    if (d == NULL) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "out of memory");
        return 1;
    }
    if (!d->started) {
        if (start(inst, d) != 0) return 1;
        d->started = 1;
    }
    memset(&in, 0, sizeof in);
    in.r = inst->vars[CONTROLLER_VR_R];
    in.r_dot = inst->vars[CONTROLLER_VR_R_DOT];
    in.r_ddot = inst->vars[CONTROLLER_VR_R_DDOT];
    for (i = 0; i < N_DOF; i++) in.x[i] = inst->vars[CONTROLLER_VR_X + i];
    for (i = 0; i < N_PARAMS; i++) in.estimate[i] = inst->vars[CONTROLLER_VR_EST + i];
    in.identified = inst->vars[CONTROLLER_VR_IDENTIFIED] != 0.0;
    rc = duffid_ctrl_step(&d->ctrl, t, h, &in, &out);
    if (rc == DUFFID_CTRL_ERR_STEP) {
        fmu_log(inst, FMU_ERROR, "logStatusError",
                "communicationStepSize %.17g at t = %.17g differs from the parameter sample_period %.17g", h, t,
                d->ctrl.cfg.sample_period);
        return 1;
    }
    if (rc == DUFFID_CTRL_ERR_NUMERIC) {
        fmu_log(inst, FMU_ERROR, "logStatusError",
                "the controller diverged at t = %.17g (its force or observer would not be finite); step refused", t);
        return 1;
    }
    if (rc != DUFFID_CTRL_OK) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "the controller rejected the inputs at t = %.17g (code %d)",
                t, rc);
        return 1;
    }
    d->out = out;
    return 0;
}

static void free_data(Instance *inst)
{
    free(inst->model_data);
    inst->model_data = NULL;
}

static size_t state_size(const Instance *inst)
{
    (void)inst;
    return sizeof(CtrlData);
}

static void save_state(const Instance *inst, void *bytes)
{
    if (inst->model_data != NULL)
        memcpy(bytes, inst->model_data, sizeof(CtrlData));
    else
        memset(bytes, 0, sizeof(CtrlData));
}

static int same_bits(double a, double b)
{
    return memcmp(&a, &b, sizeof a) == 0;
}

/* Nonzero when two configurations are equal, field by field (bits of the doubles). */
static int same_config(const duffid_ctrl_config *a, const duffid_ctrl_config *b)
{
    int i, same = a->dofs == b->dofs;
#define CTRL_SAME_REAL(field) same = same && same_bits(a->field, b->field);
#define CTRL_SAME_INT(field) same = same && a->field == b->field;
#define CTRL_SAME_BOOL(field) same = same && a->field == b->field;
#define CTRL_SAME(kind, field, NAME, name, rule, lo, hi, text) CTRL_SAME_##kind(field)
    DUFFID_CTRL_PARAMETERS(CTRL_SAME)
#undef CTRL_SAME
#undef CTRL_SAME_BOOL
#undef CTRL_SAME_INT
#undef CTRL_SAME_REAL
    for (i = 0; i < DUFFID_CTRL_MAX_PARAMS; i++) same = same && same_bits(a->nominal[i], b->nominal[i]);
    return same;
}

/* Nonzero when two output sets are equal (bits of the doubles). */
static int same_outputs(const duffid_ctrl_output *a, const duffid_ctrl_output *b)
{
    int i, same = same_bits(a->f, b->f) && same_bits(a->f_sample, b->f_sample) && a->phase == b->phase &&
                  same_bits(a->x_ref, b->x_ref) && same_bits(a->v_hat[0], b->v_hat[0]) &&
                  same_bits(a->v_hat[1], b->v_hat[1]) && a->saturated == b->saturated &&
                  same_bits(a->switch_time, b->switch_time);
    for (i = 0; i < DUFFID_CTRL_MAX_PARAMS; i++) same = same && same_bits(a->used[i], b->used[i]);
    return same;
}

/* Every invariant of the model data of an FMU state: nothing when the controller is not yet
 * started (the next evaluation starts it from the parameters); else a started controller of
 * a stepping instance, configured from the state's parameters at its start time, whose fields
 * pass duffid_ctrl_check_state and whose outputs are its own. */
static int check_state(const Instance *inst, const void *bytes, size_t size, char *msg, size_t msg_size)
{
    CtrlData d;
    duffid_ctrl_config cfg;
    duffid_ctrl_output out;
    if (size != sizeof d) {
        snprintf(msg, msg_size, "model data of %lu bytes, expected %lu", (unsigned long)size,
                 (unsigned long)sizeof d);
        return 1;
    }
    memcpy(&d, bytes, sizeof d);
    if (d.started != 0 && d.started != 1) {
        snprintf(msg, msg_size, "flag started = %d", d.started);
        return 1;
    }
    if (!d.started) return 0; /* nothing restored is used: start() rebuilds it */
    if (!(inst->mode & (MODE_STEP | MODE_STEP_FAILED | MODE_TERMINATED))) {
        snprintf(msg, msg_size, "a started controller in state %s", mode_name(inst->mode));
        return 1;
    }
    if (duffid_ctrl_check_state(&d.ctrl, msg, msg_size) != DUFFID_CTRL_OK) return 1;
    make_config(inst, &cfg);
    if (!same_config(&d.ctrl.cfg, &cfg) || !same_bits(d.ctrl.t0, inst->start_time)) {
        snprintf(msg, msg_size, "the controller's configuration is not that of the state's parameters");
        return 1;
    }
    duffid_ctrl_outputs(&d.ctrl, &out);
    if (!same_outputs(&d.out, &out)) {
        snprintf(msg, msg_size, "the outputs are not those of the controller");
        return 1;
    }
    return 0;
}

static int load_state(Instance *inst, const void *bytes, size_t size)
{
    CtrlData *d;
    if (size != sizeof(CtrlData)) return 1;
    d = data_of(inst);
    if (d == NULL) return 1;
    memcpy(d, bytes, sizeof(CtrlData));
    return 0;
}

const ModelInfo fmu_model_info = {
    DUFFID_DISCRETE_MODEL_FIELDS(controller, CONTROLLER_IDENTIFIER, CONTROLLER_TOKEN, CONTROLLER_N_VARS),
    .non_finite = controller_non_finite,
};
