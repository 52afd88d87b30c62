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

/* Every invariant of the model data of an FMU state: a valid configuration of this FMU's
 * size, buffer position and count within the differentiator's samples, flags 0/1. */
static int check_state(const Instance *inst, const void *bytes, size_t size, char *msg, size_t msg_size)
{
    CtrlData d;
    const duffid_ctrl *c = &d.ctrl;
    (void)inst;
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
    if (!d.started && !c->initialized) return 0; /* nothing restored is used before a restart */
    if (c->cfg.dofs != N_DOF || duffid_ctrl_check(&c->cfg, msg, msg_size) != DUFFID_CTRL_OK) {
        if (msg_size > 0 && msg[0] == '\0') snprintf(msg, msg_size, "configuration");
        return 1;
    }
    if (c->n_params != N_PARAMS || c->head < 0 || c->head >= c->cfg.differentiator_samples || c->count < 0 ||
        c->count > c->cfg.differentiator_samples || (c->have_ref != 0 && c->have_ref != 1) ||
        (c->phase != 0 && c->phase != 1) || (c->saturated != 0 && c->saturated != 1) ||
        (c->initialized != 0 && c->initialized != 1) || (d.out.phase != 0 && d.out.phase != 1) ||
        (d.out.saturated != 0 && d.out.saturated != 1)) {
        snprintf(msg, msg_size, "n_params %d, head %d, count %d of %d samples, or a flag out of range", c->n_params,
                 c->head, c->count, c->cfg.differentiator_samples);
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
