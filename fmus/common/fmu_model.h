/* What a model provides to the shared FMI glue (fmus/common).
 *
 * A model has n_vars variables with value references 0 .. n_vars-1, stored as doubles
 * in Instance.vars: Float64, or (ModelInfo.types) Integer / Boolean holding whole
 * numbers and 0/1. The glue handles the FMI state machine, argument checks, logging,
 * FMU state snapshots and (for co-simulation) the integration of the ODE
 *     der(x) = f(t, x, inputs, parameters)
 * with an adaptive Dormand-Prince 5(4) method. A model supplies only its variable
 * table and one function that computes every dependent variable (derivatives, outputs,
 * locals, calculated parameters) from time, states, inputs and parameters.
 *
 * A discrete-time model (an estimator, say) sets do_step instead of relying on the ODE
 * integrator; it may have no continuous states.
 *
 * A model that holds other FMUs (the container, fmus/container) also sets the lifecycle
 * hooks (instantiate, enter/exit initialisation, terminate): it reads its resources folder
 * (Instance.resource_location) and forwards the FMI state machine to its components.
 */
#ifndef DUFFID_FMU_MODEL_H
#define DUFFID_FMU_MODEL_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* Causality of a variable (FMI 2 and FMI 3 meaning). */
enum {
    CAUSALITY_PARAMETER = 0,
    CAUSALITY_CALCULATED_PARAMETER = 1,
    CAUSALITY_INPUT = 2,
    CAUSALITY_OUTPUT = 3,
    CAUSALITY_LOCAL = 4,
    CAUSALITY_INDEPENDENT = 5
};

/* Type of a variable (ModelInfo.types). Every value is stored as a double in
 * Instance.vars; Integer and Boolean variables hold whole numbers and 0/1. */
enum {
    VARTYPE_FLOAT64 = 0,
    VARTYPE_INTEGER = 1, /* FMI 2 Integer, FMI 3 Int32 */
    VARTYPE_BOOLEAN = 2
};

/* Variability of a variable. */
enum {
    VARIABILITY_CONSTANT = 0,
    VARIABILITY_FIXED = 1,
    VARIABILITY_TUNABLE = 2,
    VARIABILITY_DISCRETE = 3,
    VARIABILITY_CONTINUOUS = 4
};

struct Instance;

/* Compute all dependent variables of inst->vars at inst->time; 0 on success. */
typedef int (*ModelEvaluate)(struct Instance *inst);

/* Advance a discrete-time model from inst->time to t + h (inputs held); 0 on success. A model
 * that asks to end the simulation calls fmu_request_termination(inst, reached) (fmu_instance.h)
 * with the time it reached and returns 0. */
typedef int (*ModelDoStep)(struct Instance *inst, double t, double h);

/* Optional model data beyond the Float64 variables (Instance.model_data, owned by the
 * model): released by free_data (at fmiFreeInstance and fmiReset) and part of the FMU
 * state: state_size bytes written by save_state and read back by load_state (which may
 * allocate; nonzero on failure, logged by the model). */
typedef void (*ModelFreeData)(struct Instance *inst);
typedef size_t (*ModelStateSize)(const struct Instance *inst);
typedef void (*ModelSaveState)(const struct Instance *inst, void *bytes);
typedef int (*ModelLoadState)(struct Instance *inst, const void *bytes, size_t size);
/* Checks model data of an FMU state before anything is restored: every invariant the model
 * relies on (counts, indices, buffer positions, sizes, values that must be finite, agreement
 * with the state's parameters); 0 when usable, else nonzero with the reason in msg. inst is a
 * view of the instance as the state would leave it: its vars, mode and times are the state's
 * (already checked by the glue); its model_data is the instance's current one (not the
 * state's: do not use it). load_state is called only on data that passed (and must then
 * succeed but for lack of memory, leaving the instance unchanged then). */
typedef int (*ModelCheckState)(const struct Instance *inst, const void *bytes, size_t size, char *msg,
                               size_t msg_size);
/* A lifecycle hook (ModelInfo.instantiate, enter_initialization, exit_initialization, terminate):
 * 0 on success, else nonzero after logging the reason through fmu_log. */
