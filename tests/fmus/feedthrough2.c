/*
 * feedthrough2.c - a Feedthrough-like FMI 2.0 Co-Simulation test model (duffid's own code) with
 * every FMI 2 type: Real, Integer, Boolean, String, Enumeration (scalars). Every output is a copy
 * of the input or parameter the generated table FEED pairs it with (tests/typed_fmus.py writes
 * typed_model.h: VARS, N_VARS, FEED, N_FEED, the model identifier and the GUID). Mode and argument
 * checks log an error; unsupported functions are refused with a logged error.
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "typed_fmu.h"
#include "typed_model.h"

enum { M_INSTANTIATED = 1, M_INITIALIZATION = 2, M_STEP = 4, M_TERMINATED = 8 };

typedef struct Model2 {
    int mode;
    int logging;
    double time;
    fmi2CallbackFunctions callbacks;
    fmi2String name;
    double real[N_VARS];
    int integer[N_VARS];
    char *string[N_VARS];
} Model2;

static void say(Model2 *m, fmi2Status status, const char *fmt, ...)
{
    char text[512];
    va_list ap;
    if (m == NULL || m->callbacks.logger == NULL || (status == fmi2OK && !m->logging)) return;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    m->callbacks.logger(m->callbacks.componentEnvironment, m->name, status,
                        status == fmi2OK ? "logAll" : "logStatusError", "%s", text);
}

static void put_string(char **s, const char *text)
{
    size_t n = strlen(text);
    free(*s);
    *s = malloc(n + 1);
    if (*s) memcpy(*s, text, n + 1);
}

static void start_values(Model2 *m)
{
    int i;
    for (i = 0; i < N_VARS; i++) {
        const char *p = VARS[i].start ? VARS[i].start : "";
        m->real[i] = VARS[i].type == T_FLOAT64 ? strtod(p, NULL) : 0.0;
        m->integer[i] = VARS[i].type == T_BOOLEAN ? strncmp(p, "true", 4) == 0 || *p == '1' : (int)strtol(p, NULL, 10);
        if (VARS[i].type == T_STRING) put_string(&m->string[i], p);
    }
}

static void calculate(Model2 *m)
{
    int i;
    for (i = 0; i < N_FEED; i++) {
        int d = FEED[i][0], s = FEED[i][1];
        m->real[d] = m->real[s];
        m->integer[d] = m->integer[s];
        if (VARS[s].type == T_STRING) put_string(&m->string[d], m->string[s]);
    }
}

static int find(fmi2ValueReference vr)
{
    int i;
    for (i = 0; i < N_VARS; i++)
        if (VARS[i].vr == vr) return i;
    return -1;
}

/* The index of vr if it has one of the types a/b and may be accessed now (-1, logged, otherwise). */
static int access(Model2 *m, const char *function, fmi2ValueReference vr, int a, int b, int setting)
{
    int i = find(vr), modes;
    if (i < 0) {
        say(m, fmi2Error, "%s: unknown value reference %u", function, vr);
        return -1;
    }
    if (VARS[i].type != a && VARS[i].type != b) {
        say(m, fmi2Error, "%s: %s has another type", function, VARS[i].name);
        return -1;
    }
    modes = !setting ? M_INITIALIZATION | M_STEP | M_TERMINATED
            : VARS[i].causality == C_INPUT ? M_INSTANTIATED | M_INITIALIZATION | M_STEP
            : VARS[i].causality == C_PARAMETER ? M_INSTANTIATED | M_INITIALIZATION |
                                                     (VARS[i].variability == V_TUNABLE ? M_STEP : 0)
                                               : 0;
    if (!(m->mode & modes)) {
        say(m, fmi2Error, "%s: %s cannot be accessed in mode %d", function, VARS[i].name, m->mode);
        return -1;
    }
    return i;
}

static int bad(Model2 *m, const char *function, const void *vr, size_t nvr, const void *values)
{
    if (m == NULL) return 1;
    if (nvr > 0 && (vr == NULL || values == NULL)) {
        say(m, fmi2Error, "%s: a NULL argument", function);
        return 1;
    }
    return 0;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n, const fmi2String categories[])
{
    (void)n; (void)categories;
    if (c == NULL) return fmi2Error;
    ((Model2 *)c)->logging = loggingOn;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    Model2 *m;
    (void)fmuResourceLocation; (void)visible;
    if (functions == NULL || fmuType != fmi2CoSimulation || fmuGUID == NULL || strcmp(fmuGUID, INSTANTIATION_TOKEN))
        return NULL;
    m = calloc(1, sizeof *m);
    if (m == NULL) return NULL;
    m->callbacks = *functions;
    m->name = instanceName;
    m->logging = loggingOn;
    m->mode = M_INSTANTIATED;
    start_values(m);
    return m;
}

