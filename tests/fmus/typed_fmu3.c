/*
 * typed_fmu3.c - the FMI 3.0 Co-Simulation functions of duffid's typed test FMUs (see
 * typed_fmu.h). Model Exchange, Scheduled Execution, clocks, FMU states and derivatives are
 * refused with a logged error.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "typed_fmu.h"
#include "typed_model.h"

enum { M_INSTANTIATED = 1, M_CONFIGURATION = 2, M_INITIALIZATION = 4, M_STEP = 8, M_TERMINATED = 16,
       M_ERROR = 32, M_EVENT = 64 };

struct Model {
    char *name;
    int mode;
    int logging;
    int event_mode_used;
    double time;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback logger;
    void *values[N_VARS];
};

static const size_t ITEM_SIZE[] = {sizeof(float), sizeof(double), 1, 1, 2, 2, 4, 4, 8, 8, sizeof(fmi3Boolean),
                                   sizeof(char *), sizeof(BinaryValue), sizeof(long long), sizeof(fmi3Clock)};
static const char *const TYPE_NAMES[] = {"Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32",
                                         "UInt32", "Int64", "UInt64", "Boolean", "String", "Binary",
                                         "Enumeration", "Clock"};

static void say(Model *m, fmi3Status status, const char *fmt, ...)
{
    char text[512];
    va_list ap;
    if (m == NULL || m->logger == NULL || (status == fmi3OK && !m->logging)) return;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    m->logger(m->env, status, status == fmi3OK ? "logEvents" : "logStatusError", text);
}

static fmi3Status fail(Model *m, const char *fmt, const char *function, const char *detail)
{
    say(m, fmi3Error, fmt, function, detail);
    return fmi3Error;
}

void *model_values(Model *m, int index) { return m->values[index]; }
double model_time(const Model *m) { return m->time; }

size_t model_size(const Model *m, int index)
{
    const VarInfo *v = &VARS[index];
    size_t n = 1;
    int k;
    for (k = 0; k < v->ndims; k++)
        n *= v->dim[k] < 0 ? (size_t)v->fixed[k] : (size_t)((unsigned long long *)m->values[v->dim[k]])[0];
    return n;
}

static int find(unsigned vr)
{
    int i;
    for (i = 0; i < N_VARS; i++)
        if (VARS[i].vr == vr) return i;
    return -1;
}

static int hex_digit(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

static void set_binary(BinaryValue *b, const unsigned char *data, size_t size)
{
    free(b->data);
    b->data = size ? malloc(size) : NULL;
    b->size = b->data ? size : 0;
    if (b->data) memcpy(b->data, data, size);
}

static void set_string(char **s, const char *text)
{
    size_t n = strlen(text);
    free(*s);
    *s = malloc(n + 1);
    if (*s) memcpy(*s, text, n + 1);
}

void model_copy(Model *m, int dst, int src)
{
    size_t k, n = model_size(m, src);
    int type = VARS[src].type;
    for (k = 0; k < n; k++) {
        if (type == T_STRING)
            set_string(&((char **)m->values[dst])[k], ((char **)m->values[src])[k]);
        else if (type == T_BINARY)
            set_binary(&((BinaryValue *)m->values[dst])[k], ((BinaryValue *)m->values[src])[k].data,
                       ((BinaryValue *)m->values[src])[k].size);
        else
            memcpy((char *)m->values[dst] + k * ITEM_SIZE[type], (char *)m->values[src] + k * ITEM_SIZE[type],
                   ITEM_SIZE[type]);
    }
}

/* Every element of variable i from its start attribute (zero without one). */
static void start_values(Model *m, int i)
{
    const VarInfo *v = &VARS[i];
    const char *p = v->start ? v->start : "";
    size_t k;
    char *end;
    if (v->type == T_STRING) {
        for (k = 0; k < v->capacity; k++) set_string(&((char **)m->values[i])[k], p);
        return;
    }
    if (v->type == T_BINARY) {
        size_t n = strlen(p) / 2;
        unsigned char *bytes = malloc(n + 1);
        for (k = 0; k < n; k++) bytes[k] = (unsigned char)(hex_digit(p[2 * k]) * 16 + hex_digit(p[2 * k + 1]));
        for (k = 0; k < v->capacity; k++) set_binary(&((BinaryValue *)m->values[i])[k], bytes, n);
        free(bytes);
        return;
    }
    for (k = 0; k < v->capacity; k++) {
        double d = 0;
        long long s = 0;
        unsigned long long u = 0;
        while (*p == ' ') p++;
        if (*p) {
            if (v->type == T_BOOLEAN) {
                s = strncmp(p, "true", 4) == 0 || *p == '1';
                while (*p && *p != ' ') p++;
            } else if (v->type == T_FLOAT32 || v->type == T_FLOAT64) {
                d = strtod(p, &end);
                p = end;
            } else if (v->type == T_UINT8 || v->type == T_UINT16 || v->type == T_UINT32 || v->type == T_UINT64) {
                u = strtoull(p, &end, 10);
                p = end;
            } else {
                s = strtoll(p, &end, 10);
                p = end;
            }
        }
        switch (v->type) {
        case T_FLOAT32: ((float *)m->values[i])[k] = (float)d; break;
        case T_FLOAT64: ((double *)m->values[i])[k] = d; break;
        case T_INT8: ((signed char *)m->values[i])[k] = (signed char)s; break;
        case T_UINT8: ((unsigned char *)m->values[i])[k] = (unsigned char)u; break;
        case T_INT16: ((short *)m->values[i])[k] = (short)s; break;
        case T_UINT16: ((unsigned short *)m->values[i])[k] = (unsigned short)u; break;
        case T_INT32: ((int *)m->values[i])[k] = (int)s; break;
        case T_UINT32: ((unsigned *)m->values[i])[k] = (unsigned)u; break;
        case T_INT64: case T_ENUMERATION: ((long long *)m->values[i])[k] = s; break;
        case T_UINT64: ((unsigned long long *)m->values[i])[k] = u; break;
        case T_BOOLEAN: ((fmi3Boolean *)m->values[i])[k] = s != 0; break;
        default: break;
        }
    }
}