typedef int (*ModelHook)(struct Instance *inst);

typedef struct ModelInfo {
    const char *model_identifier;
    const char *instantiation_token;   /* guid (FMI 2) / instantiationToken (FMI 3) */
    size_t n_vars;                     /* variables, value references 0..n_vars-1 */
    const char *const *names;          /* variable names, for messages */
    const double *start;               /* start values (NaN: none) */
    const unsigned char *causality;    /* CAUSALITY_* */
    const unsigned char *variability;  /* VARIABILITY_* */
    const unsigned char *settable_start; /* 1: start value may be set before initialisation */
    size_t n_states;
    const unsigned *state_vr;          /* value references of the continuous states */
    const unsigned *derivative_vr;     /* value references of their derivatives */
    size_t n_work;                     /* doubles of scratch memory (Instance.work) */
    size_t n_iwork;                    /* long long of scratch memory (Instance.iwork) */
    ModelEvaluate evaluate;            /* required */
    ModelDoStep do_step;               /* NULL: integrate the ODE */
    double default_tolerance;          /* co-simulation tolerance without SetupExperiment */
    unsigned interfaces;               /* INTERFACE_* bits declared in modelDescription.xml */
    /* optional (zero in the plants' positional initialisers) */
    ModelFreeData free_data;           /* NULL: no model data */
    ModelStateSize state_size;         /* NULL: no model data in the FMU state */
    ModelSaveState save_state;
    ModelLoadState load_state;
    int non_finite_outputs;            /* 1: outputs may be NaN/Inf (e.g. "not yet estimated") */
    const unsigned char *types;        /* VARTYPE_* per variable; NULL: all Float64 */
    const unsigned char *non_finite;   /* per variable, 1: may be set to and hold NaN/Inf (an input
                                        * such as an estimate "not yet known"); NULL: none. Every
                                        * other input or parameter is rejected when not finite. */
    ModelCheckState check_state;       /* required when state_size is set */
    /* lifecycle hooks (NULL: none): */
    ModelHook instantiate;             /* at instantiation and reset, after the start values are set
                                        * (failure: no instance / reset fails); may set model_data */
    ModelHook enter_initialization;    /* at fmiEnterInitializationMode, the experiment set up */
    ModelHook exit_initialization;     /* at fmiExitInitializationMode, before the evaluation */
    ModelHook terminate;               /* at fmiTerminate */
    int no_fmu_state;                  /* 1: canGetAndSetFMUstate=false: get/set/serialize refused */
} ModelInfo;

/* Interfaces of ModelInfo.interfaces. */
#define INTERFACE_MODEL_EXCHANGE 1u
#define INTERFACE_CO_SIMULATION 2u

/* The fields of the ModelInfo of a discrete-time co-simulation model with model data
 * (the estimator and controller FMUs): its tables <prefix>_names, _start, _causality,
 * _variability, _settable_start and _types come from the generated config header, and
 * the model defines evaluate, do_step, free_data, state_size, save_state, load_state and
 * check_state.
 * Use as  const ModelInfo fmu_model_info = { DUFFID_DISCRETE_MODEL_FIELDS(...), ... };  */
#define DUFFID_DISCRETE_MODEL_FIELDS(prefix, identifier, token, count) \
    .model_identifier = (identifier), .instantiation_token = (token), .n_vars = (count), \
    .names = prefix##_names, .start = prefix##_start, .causality = prefix##_causality, \
    .variability = prefix##_variability, .settable_start = prefix##_settable_start, \
    .n_states = 0, .state_vr = NULL, .derivative_vr = NULL, .n_work = 0, .n_iwork = 0, \
    .evaluate = evaluate, .do_step = do_step, .default_tolerance = 1e-8, \
    .interfaces = INTERFACE_CO_SIMULATION, .free_data = free_data, .state_size = state_size, \
    .save_state = save_state, .load_state = load_state, .check_state = check_state, \
    .non_finite_outputs = 1, \
    .types = prefix##_types

/* The model compiled into this FMU (defined by the model's own source file). */
extern const ModelInfo fmu_model_info;

#ifdef __cplusplus
}
#endif

#endif
