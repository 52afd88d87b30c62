/* FMI 2.0 API (Model Exchange and Co-Simulation) over the shared instance (fmu_instance.c). */
#include <stdio.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_instance.h"

#define ALL_GET (MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS_TIME | MODE_STEP | \
                 MODE_STEP_FAILED | MODE_TERMINATED | MODE_ERROR)
#define ALL_SET (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS_TIME | MODE_STEP)
#define STATE_MODES (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS_TIME | \
                     MODE_STEP | MODE_STEP_FAILED | MODE_TERMINATED | MODE_ERROR)

/* The FMI 2 logger takes a printf format: pass the message with '%' escaped. */
static void log_fmi2(Instance *inst, FmuStatus status, const char *category, const char *message)
{
    fmi2CallbackLogger logger = (fmi2CallbackLogger)inst->log_callback;
    char escaped[2048];
    size_t i, j = 0;
    if (logger == NULL) return;
    for (i = 0; message[i] != '\0' && j + 2 < sizeof escaped; i++) {
        if (message[i] == '%') escaped[j++] = '%';
        escaped[j++] = message[i];
    }
    escaped[j] = '\0';
    logger((fmi2ComponentEnvironment)inst->log_env, inst->name, (fmi2Status)status, category, escaped);
}

static Instance *as_instance(fmi2Component c) { return (Instance *)c; }

static fmi2Status check(fmi2Component c, const char *function, int modes)
{
    return (fmi2Status)fmu_check(as_instance(c), function, modes);
}

static fmi2Status check_kind(fmi2Component c, const char *function, int modes, InterfaceKind kind)
{
    Instance *inst = as_instance(c);
    if (inst == NULL) return fmi2Error;
    if (inst->kind != kind) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "%s is a %s function; this instance is %s",
                function, kind == KIND_MODEL_EXCHANGE ? "Model Exchange" : "Co-Simulation",
                inst->kind == KIND_MODEL_EXCHANGE ? "Model Exchange" : "Co-Simulation");
        return fmi2Error;
    }
    return (fmu_check(inst, function, modes) == FMU_OK) ? fmi2OK : fmi2Error;
}

/* ------------------------------------------------------------------ common functions */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }

const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    static const char *known[] = {"logStatusError", "logStatusDiscard", "logStatusWarning", "logAll"};
    Instance *inst = as_instance(c);
    size_t i, j;
    if (check(c, "fmi2SetDebugLogging", MODE_ANY) != fmi2OK) return fmi2Error;
    if (fmu_null_arg(inst, "fmi2SetDebugLogging", "categories", categories, nCategories)) return fmi2Error;
    for (i = 0; i < nCategories; i++) {
        int found = 0;
        for (j = 0; j < sizeof known / sizeof known[0]; j++)
            if (categories[i] != NULL && strcmp(categories[i], known[j]) == 0) found = 1;
        if (!found) {
            fmu_log(inst, FMU_ERROR, "logStatusError", "fmi2SetDebugLogging: unknown log category %s",
                    categories[i] ? categories[i] : "(NULL)");
            return fmi2Error;
        }
    }
    inst->logging_on = loggingOn ? 1 : 0;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    Instance *inst;
    (void)visible;
    if (functions == NULL || functions->logger == NULL) return NULL;
    if (fmuType != fmi2ModelExchange && fmuType != fmi2CoSimulation) {
        functions->logger(functions->componentEnvironment, instanceName ? instanceName : "?", fmi2Error,
                          "logStatusError", "fmi2Instantiate: unknown fmuType");
        return NULL;
    }
    inst = instance_new(&fmu_model_info, instanceName, fmuGUID, fmuResourceLocation, 2,
                        fmuType == fmi2CoSimulation ? KIND_CO_SIMULATION : KIND_MODEL_EXCHANGE,
                        loggingOn ? 1 : 0, log_fmi2, functions->componentEnvironment,
                        (void (*)(void))functions->logger);
    return (fmi2Component)inst;
}