void fmi2FreeInstance(fmi2Component c)
{
    Model2 *m = (Model2 *)c;
    int i;
    if (m == NULL) return;
    for (i = 0; i < N_VARS; i++) free(m->string[i]);
    free(m);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (c == NULL || ((Model2 *)c)->mode != M_INSTANTIATED) return fmi2Error;
    ((Model2 *)c)->time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    Model2 *m = (Model2 *)c;
    if (m == NULL || m->mode != M_INSTANTIATED) return fmi2Error;
    m->mode = M_INITIALIZATION;
    calculate(m);
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    Model2 *m = (Model2 *)c;
    if (m == NULL || m->mode != M_INITIALIZATION) return fmi2Error;
    calculate(m);
    m->mode = M_STEP;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    if (c == NULL || ((Model2 *)c)->mode != M_STEP) return fmi2Error;
    ((Model2 *)c)->mode = M_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    Model2 *m = (Model2 *)c;
    if (m == NULL) return fmi2Error;
    m->mode = M_INSTANTIATED;
    m->time = 0;
    start_values(m);
    return fmi2OK;
}

/* fmi2Get<Name> / fmi2Set<Name> of variables of the types a or b, values in m-><store>[index]. */
#define GET_SET(Name, Type, a, b, store, assign)                                                             \
    fmi2Status fmi2Get##Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, Type value[])       \
    {                                                                                                        \
        Model2 *m = (Model2 *)c;                                                                             \
        size_t j;                                                                                            \
        if (bad(m, "fmi2Get" #Name, vr, nvr, value)) return fmi2Error;                                       \
        for (j = 0; j < nvr; j++) {                                                                          \
            int i = access(m, "fmi2Get" #Name, vr[j], a, b, 0);                                              \
            if (i < 0) return fmi2Error;                                                                     \
            value[j] = m->store[i];                                                                          \
        }                                                                                                    \
        return fmi2OK;                                                                                       \
    }                                                                                                        \
    fmi2Status fmi2Set##Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const Type value[]) \
    {                                                                                                        \
        Model2 *m = (Model2 *)c;                                                                             \
        size_t j;                                                                                            \
        if (bad(m, "fmi2Set" #Name, vr, nvr, value)) return fmi2Error;                                       \
        for (j = 0; j < nvr; j++) {                                                                          \
            int i = access(m, "fmi2Set" #Name, vr[j], a, b, 1);                                              \
            if (i < 0 || assign(m, i, value[j])) return fmi2Error;                                           \
        }                                                                                                    \
        calculate(m);                                                                                        \
        return fmi2OK;                                                                                       \
    }

static int assign_real(Model2 *m, int i, fmi2Real value) { return m->real[i] = value, 0; }
static int assign_integer(Model2 *m, int i, fmi2Integer value) { return m->integer[i] = value, 0; }
static int assign_boolean(Model2 *m, int i, fmi2Boolean value) { return m->integer[i] = value != 0, 0; }
static int assign_string(Model2 *m, int i, fmi2String value)
{
    if (value == NULL) {
        say(m, fmi2Error, "fmi2SetString: a NULL string");
        return 1;
    }
    put_string(&m->string[i], value);
    return 0;
}

GET_SET(Real, fmi2Real, T_FLOAT64, T_FLOAT64, real, assign_real)
GET_SET(Integer, fmi2Integer, T_INT32, T_ENUMERATION, integer, assign_integer)
GET_SET(Boolean, fmi2Boolean, T_BOOLEAN, T_BOOLEAN, integer, assign_boolean)
GET_SET(String, fmi2String, T_STRING, T_STRING, string, assign_string)

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    Model2 *m = (Model2 *)c;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (m == NULL || m->mode != M_STEP || !(communicationStepSize > 0)) {
        say(m, fmi2Error, "fmi2DoStep: not in step mode or a bad step size");
        return fmi2Error;
    }
    m->time = currentCommunicationPoint + communicationStepSize;
    calculate(m);
    return fmi2OK;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    if (c == NULL || value == NULL) return fmi2Error;
    *value = fmi2False;
    return s == fmi2Terminated ? fmi2OK : fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    if (c == NULL || value == NULL) return fmi2Error;
    *value = ((Model2 *)c)->time;
    return s == fmi2LastSuccessfulTime ? fmi2OK : fmi2Discard;
}

static fmi2Status refused(fmi2Component c, const char *function)
{
    say((Model2 *)c, fmi2Error, "%s is not supported by this FMU", function);
    return fmi2Error;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)s; return refused(c, "fmi2GetFMUstate"); }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)s; return refused(c, "fmi2SetFMUstate"); }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)s; return refused(c, "fmi2FreeFMUstate"); }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n)
{
    (void)s; (void)n;
    return refused(c, "fmi2SerializedFMUstateSize");
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n)
{
    (void)s; (void)b; (void)n;
    return refused(c, "fmi2SerializeFMUstate");
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s)
{
    (void)s; (void)b; (void)n;
    return refused(c, "fmi2DeSerializeFMUstate");
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[])
{
    (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz;
    return refused(c, "fmi2GetDirectionalDerivative");
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer o[], const fmi2Real v[])
{
    (void)vr; (void)n; (void)o; (void)v;
    return refused(c, "fmi2SetRealInputDerivatives");
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer o[], fmi2Real v[])
{
    (void)vr; (void)n; (void)o; (void)v;
    return refused(c, "fmi2GetRealOutputDerivatives");
}
fmi2Status fmi2CancelStep(fmi2Component c) { return refused(c, "fmi2CancelStep"); }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v)
{
    (void)s; (void)v;
    return refused(c, "fmi2GetStatus");
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v)
{
    (void)s; (void)v;
    return refused(c, "fmi2GetIntegerStatus");
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v)
{
    (void)s; (void)v;
    return refused(c, "fmi2GetStringStatus");
}
