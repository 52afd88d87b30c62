/* A test model on the shared FMI glue (fmus/common) that asks to end the simulation: the C
 * counterpart of tests/pyfmus/Stopper.py, FMI 2 and FMI 3 (tests/stopper_fmu.py builds it).
 *
 * Discrete-time: each doStep(t, h) gives y = the time reached and s += u * (time reached - t)
 * (u held). The step that passes the parameter t_end stops at t_end (or at t when t_end is
 * already behind) and asks to end the simulation there (fmu_request_termination): a step that
 * ends exactly at t_end is completed, a step across t_end stops inside it.
 */
#include <math.h>

#include "fmu_instance.h"
#include "fmu_model.h"
#include "stopper_fmu_config.h"

enum { VR_TIME = 0, VR_U, VR_Y, VR_S, VR_T_END, VR_SAMPLE_PERIOD };

static int evaluate(Instance *inst)
{
    inst->vars[VR_TIME] = inst->time;
    return 0;
}

static int do_step(Instance *inst, double t, double h)
{
    double *v = inst->vars, t_end = v[VR_T_END], reached = t + h;
    const double tol = 1e-9 * h;
    if (reached > t_end + tol) reached = fmax(t, t_end);
    else if (reached >= t_end - tol) reached = t + h; /* this step ends at t_end: completed */
    v[VR_S] += v[VR_U] * (reached - t);
    v[VR_Y] = reached;
    if (reached >= t_end - tol) fmu_request_termination(inst, reached);
    return 0;
}

const ModelInfo fmu_model_info = {
    .model_identifier = STOPPER_IDENTIFIER,
    .instantiation_token = STOPPER_TOKEN,
    .n_vars = STOPPER_N_VARS,
    .names = stopper_names,
    .start = stopper_start,
    .causality = stopper_causality,
    .variability = stopper_variability,
    .settable_start = stopper_settable_start,
    .n_states = 0,
    .evaluate = evaluate,
    .do_step = do_step,
    .default_tolerance = 1e-8,
    .interfaces = INTERFACE_CO_SIMULATION,
    .types = stopper_types,
};