static void release_values(Model *m)
{
    int i;
    size_t k;
    for (i = 0; i < N_VARS; i++) {
        if (m->values[i] == NULL) continue;
        for (k = 0; k < VARS[i].capacity; k++) {
            if (VARS[i].type == T_STRING) free(((char **)m->values[i])[k]);
            if (VARS[i].type == T_BINARY) free(((BinaryValue *)m->values[i])[k].data);
        }
        free(m->values[i]);
        m->values[i] = NULL;
    }
}

static int allocate_values(Model *m)
{
    int i;
    for (i = 0; i < N_VARS; i++) {
        m->values[i] = calloc(VARS[i].capacity, ITEM_SIZE[VARS[i].type]);
        if (m->values[i] == NULL) return 1;
    }
    for (i = 0; i < N_VARS; i++) start_values(m, i);
    return 0;
}

static fmi3Status check(Model *m, const char *function, int modes)
{
    if (m == NULL) return fmi3Error;
    if (!(m->mode & modes)) {
        say(m, fmi3Error, "%s may not be called in this state (mode %d)", function, m->mode);
        return fmi3Error;
    }
    return fmi3OK;
}

/* The modes in which variable v may be set. */
static int settable_modes(const VarInfo *v)
{
    if (v->causality == C_STRUCTURAL) return M_CONFIGURATION;
    if (v->causality == C_INPUT) return M_INSTANTIATED | M_INITIALIZATION | M_STEP | M_EVENT;
    if (v->causality == C_PARAMETER)
        return M_INSTANTIATED | M_INITIALIZATION | (v->variability == V_TUNABLE ? M_STEP : 0);
    return 0;
}

/* The indices of the variables of vr[] after checking their type and access; the total number of
 * values through *total. -1 on error (logged). */
