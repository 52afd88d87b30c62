/* Version-independent FMU instance: state machine, checked access to the variables,
 * evaluation, the co-simulation integrator and FMU state snapshots. The FMI 2 and FMI 3
 * API files (fmi2_functions.c, fmi3_functions.c) are thin adapters over these functions.
 */
#ifndef DUFFID_FMU_INSTANCE_H
#define DUFFID_FMU_INSTANCE_H

#include <stddef.h>

#include "fmu_model.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Status codes: the same numbers as fmi2Status and fmi3Status. */
typedef enum { FMU_OK = 0, FMU_WARNING = 1, FMU_DISCARD = 2, FMU_ERROR = 3, FMU_FATAL = 4 } FmuStatus;

/* States of the FMI state machines (a bit each, so that calls can list allowed states). */
typedef enum {
    MODE_INSTANTIATED = 1 << 0,
    MODE_INITIALIZATION = 1 << 1,
    MODE_EVENT = 1 << 2,
    MODE_CONTINUOUS_TIME = 1 << 3,
    MODE_STEP = 1 << 4,          /* co-simulation: stepComplete (FMI 2), Step Mode (FMI 3) */
    MODE_STEP_FAILED = 1 << 5,   /* co-simulation step discarded */
    MODE_TERMINATED = 1 << 6,
    MODE_ERROR = 1 << 7
} Mode;

#define MODE_ANY (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS_TIME | \
                  MODE_STEP | MODE_STEP_FAILED | MODE_TERMINATED | MODE_ERROR)

typedef enum { KIND_MODEL_EXCHANGE = 0, KIND_CO_SIMULATION = 1 } InterfaceKind;

struct Instance;
/* Forwards a message to the importer's logger (FMI version specific). */
typedef void (*LogFunction)(struct Instance *inst, FmuStatus status, const char *category,
                            const char *message);

typedef struct Instance {
    const ModelInfo *model;
    char *name;
    InterfaceKind kind;
    Mode mode;
    int logging_on;
    LogFunction log;
    void *log_env;                 /* importer's environment pointer */
    void (*log_callback)(void);    /* importer's logger function (cast to its FMI type) */
    char *resource_location;       /* copy of fmuResourceLocation (FMI 2, a URI) or resourcePath
                                    * (FMI 3, a path); NULL when the importer gave none */
    int fmi_version;               /* 2 or 3: the API that made the instance */
    double time;
    double start_time;
    double stop_time;
    int stop_time_defined;
    double tolerance;
    double *vars;                  /* all Float64 variables, indexed by value reference */
    int dirty;                     /* vars changed since the last evaluation */
    double *work;                  /* model scratch memory */
    void *model_data;              /* model-owned data (ModelInfo.free_data), NULL: none */
    long long *iwork;
    /* integrator (co-simulation) */
    double *y, *y1, *ytmp, *err, *yscale, *k[7];
    double *saved;                 /* variables at the start of a step (restored on failure) */
    double h_next;                 /* step size proposed for the next step (0: none) */
    unsigned long n_steps, n_rejected, n_evaluations;
    /* the model asked to end the simulation (fmu_request_termination) in the last doStep */
    int terminate_requested;
    double terminate_time;         /* the time it reached then */
    int early_return_allowed;      /* FMI 3: the importer's earlyReturnAllowed */
} Instance;

/* A new instance (NULL on failure, logged): resource_location (may be NULL) is copied. */
Instance *instance_new(const ModelInfo *model, const char *name, const char *token,
                       const char *resource_location, int fmi_version, InterfaceKind kind, int logging_on,
                       LogFunction log, void *log_env, void (*log_callback)(void));
void instance_free(Instance *inst);
/* Back to the state after instantiation (the model's instantiate hook runs again; on its
 * failure the instance is in Error mode). */
FmuStatus instance_reset(Instance *inst);

/* Logging: errors and discards are always forwarded, other messages only when logging_on. */
void fmu_log(Instance *inst, FmuStatus status, const char *category, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 4, 5)))
#endif
    ;

/* Checks the instance pointer and that `function` may be called in the current mode. */
FmuStatus fmu_check(Instance *inst, const char *function, int allowed_modes);
/* Logs an error when a required pointer argument is NULL (n > 0 elements). */
int fmu_null_arg(Instance *inst, const char *function, const char *argument, const void *p, size_t n);
const char *mode_name(Mode mode);

FmuStatus fmu_setup(Instance *inst, int tolerance_defined, double tolerance, double start_time,
                    int stop_time_defined, double stop_time);
