/*
 * typed_fmu.h - the variable table of duffid's typed test FMUs and a small FMI 3.0 Co-Simulation engine for duffid's tests: every variable type
 * (Float32 .. UInt64, Boolean, String, Binary, Enumeration), arrays whose dimensions are fixed
 * or given by structural parameters (set in Configuration Mode), strict mode and argument
 * checks (every error logged, never a crash).
 *
 * A test model is a generated header typed_model.h (its variable table VARS, made by
 * tests/typed_fmus.py, with the model identifier, the token and V_<name> indices) and a model
 * source with model_calculate (outputs from inputs, parameters and states) and model_step
 * (advance the states over h). Written for duffid's tests; not derived from other FMUs' code.
 */
#ifndef TYPED_FMU_H
#define TYPED_FMU_H

#include <stddef.h>

enum { T_FLOAT32, T_FLOAT64, T_INT8, T_UINT8, T_INT16, T_UINT16, T_INT32, T_UINT32, T_INT64, T_UINT64,
       T_BOOLEAN, T_STRING, T_BINARY, T_ENUMERATION, T_CLOCK };
enum { C_PARAMETER, C_STRUCTURAL, C_CALCULATED, C_INPUT, C_OUTPUT, C_LOCAL, C_INDEPENDENT };
enum { V_CONSTANT, V_FIXED, V_TUNABLE, V_DISCRETE, V_CONTINUOUS };

typedef struct VarInfo {
    const char *name;
    unsigned vr;
    int type;          /* T_* */
    int causality;     /* C_* */
    int variability;   /* V_* */
    int ndims;         /* 0: scalar */
    long fixed[2];     /* fixed extent of each dimension (when dim[k] < 0) */
    int dim[2];        /* index in VARS of the structural parameter giving the extent, or -1 */
    size_t capacity;   /* elements allocated (the largest size the structural parameters allow) */
    const char *start; /* start values, space separated (Binary: hex; String: the whole text), or NULL */
    unsigned long long max; /* structural parameters: the largest value accepted */
} VarInfo;

typedef struct BinaryValue {
    size_t size;
    unsigned char *data;
} BinaryValue;

typedef struct Model Model;

/* The values of variable `index` (its type's C array: double *, float *, ..., char ** for String,
 * BinaryValue * for Binary, long long * for Enumeration) and its current number of elements. */
void *model_values(Model *m, int index);
size_t model_size(const Model *m, int index);
double model_time(const Model *m);
/* Copy every element of variable `src` into variable `dst` (same type and size; Strings and Binaries
 * are copied, not shared). */
void model_copy(Model *m, int dst, int src);

/* Provided by the model source: the states from their parameters at the end of initialisation, the
 * dependent variables, a step of h. */
void model_initialize(Model *m);
void model_calculate(Model *m);
void model_step(Model *m, double h);
/* Time events (after a step, at the model's time): whether one is due, and its discrete update
 * (in_event_mode: made in Event Mode at the importer's fmi3UpdateDiscreteStates, else inside doStep). */
int model_event_due(Model *m);
void model_update(Model *m, int in_event_mode);
/* The two for a model without events. */
#define MODEL_WITHOUT_EVENTS                                                                       \
    int model_event_due(Model *m) { return (void)m, 0; }                                           \
    void model_update(Model *m, int in_event_mode) { (void)m, (void)in_event_mode; }

#endif