static int resolve(Model *m, const char *function, int type, int setting, const fmi3ValueReference vr[],
                   size_t nvr, size_t n_values, int *indices)
{
    size_t j, total = 0;
    if (nvr > 0 && vr == NULL) return fail(m, "%s: %s", function, "valueReferences is NULL"), -1;
    for (j = 0; j < nvr; j++) {
        int i = find(vr[j]);
        const VarInfo *v;
        if (i < 0) {
            say(m, fmi3Error, "%s: unknown value reference %u", function, vr[j]);
            return -1;
        }
        v = &VARS[i];
        if (v->type != type && !(type == T_INT64 && v->type == T_ENUMERATION)) {
            say(m, fmi3Error, "%s: %s is %s", function, v->name, TYPE_NAMES[v->type]);
            return -1;
        }
        if (setting && !(settable_modes(v) & m->mode)) {
            say(m, fmi3Error, "%s: %s cannot be set in mode %d", function, v->name, m->mode);
            return -1;
        }
        indices[j] = i;
        total += model_size(m, i);
    }
    if (total != n_values) {
        say(m, fmi3Error, "%s: nValues is %lu, the variables have %lu values", function, (unsigned long)n_values,
            (unsigned long)total);
        return -1;
    }
    return 0;
}

static fmi3Status get_values(fmi3Instance instance, const char *function, int type, const fmi3ValueReference vr[],
                             size_t nvr, void *values, size_t n_values)
{
    Model *m = (Model *)instance;
    int indices[N_VARS + 1];
    size_t j, at = 0, item;
    if (check(m, function, M_CONFIGURATION | M_INITIALIZATION | M_STEP | M_EVENT | M_TERMINATED) != fmi3OK)
        return fmi3Error;
    if (nvr > N_VARS) return fail(m, "%s: %s", function, "too many value references");
    if (resolve(m, function, type, 0, vr, nvr, n_values, indices) < 0) return fmi3Error;
    if (n_values > 0 && values == NULL) return fail(m, "%s: %s", function, "values is NULL");
    item = ITEM_SIZE[type];
    for (j = 0; j < nvr; j++) {
        size_t n = model_size(m, indices[j]);
        memcpy((char *)values + at * item, m->values[indices[j]], n * item);
        at += n;
    }
    return fmi3OK;
}

static fmi3Status set_values(fmi3Instance instance, const char *function, int type, const fmi3ValueReference vr[],
                             size_t nvr, const void *values, size_t n_values)
{
    Model *m = (Model *)instance;
    int indices[N_VARS + 1];
    size_t j, k, at = 0;
    if (check(m, function, M_INSTANTIATED | M_CONFIGURATION | M_INITIALIZATION | M_STEP | M_EVENT) != fmi3OK)
        return fmi3Error;
    if (nvr > N_VARS) return fail(m, "%s: %s", function, "too many value references");
    if (resolve(m, function, type, 1, vr, nvr, n_values, indices) < 0) return fmi3Error;
    if (n_values > 0 && values == NULL) return fail(m, "%s: %s", function, "values is NULL");
    for (j = 0; j < nvr; j++) {
        const VarInfo *v = &VARS[indices[j]];
        size_t n = model_size(m, indices[j]);
        if (v->causality == C_STRUCTURAL && ((const unsigned long long *)values)[at] > v->max) {
            say(m, fmi3Error, "%s: %s = %llu exceeds its maximum %llu", function, v->name,
                ((const unsigned long long *)values)[at], v->max);
            return fmi3Error;
        }
        for (k = 0; k < n; k++, at++) {
            if (type == T_STRING) {
                const char *text = ((const fmi3String *)values)[at];
                if (text == NULL) return fail(m, "%s: %s", function, "a string is NULL");
                set_string(&((char **)m->values[indices[j]])[k], text);
            } else if (type == T_BOOLEAN) {
                ((fmi3Boolean *)m->values[indices[j]])[k] = ((const fmi3Boolean *)values)[at] != 0;
            } else {
                memcpy((char *)m->values[indices[j]] + k * ITEM_SIZE[type], (const char *)values + at * ITEM_SIZE[type],
                       ITEM_SIZE[type]);
            }
        }
    }
    if (m->mode & (M_INITIALIZATION | M_STEP | M_EVENT)) model_calculate(m);
    return fmi3OK;
}