void fmi2FreeInstance(fmi2Component c)
{
    instance_free(as_instance(c));
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    if (check(c, "fmi2SetupExperiment", MODE_INSTANTIATED) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_setup(as_instance(c), toleranceDefined, tolerance, startTime,
                                 stopTimeDefined, stopTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    if (check(c, "fmi2EnterInitializationMode", MODE_INSTANTIATED) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_enter_initialization(as_instance(c));
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    if (check(c, "fmi2ExitInitializationMode", MODE_INITIALIZATION) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_exit_initialization(as_instance(c));
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    if (check(c, "fmi2Terminate", MODE_EVENT | MODE_CONTINUOUS_TIME | MODE_STEP | MODE_STEP_FAILED) != fmi2OK)
        return fmi2Error;
    return (fmi2Status)fmu_terminate(as_instance(c));
}

fmi2Status fmi2Reset(fmi2Component c)
{
    if (check(c, "fmi2Reset", MODE_ANY) != fmi2OK) return fmi2Error;
    return (fmi2Status)instance_reset(as_instance(c));
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    if (check(c, "fmi2GetReal", ALL_GET) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_get_float64(as_instance(c), "fmi2GetReal", vr, nvr, value);
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    if (check(c, "fmi2GetInteger", ALL_GET) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_get_int(as_instance(c), "fmi2GetInteger", VARTYPE_INTEGER, vr, nvr, value);
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    if (check(c, "fmi2GetBoolean", ALL_GET) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_get_int(as_instance(c), "fmi2GetBoolean", VARTYPE_BOOLEAN, vr, nvr, value);
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    (void)value;
    if (check(c, "fmi2GetString", ALL_GET) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_no_variables(as_instance(c), "fmi2GetString", vr, nvr);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    if (check(c, "fmi2SetReal", ALL_SET) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_set_float64(as_instance(c), "fmi2SetReal", vr, nvr, value);
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    if (check(c, "fmi2SetInteger", ALL_SET) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_set_int(as_instance(c), "fmi2SetInteger", VARTYPE_INTEGER, vr, nvr, value);
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    if (check(c, "fmi2SetBoolean", ALL_SET) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_set_int(as_instance(c), "fmi2SetBoolean", VARTYPE_BOOLEAN, vr, nvr, value);
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    (void)value;
    if (check(c, "fmi2SetString", ALL_SET) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_no_variables(as_instance(c), "fmi2SetString", vr, nvr);
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    if (check(c, "fmi2GetFMUstate", STATE_MODES) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_get_state(as_instance(c), "fmi2GetFMUstate", FMUstate);
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate)
{
    if (check(c, "fmi2SetFMUstate", STATE_MODES) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_set_state(as_instance(c), "fmi2SetFMUstate", FMUstate);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate)
{
    if (check(c, "fmi2FreeFMUstate", MODE_ANY) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_free_state(as_instance(c), "fmi2FreeFMUstate", FMUstate);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size)
{
    if (check(c, "fmi2SerializedFMUstateSize", MODE_ANY) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_serialized_size(as_instance(c), "fmi2SerializedFMUstateSize", FMUstate, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[],
                                 size_t size)
{
    if (check(c, "fmi2SerializeFMUstate", MODE_ANY) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_serialize(as_instance(c), "fmi2SerializeFMUstate", FMUstate, serializedState, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate)
{
    if (check(c, "fmi2DeSerializeFMUstate", MODE_ANY) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_deserialize(as_instance(c), "fmi2DeSerializeFMUstate", serializedState, size,
                                       FMUstate);
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                        size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                        size_t nKnown, const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    if (check(c, "fmi2GetDirectionalDerivative", MODE_ANY) != fmi2OK) return fmi2Error;
    fmu_log(as_instance(c), FMU_ERROR, "logStatusError",
            "fmi2GetDirectionalDerivative is not supported (providesDirectionalDerivative=false)");
    return fmi2Error;
}

/* ------------------------------------------------------------------ model exchange */

fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    if (check_kind(c, "fmi2EnterEventMode", MODE_EVENT | MODE_CONTINUOUS_TIME, KIND_MODEL_EXCHANGE) != fmi2OK)
        return fmi2Error;
    as_instance(c)->mode = MODE_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo)
{
    Instance *inst = as_instance(c);
    if (check_kind(c, "fmi2NewDiscreteStates", MODE_EVENT, KIND_MODEL_EXCHANGE) != fmi2OK) return fmi2Error;
    if (fmu_null_arg(inst, "fmi2NewDiscreteStates", "eventInfo", eventInfo, 1)) return fmi2Error;
    eventInfo->newDiscreteStatesNeeded = fmi2False;
    eventInfo->terminateSimulation = fmi2False;
    eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    eventInfo->valuesOfContinuousStatesChanged = fmi2False;
    eventInfo->nextEventTimeDefined = fmi2False;
    eventInfo->nextEventTime = 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    if (check_kind(c, "fmi2EnterContinuousTimeMode", MODE_EVENT, KIND_MODEL_EXCHANGE) != fmi2OK) return fmi2Error;
    as_instance(c)->mode = MODE_CONTINUOUS_TIME;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    Instance *inst = as_instance(c);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (check_kind(c, "fmi2CompletedIntegratorStep", MODE_CONTINUOUS_TIME, KIND_MODEL_EXCHANGE) != fmi2OK)
        return fmi2Error;
    if (fmu_null_arg(inst, "fmi2CompletedIntegratorStep", "enterEventMode", enterEventMode, 1) ||
        fmu_null_arg(inst, "fmi2CompletedIntegratorStep", "terminateSimulation", terminateSimulation, 1))
        return fmi2Error;
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    if (check_kind(c, "fmi2SetTime", MODE_EVENT | MODE_CONTINUOUS_TIME, KIND_MODEL_EXCHANGE) != fmi2OK)
        return fmi2Error;
    return (fmi2Status)fmu_set_time(as_instance(c), "fmi2SetTime", time);
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    if (check_kind(c, "fmi2SetContinuousStates", MODE_CONTINUOUS_TIME, KIND_MODEL_EXCHANGE) != fmi2OK)
        return fmi2Error;
    return (fmi2Status)fmu_set_states(as_instance(c), "fmi2SetContinuousStates", x, nx);
}

#define ME_GET_MODES (MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS_TIME | MODE_TERMINATED | MODE_ERROR)

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx)
{
    if (check_kind(c, "fmi2GetDerivatives", ME_GET_MODES, KIND_MODEL_EXCHANGE) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_get_derivatives(as_instance(c), "fmi2GetDerivatives", derivatives, nx);
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni)
{
    Instance *inst = as_instance(c);
    (void)eventIndicators;
    if (check_kind(c, "fmi2GetEventIndicators", ME_GET_MODES, KIND_MODEL_EXCHANGE) != fmi2OK) return fmi2Error;
    if (ni != 0) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "fmi2GetEventIndicators: the model has no event "
                "indicators, got ni = %lu", (unsigned long)ni);
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    if (check_kind(c, "fmi2GetContinuousStates", ME_GET_MODES, KIND_MODEL_EXCHANGE) != fmi2OK) return fmi2Error;
    return (fmi2Status)fmu_get_states(as_instance(c), "fmi2GetContinuousStates", x, nx);
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    if (check_kind(c, "fmi2GetNominalsOfContinuousStates", ME_GET_MODES | MODE_INSTANTIATED,
                   KIND_MODEL_EXCHANGE) != fmi2OK)
        return fmi2Error;
    return (fmi2Status)fmu_get_nominals(as_instance(c), "fmi2GetNominalsOfContinuousStates", x_nominal, nx);
}

/* ------------------------------------------------------------------ co-simulation */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    if (check_kind(c, "fmi2SetRealInputDerivatives", MODE_ANY, KIND_CO_SIMULATION) != fmi2OK) return fmi2Error;
    fmu_log(as_instance(c), FMU_ERROR, "logStatusError",
            "fmi2SetRealInputDerivatives is not supported (canInterpolateInputs=false)");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr; (void)nvr; (void)order; (void)value;
    if (check_kind(c, "fmi2GetRealOutputDerivatives", MODE_ANY, KIND_CO_SIMULATION) != fmi2OK) return fmi2Error;
    fmu_log(as_instance(c), FMU_ERROR, "logStatusError",
            "fmi2GetRealOutputDerivatives is not supported (maxOutputDerivativeOrder=0)");
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    fmi2Status status;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (check_kind(c, "fmi2DoStep", MODE_STEP, KIND_CO_SIMULATION) != fmi2OK) return fmi2Error;
    status = (fmi2Status)fmu_do_step(as_instance(c), "fmi2DoStep", currentCommunicationPoint,
                                     communicationStepSize);
    if (status == fmi2OK && as_instance(c)->terminate_requested) {
        /* FMI 2 says "stop" with Discard: fmi2Terminated and fmi2LastSuccessfulTime tell the rest */
        fmu_log(as_instance(c), FMU_DISCARD, "logStatusDiscard", "fmi2DoStep: the FMU asks to end the simulation "
                "at t = %.17g (fmi2GetBooleanStatus(fmi2Terminated) is true)", as_instance(c)->time);
        return fmi2Discard;
    }
    return status;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    if (check_kind(c, "fmi2CancelStep", MODE_STEP, KIND_CO_SIMULATION) != fmi2OK) return fmi2Error;
    fmu_log(as_instance(c), FMU_ERROR, "logStatusError",
            "fmi2CancelStep: steps are synchronous, there is nothing to cancel");
    return fmi2Error;
}

#define STATUS_MODES (MODE_STEP | MODE_STEP_FAILED | MODE_TERMINATED)

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    Instance *inst = as_instance(c);
    if (check_kind(c, "fmi2GetStatus", STATUS_MODES, KIND_CO_SIMULATION) != fmi2OK) return fmi2Error;
    if (fmu_null_arg(inst, "fmi2GetStatus", "value", value, 1)) return fmi2Error;
    if (s != fmi2DoStepStatus) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "fmi2GetStatus: only fmi2DoStepStatus is supported");
        return fmi2Error;
    }
    *value = inst->mode == MODE_STEP_FAILED ? fmi2Discard : fmi2OK;
    return fmi2OK;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    Instance *inst = as_instance(c);
    if (check_kind(c, "fmi2GetRealStatus", STATUS_MODES, KIND_CO_SIMULATION) != fmi2OK) return fmi2Error;
    if (fmu_null_arg(inst, "fmi2GetRealStatus", "value", value, 1)) return fmi2Error;
    if (s != fmi2LastSuccessfulTime) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "fmi2GetRealStatus: only fmi2LastSuccessfulTime is supported");
        return fmi2Error;
    }
    *value = inst->time;
    return fmi2OK;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)s; (void)value;
    if (check_kind(c, "fmi2GetIntegerStatus", STATUS_MODES, KIND_CO_SIMULATION) != fmi2OK) return fmi2Error;
    fmu_log(as_instance(c), FMU_ERROR, "logStatusError", "fmi2GetIntegerStatus: no integer status");
    return fmi2Error;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    Instance *inst = as_instance(c);
    if (check_kind(c, "fmi2GetBooleanStatus", STATUS_MODES, KIND_CO_SIMULATION) != fmi2OK) return fmi2Error;
    if (fmu_null_arg(inst, "fmi2GetBooleanStatus", "value", value, 1)) return fmi2Error;
    if (s != fmi2Terminated) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "fmi2GetBooleanStatus: only fmi2Terminated is supported");
        return fmi2Error;
    }
    *value = inst->mode == MODE_STEP_FAILED && inst->terminate_requested ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)s; (void)value;
    if (check_kind(c, "fmi2GetStringStatus", STATUS_MODES, KIND_CO_SIMULATION) != fmi2OK) return fmi2Error;
    fmu_log(as_instance(c), FMU_ERROR, "logStatusError", "fmi2GetStringStatus: no string status");
    return fmi2Error;
}