/* fmiEnterInitializationMode (after fmu_setup), fmiExitInitializationMode and fmiTerminate,
 * with the model's hooks; a failing hook leaves the instance in Error mode. */
FmuStatus fmu_enter_initialization(Instance *inst);
FmuStatus fmu_exit_initialization(Instance *inst);
FmuStatus fmu_terminate(Instance *inst);
FmuStatus fmu_evaluate(Instance *inst, const char *function);

FmuStatus fmu_get_float64(Instance *inst, const char *function, const unsigned vr[], size_t nvr,
                          double value[]);
FmuStatus fmu_set_float64(Instance *inst, const char *function, const unsigned vr[], size_t nvr,
                          const double value[]);
/* Integer (FMI 2 Integer, FMI 3 Int32) and Boolean variables (type VARTYPE_INTEGER or
 * VARTYPE_BOOLEAN), as ints; Boolean values are 0/1 (any nonzero sets 1). */
FmuStatus fmu_get_int(Instance *inst, const char *function, int type, const unsigned vr[], size_t nvr,
                      int value[]);
FmuStatus fmu_set_int(Instance *inst, const char *function, int type, const unsigned vr[], size_t nvr,
                      const int value[]);
/* Booleans stored in one byte each (FMI 3 fmi3Boolean, a C99 bool). */
FmuStatus fmu_get_bool8(Instance *inst, const char *function, const unsigned vr[], size_t nvr,
                        unsigned char value[]);
FmuStatus fmu_set_bool8(Instance *inst, const char *function, const unsigned vr[], size_t nvr,
                        const unsigned char value[]);
/* Other variable types: none exist, so any reference is invalid. */
FmuStatus fmu_no_variables(Instance *inst, const char *function, const unsigned vr[], size_t nvr);

FmuStatus fmu_set_time(Instance *inst, const char *function, double time);
FmuStatus fmu_set_states(Instance *inst, const char *function, const double x[], size_t nx);
FmuStatus fmu_get_states(Instance *inst, const char *function, double x[], size_t nx);
FmuStatus fmu_get_derivatives(Instance *inst, const char *function, double dx[], size_t nx);
FmuStatus fmu_get_nominals(Instance *inst, const char *function, double nominals[], size_t nx);

/* Co-simulation step from current_time to current_time + h with inputs held. A model that asks
 * to end the simulation during the step (fmu_request_termination) makes it return FMU_OK with
 * inst->terminate_requested set, inst->time the time reached and the variables those of that
 * time; the instance is then in Step Failed, where only gets, the status functions, terminate,
 * reset and free are allowed (the FMI 2 adapter returns Discard with fmi2Terminated true, the
 * FMI 3 adapter sets terminateSimulation and lastSuccessfulTime, and earlyReturn when the step
 * was not completed and the importer allowed early returns). */
FmuStatus fmu_do_step(Instance *inst, const char *function, double current_time, double h);
/* For a model's do_step(inst, t, h): ask to end the simulation at time `reached` (t <= reached
 * <= t + h; the model's variables must then be those of that time), then return 0. */
void fmu_request_termination(Instance *inst, double reached);

/* FMU state snapshots. */
FmuStatus fmu_get_state(Instance *inst, const char *function, void **state);
FmuStatus fmu_set_state(Instance *inst, const char *function, const void *state);
FmuStatus fmu_free_state(Instance *inst, const char *function, void **state);
FmuStatus fmu_serialized_size(Instance *inst, const char *function, const void *state, size_t *size);
FmuStatus fmu_serialize(Instance *inst, const char *function, const void *state, char *bytes,
                        size_t size);
FmuStatus fmu_deserialize(Instance *inst, const char *function, const char *bytes, size_t size,
                          void **state);

/* The checksum of FMU states: 64-bit FNV-1a of `size` bytes continuing from `hash` (start with
 * FMU_STATE_CHECKSUM_SEED). A serialized state holds at byte SNAPSHOT_CHECKSUM_OFFSET (8) the
 * checksum of all its bytes from SNAPSHOT_CHECKSUM_OFFSET + 8 to the end (so a test host can
 * reseal a state it changed, to reach the invariant checks behind the checksum). */
#define FMU_STATE_CHECKSUM_SEED 14695981039346656037ULL
#define SNAPSHOT_CHECKSUM_OFFSET 8
unsigned long long fmu_state_checksum(unsigned long long hash, const void *bytes, size_t size);

#ifdef __cplusplus
}
#endif

#endif