/* ------------------------------------------------------------------ lifecycle */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    (void)nCategories; (void)categories;
    if (instance == NULL) return fmi3Error;
    ((Model *)instance)->logging = loggingOn;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", "Model Exchange is not provided");
    return NULL;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    Model *m;
    (void)resourcePath; (void)visible; (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables; (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
    if (instantiationToken == NULL || strcmp(instantiationToken, INSTANTIATION_TOKEN) != 0) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError", "wrong instantiation token");
        return NULL;
    }
    m = calloc(1, sizeof *m);
    if (m == NULL) return NULL;
    m->env = instanceEnvironment;
    m->logger = logMessage;
    m->logging = loggingOn;
    m->event_mode_used = eventModeUsed;
    m->mode = M_INSTANTIATED;
    set_string(&m->name, instanceName ? instanceName : "");
    if (allocate_values(m) != 0) {
        release_values(m);
        free(m->name);
        free(m);
        return NULL;
    }
    return m;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError", "Scheduled Execution is not provided");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance)
{
    Model *m = (Model *)instance;
    if (m == NULL) return;
    release_values(m);
    free(m->name);
    free(m);
}

/* A change of mode allowed from the modes `from`. */
static fmi3Status switch_mode(fmi3Instance instance, const char *function, int from, int to)
{
    Model *m = (Model *)instance;
    if (check(m, function, from) != fmi3OK) return fmi3Error;
    m->mode = to;
    return fmi3OK;
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    return switch_mode(instance, "fmi3EnterConfigurationMode", M_INSTANTIATED, M_CONFIGURATION);
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{
    return switch_mode(instance, "fmi3ExitConfigurationMode", M_CONFIGURATION, M_INSTANTIATED);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    Model *m = (Model *)instance;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (check(m, "fmi3EnterInitializationMode", M_INSTANTIATED) != fmi3OK) return fmi3Error;
    m->time = startTime;
    m->mode = M_INITIALIZATION;
    model_calculate(m);
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    Model *m = (Model *)instance;
    if (check(m, "fmi3ExitInitializationMode", M_INITIALIZATION) != fmi3OK) return fmi3Error;
    model_initialize(m);
    model_calculate(m);
    m->mode = m->event_mode_used ? M_EVENT : M_STEP; /* FMI 3 Co-Simulation with Event Mode starts there */
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    return switch_mode(instance, "fmi3Terminate", M_STEP | M_EVENT, M_TERMINATED);
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    Model *m = (Model *)instance;
    if (m == NULL) return fmi3Error;
    release_values(m);
    if (allocate_values(m) != 0) {
        m->mode = M_ERROR;
        return fmi3Fatal;
    }
    m->mode = M_INSTANTIATED;
    m->time = 0;
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime)
{
    Model *m = (Model *)instance;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (check(m, "fmi3DoStep", M_STEP) != fmi3OK) return fmi3Error;
    if (!(communicationStepSize > 0)) return fail(m, "%s: %s", "fmi3DoStep", "the step size must be positive");
    if (currentCommunicationPoint < m->time - 1e-9 || currentCommunicationPoint > m->time + 1e-9) {
        say(m, fmi3Error, "fmi3DoStep: the communication point %.17g is not the FMU's time %.17g",
            currentCommunicationPoint, m->time);
        return fmi3Error;
    }
    if (eventHandlingNeeded == NULL || terminateSimulation == NULL || earlyReturn == NULL ||
        lastSuccessfulTime == NULL)
        return fail(m, "%s: %s", "fmi3DoStep", "an output argument is NULL");
    model_step(m, communicationStepSize);
    m->time = currentCommunicationPoint + communicationStepSize;
    *eventHandlingNeeded = fmi3False;
    if (m->event_mode_used)
        *eventHandlingNeeded = model_event_due(m) ? fmi3True : fmi3False; /* the importer updates in Event Mode */
    else
        while (model_event_due(m)) model_update(m, 0);                    /* handled inside the step */
    model_calculate(m);
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = m->time;
    return fmi3OK;
}

/* ------------------------------------------------------------------ Event Mode (eventModeUsed) */

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    Model *m = (Model *)instance;
    if (m != NULL && !m->event_mode_used)
        return fail(m, "%s: %s", "fmi3EnterEventMode", "the instance was made with eventModeUsed false");
    return switch_mode(instance, "fmi3EnterEventMode", M_STEP, M_EVENT);
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsChanged,
                                    fmi3Boolean *valuesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime)
{
    Model *m = (Model *)instance;
    if (check(m, "fmi3UpdateDiscreteStates", M_EVENT) != fmi3OK) return fmi3Error;
    if (discreteStatesNeedUpdate == NULL || terminateSimulation == NULL || nominalsChanged == NULL ||
        valuesChanged == NULL || nextEventTimeDefined == NULL || nextEventTime == NULL)
        return fail(m, "%s: %s", "fmi3UpdateDiscreteStates", "an output argument is NULL");
    if (model_event_due(m)) model_update(m, 1);
    model_calculate(m);
    *discreteStatesNeedUpdate = model_event_due(m) ? fmi3True : fmi3False;
    *terminateSimulation = *nominalsChanged = *valuesChanged = *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
    return fmi3OK;
}

fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    return switch_mode(instance, "fmi3EnterStepMode", M_EVENT, M_STEP);
}

/* ------------------------------------------------------------------ getters and setters */

#define GET_SET(Name, Type, code)                                                                            \
    fmi3Status fmi3Get##Name(fmi3Instance instance, const fmi3ValueReference valueReferences[],              \
                             size_t nValueReferences, Type values[], size_t nValues)                         \
    {                                                                                                        \
        return get_values(instance, "fmi3Get" #Name, code, valueReferences, nValueReferences, values, nValues); \
    }                                                                                                        \
    fmi3Status fmi3Set##Name(fmi3Instance instance, const fmi3ValueReference valueReferences[],              \
                             size_t nValueReferences, const Type values[], size_t nValues)                   \
    {                                                                                                        \
        return set_values(instance, "fmi3Set" #Name, code, valueReferences, nValueReferences, values, nValues); \
    }

GET_SET(Float32, fmi3Float32, T_FLOAT32)
GET_SET(Float64, fmi3Float64, T_FLOAT64)
GET_SET(Int8, fmi3Int8, T_INT8)
GET_SET(UInt8, fmi3UInt8, T_UINT8)
GET_SET(Int16, fmi3Int16, T_INT16)
GET_SET(UInt16, fmi3UInt16, T_UINT16)
GET_SET(Int32, fmi3Int32, T_INT32)
GET_SET(UInt32, fmi3UInt32, T_UINT32)
GET_SET(Int64, fmi3Int64, T_INT64)
GET_SET(UInt64, fmi3UInt64, T_UINT64)
GET_SET(Boolean, fmi3Boolean, T_BOOLEAN)
GET_SET(String, fmi3String, T_STRING)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues)
{
    Model *m = (Model *)instance;
    int indices[N_VARS + 1];
    size_t j, k, at = 0;
    if (check(m, "fmi3GetBinary", M_CONFIGURATION | M_INITIALIZATION | M_STEP | M_TERMINATED) != fmi3OK)
        return fmi3Error;
    if (nValueReferences > N_VARS) return fail(m, "%s: %s", "fmi3GetBinary", "too many value references");
    if (resolve(m, "fmi3GetBinary", T_BINARY, 0, valueReferences, nValueReferences, nValues, indices) < 0)
        return fmi3Error;
    if (nValues > 0 && (values == NULL || valueSizes == NULL))
        return fail(m, "%s: %s", "fmi3GetBinary", "values or valueSizes is NULL");
    for (j = 0; j < nValueReferences; j++)
        for (k = 0; k < model_size(m, indices[j]); k++, at++) {
            const BinaryValue *b = &((BinaryValue *)m->values[indices[j]])[k];
            valueSizes[at] = b->size;
            values[at] = b->data;
        }
    return fmi3OK;
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues)
{
    Model *m = (Model *)instance;
    int indices[N_VARS + 1];
    size_t j, k, at = 0;
    if (check(m, "fmi3SetBinary", M_INSTANTIATED | M_INITIALIZATION | M_STEP) != fmi3OK) return fmi3Error;
    if (nValueReferences > N_VARS) return fail(m, "%s: %s", "fmi3SetBinary", "too many value references");
    if (resolve(m, "fmi3SetBinary", T_BINARY, 1, valueReferences, nValueReferences, nValues, indices) < 0)
        return fmi3Error;
    if (nValues > 0 && (values == NULL || valueSizes == NULL))
        return fail(m, "%s: %s", "fmi3SetBinary", "values or valueSizes is NULL");
    for (j = 0; j < nValueReferences; j++)
        for (k = 0; k < model_size(m, indices[j]); k++, at++) {
            if (valueSizes[at] > 0 && values[at] == NULL) return fail(m, "%s: %s", "fmi3SetBinary", "a value is NULL");
            set_binary(&((BinaryValue *)m->values[indices[j]])[k], values[at], valueSizes[at]);
        }
    if (m->mode & (M_INITIALIZATION | M_STEP)) model_calculate(m);
    return fmi3OK;
}

/* ------------------------------------------------------------------ refused */

static fmi3Status refused(fmi3Instance instance, const char *function)
{
    say((Model *)instance, fmi3Error, "%s is not supported by this FMU", function);
    return fmi3Error;
}

#define REFUSED(name, params, ...)                                                                           \
    fmi3Status name params                                                                                   \
    {                                                                                                        \
        __VA_ARGS__;                                                                                         \
        return refused(instance, #name);                                                                     \
    }

REFUSED(fmi3GetClock, (fmi3Instance instance, const fmi3ValueReference vr[], size_t n, fmi3Clock v[]),
        (void)vr; (void)n; (void)v)
REFUSED(fmi3SetClock, (fmi3Instance instance, const fmi3ValueReference vr[], size_t n, const fmi3Clock v[]),
        (void)vr; (void)n; (void)v)
REFUSED(fmi3GetNumberOfVariableDependencies, (fmi3Instance instance, fmi3ValueReference vr, size_t *n),
        (void)vr; (void)n)
REFUSED(fmi3GetVariableDependencies,
        (fmi3Instance instance, fmi3ValueReference d, size_t ei[], fmi3ValueReference i[], size_t ie[],
         fmi3DependencyKind k[], size_t n),
        (void)d; (void)ei; (void)i; (void)ie; (void)k; (void)n)
REFUSED(fmi3GetFMUState, (fmi3Instance instance, fmi3FMUState *s), (void)s)
REFUSED(fmi3SetFMUState, (fmi3Instance instance, fmi3FMUState s), (void)s)
REFUSED(fmi3FreeFMUState, (fmi3Instance instance, fmi3FMUState *s), (void)s)
REFUSED(fmi3SerializedFMUStateSize, (fmi3Instance instance, fmi3FMUState s, size_t *n), (void)s; (void)n)
REFUSED(fmi3SerializeFMUState, (fmi3Instance instance, fmi3FMUState s, fmi3Byte b[], size_t n),
        (void)s; (void)b; (void)n)
REFUSED(fmi3DeserializeFMUState, (fmi3Instance instance, const fmi3Byte b[], size_t n, fmi3FMUState *s),
        (void)s; (void)b; (void)n)
REFUSED(fmi3GetDirectionalDerivative,
        (fmi3Instance instance, const fmi3ValueReference u[], size_t nu, const fmi3ValueReference k[], size_t nk,
         const fmi3Float64 s[], size_t ns, fmi3Float64 r[], size_t nr),
        (void)u; (void)nu; (void)k; (void)nk; (void)s; (void)ns; (void)r; (void)nr)
REFUSED(fmi3GetAdjointDerivative,
        (fmi3Instance instance, const fmi3ValueReference u[], size_t nu, const fmi3ValueReference k[], size_t nk,
         const fmi3Float64 s[], size_t ns, fmi3Float64 r[], size_t nr),
        (void)u; (void)nu; (void)k; (void)nk; (void)s; (void)ns; (void)r; (void)nr)
REFUSED(fmi3GetIntervalDecimal,
        (fmi3Instance instance, const fmi3ValueReference vr[], size_t n, fmi3Float64 i[], fmi3IntervalQualifier q[]),
        (void)vr; (void)n; (void)i; (void)q)
REFUSED(fmi3GetIntervalFraction,
        (fmi3Instance instance, const fmi3ValueReference vr[], size_t n, fmi3UInt64 c[], fmi3UInt64 r[],
         fmi3IntervalQualifier q[]),
        (void)vr; (void)n; (void)c; (void)r; (void)q)
REFUSED(fmi3GetShiftDecimal, (fmi3Instance instance, const fmi3ValueReference vr[], size_t n, fmi3Float64 s[]),
        (void)vr; (void)n; (void)s)
REFUSED(fmi3GetShiftFraction,
        (fmi3Instance instance, const fmi3ValueReference vr[], size_t n, fmi3UInt64 c[], fmi3UInt64 r[]),
        (void)vr; (void)n; (void)c; (void)r)
REFUSED(fmi3SetIntervalDecimal, (fmi3Instance instance, const fmi3ValueReference vr[], size_t n, const fmi3Float64 i[]),
        (void)vr; (void)n; (void)i)
REFUSED(fmi3SetIntervalFraction,
        (fmi3Instance instance, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 c[], const fmi3UInt64 r[]),
        (void)vr; (void)n; (void)c; (void)r)
REFUSED(fmi3SetShiftDecimal, (fmi3Instance instance, const fmi3ValueReference vr[], size_t n, const fmi3Float64 s[]),
        (void)vr; (void)n; (void)s)
REFUSED(fmi3SetShiftFraction,
        (fmi3Instance instance, const fmi3ValueReference vr[], size_t n, const fmi3UInt64 c[], const fmi3UInt64 r[]),
        (void)vr; (void)n; (void)c; (void)r)
REFUSED(fmi3EvaluateDiscreteStates, (fmi3Instance instance), (void)0)
REFUSED(fmi3EnterContinuousTimeMode, (fmi3Instance instance), (void)0)
REFUSED(fmi3CompletedIntegratorStep, (fmi3Instance instance, fmi3Boolean a, fmi3Boolean *b, fmi3Boolean *c),
        (void)a; (void)b; (void)c)
REFUSED(fmi3SetTime, (fmi3Instance instance, fmi3Float64 t), (void)t)
REFUSED(fmi3SetContinuousStates, (fmi3Instance instance, const fmi3Float64 x[], size_t n), (void)x; (void)n)
REFUSED(fmi3GetContinuousStateDerivatives, (fmi3Instance instance, fmi3Float64 x[], size_t n), (void)x; (void)n)
REFUSED(fmi3GetEventIndicators, (fmi3Instance instance, fmi3Float64 x[], size_t n), (void)x; (void)n)
REFUSED(fmi3GetContinuousStates, (fmi3Instance instance, fmi3Float64 x[], size_t n), (void)x; (void)n)
REFUSED(fmi3GetNominalsOfContinuousStates, (fmi3Instance instance, fmi3Float64 x[], size_t n), (void)x; (void)n)
REFUSED(fmi3GetNumberOfEventIndicators, (fmi3Instance instance, size_t *n), (void)n)
REFUSED(fmi3GetNumberOfContinuousStates, (fmi3Instance instance, size_t *n), (void)n)
REFUSED(fmi3GetOutputDerivatives,
        (fmi3Instance instance, const fmi3ValueReference vr[], size_t n, const fmi3Int32 o[], fmi3Float64 v[],
         size_t nv),
        (void)vr; (void)n; (void)o; (void)v; (void)nv)
REFUSED(fmi3ActivateModelPartition, (fmi3Instance instance, fmi3ValueReference c, fmi3Float64 t), (void)c; (void)t)
