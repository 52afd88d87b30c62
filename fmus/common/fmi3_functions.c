/* FMI 3.0 API (Model Exchange and Co-Simulation) over the shared instance (fmu_instance.c). */
#include <string.h>

#include "fmi3Functions.h"
#include "fmu_instance.h"

#define ALL_GET (MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS_TIME | MODE_STEP | \
                 MODE_STEP_FAILED | MODE_TERMINATED | MODE_ERROR)
#define ALL_SET (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS_TIME | MODE_STEP)
#define STATE_MODES (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS_TIME | \
                     MODE_STEP | MODE_STEP_FAILED | MODE_TERMINATED | MODE_ERROR)
#define ME_GET_MODES (MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS_TIME | MODE_TERMINATED | MODE_ERROR)

static void log_fmi3(Instance *inst, FmuStatus status, const char *category, const char *message)
{
    fmi3LogMessageCallback logger = (fmi3LogMessageCallback)inst->log_callback;
    if (logger != NULL) logger((fmi3InstanceEnvironment)inst->log_env, (fmi3Status)status, category, message);
}

static Instance *as_instance(fmi3Instance c) { return (Instance *)c; }

static fmi3Status check(fmi3Instance c, const char *function, int modes)
{
    return (fmi3Status)fmu_check(as_instance(c), function, modes);
}

static fmi3Status check_kind(fmi3Instance c, const char *function, int modes, InterfaceKind kind)
{
    Instance *inst = as_instance(c);
    if (inst == NULL) return fmi3Error;
    if (inst->kind != kind) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "%s is a %s function; this instance is %s",
                function, kind == KIND_MODEL_EXCHANGE ? "Model Exchange" : "Co-Simulation",
                inst->kind == KIND_MODEL_EXCHANGE ? "Model Exchange" : "Co-Simulation");
        return fmi3Error;
    }
    return (fmu_check(inst, function, modes) == FMU_OK) ? fmi3OK : fmi3Error;
}

static fmi3Status unsupported(fmi3Instance c, const char *function)
{
    if (check(c, function, MODE_ANY) != fmi3OK) return fmi3Error;
    fmu_log(as_instance(c), FMU_ERROR, "logStatusError", "%s is not supported by this FMU", function);
    return fmi3Error;
}

static int check_n_values(Instance *inst, const char *function, size_t nvr, size_t n_values)
{
    if (nvr != n_values) {
        fmu_log(inst, FMU_ERROR, "logStatusError",
                "%s: nValues (%lu) must equal nValueReferences (%lu) for scalar variables", function,
                (unsigned long)n_values, (unsigned long)nvr);
        return 1;
    }
    return 0;
}

/* ------------------------------------------------------------------ common functions */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[])
{
    static const char *known[] = {"logStatusError", "logStatusDiscard", "logStatusWarning", "logAll"};
    Instance *inst = as_instance(instance);
    size_t i, j;
    if (check(instance, "fmi3SetDebugLogging", MODE_ANY) != fmi3OK) return fmi3Error;
    if (fmu_null_arg(inst, "fmi3SetDebugLogging", "categories", categories, nCategories)) return fmi3Error;
    for (i = 0; i < nCategories; i++) {
        int found = 0;
        for (j = 0; j < sizeof known / sizeof known[0]; j++)
            if (categories[i] != NULL && strcmp(categories[i], known[j]) == 0) found = 1;
        if (!found) {
            fmu_log(inst, FMU_ERROR, "logStatusError", "fmi3SetDebugLogging: unknown log category %s",
                    categories[i] ? categories[i] : "(NULL)");
            return fmi3Error;
        }
    }
    inst->logging_on = loggingOn ? 1 : 0;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    (void)visible;
    return (fmi3Instance)instance_new(&fmu_model_info, instanceName, instantiationToken, resourcePath, 3,
                                      KIND_MODEL_EXCHANGE, loggingOn ? 1 : 0, log_fmi3, instanceEnvironment,
                                      (void (*)(void))logMessage);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible,
                                         fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
                                         fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    Instance *inst;
    (void)visible;
    (void)requiredIntermediateVariables;
    (void)intermediateUpdate;
    inst = instance_new(&fmu_model_info, instanceName, instantiationToken, resourcePath, 3, KIND_CO_SIMULATION,
                        loggingOn ? 1 : 0, log_fmi3, instanceEnvironment, (void (*)(void))logMessage);
    if (inst == NULL) return NULL;
    if (eventModeUsed || nRequiredIntermediateVariables > 0) {
        fmu_log(inst, FMU_ERROR, "logStatusError", "fmi3InstantiateCoSimulation: event mode and "
                "intermediate variables are not supported (hasEventMode=false)");
        instance_free(inst);
        return NULL;
    }
    inst->early_return_allowed = earlyReturnAllowed ? 1 : 0;
    return (fmi3Instance)inst;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible,
                                               fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage != NULL)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "fmi3InstantiateScheduledExecution: scheduled execution is not supported");
    (void)instanceName;
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance)
{
    instance_free(as_instance(instance));
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    fmi3Status status;
    if (check(instance, "fmi3EnterInitializationMode", MODE_INSTANTIATED) != fmi3OK) return fmi3Error;
    status = (fmi3Status)fmu_setup(as_instance(instance), toleranceDefined, tolerance, startTime,
                                   stopTimeDefined, stopTime);
    if (status != fmi3OK) return status;
    return (fmi3Status)fmu_enter_initialization(as_instance(instance));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    if (check(instance, "fmi3ExitInitializationMode", MODE_INITIALIZATION) != fmi3OK) return fmi3Error;
    return (fmi3Status)fmu_exit_initialization(as_instance(instance));
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance)
{
    if (check_kind(instance, "fmi3EnterEventMode", MODE_EVENT | MODE_CONTINUOUS_TIME, KIND_MODEL_EXCHANGE) != fmi3OK)
        return fmi3Error;
    as_instance(instance)->mode = MODE_EVENT;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance)
{
    if (check(instance, "fmi3Terminate", MODE_EVENT | MODE_CONTINUOUS_TIME | MODE_STEP | MODE_STEP_FAILED) != fmi3OK)
        return fmi3Error;
    return (fmi3Status)fmu_terminate(as_instance(instance));
}

fmi3Status fmi3Reset(fmi3Instance instance)
{
    if (check(instance, "fmi3Reset", MODE_ANY) != fmi3OK) return fmi3Error;
    return (fmi3Status)instance_reset(as_instance(instance));
}

/* ------------------------------------------------------------------ variables */

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues)
{
    if (check(instance, "fmi3GetFloat64", ALL_GET) != fmi3OK) return fmi3Error;
    if (check_n_values(as_instance(instance), "fmi3GetFloat64", nValueReferences, nValues)) return fmi3Error;
    return (fmi3Status)fmu_get_float64(as_instance(instance), "fmi3GetFloat64", valueReferences,
                                       nValueReferences, values);
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues)
{
    if (check(instance, "fmi3SetFloat64", ALL_SET) != fmi3OK) return fmi3Error;
    if (check_n_values(as_instance(instance), "fmi3SetFloat64", nValueReferences, nValues)) return fmi3Error;
    return (fmi3Status)fmu_set_float64(as_instance(instance), "fmi3SetFloat64", valueReferences,
                                       nValueReferences, values);
}

/* Int32 and Boolean variables (ModelInfo.types); values are stored as doubles. */
typedef char int32_is_int[(sizeof(fmi3Int32) == sizeof(int)) ? 1 : -1];
typedef char boolean_is_a_byte[(sizeof(fmi3Boolean) == 1) ? 1 : -1];

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Int32 values[], size_t nValues)
{
    if (check(instance, "fmi3GetInt32", ALL_GET) != fmi3OK) return fmi3Error;
    if (check_n_values(as_instance(instance), "fmi3GetInt32", nValueReferences, nValues)) return fmi3Error;
    return (fmi3Status)fmu_get_int(as_instance(instance), "fmi3GetInt32", VARTYPE_INTEGER, valueReferences,
                                   nValueReferences, (int *)values);
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Int32 values[], size_t nValues)
{
    if (check(instance, "fmi3SetInt32", ALL_SET) != fmi3OK) return fmi3Error;
    if (check_n_values(as_instance(instance), "fmi3SetInt32", nValueReferences, nValues)) return fmi3Error;
    return (fmi3Status)fmu_set_int(as_instance(instance), "fmi3SetInt32", VARTYPE_INTEGER, valueReferences,
                                   nValueReferences, (const int *)values);
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Boolean values[], size_t nValues)
{
    if (check(instance, "fmi3GetBoolean", ALL_GET) != fmi3OK) return fmi3Error;
    if (check_n_values(as_instance(instance), "fmi3GetBoolean", nValueReferences, nValues)) return fmi3Error;
    return (fmi3Status)fmu_get_bool8(as_instance(instance), "fmi3GetBoolean", valueReferences,
                                     nValueReferences, (unsigned char *)values);
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Boolean values[], size_t nValues)
{
    if (check(instance, "fmi3SetBoolean", ALL_SET) != fmi3OK) return fmi3Error;
    if (check_n_values(as_instance(instance), "fmi3SetBoolean", nValueReferences, nValues)) return fmi3Error;
    return (fmi3Status)fmu_set_bool8(as_instance(instance), "fmi3SetBoolean", valueReferences,
                                     nValueReferences, (const unsigned char *)values);
}

/* Other types: no variables; their getters and setters accept empty requests. */
#define NO_VARIABLES_GET(NAME, TYPE)                                                                  \
    fmi3Status NAME(fmi3Instance instance, const fmi3ValueReference valueReferences[],               \
                    size_t nValueReferences, TYPE values[], size_t nValues)                          \
    {                                                                                                 \
        (void)values;                                                                                 \
        (void)nValues;                                                                                \
        if (check(instance, #NAME, ALL_GET) != fmi3OK) return fmi3Error;                             \
        return (fmi3Status)fmu_no_variables(as_instance(instance), #NAME, valueReferences,           \
                                            nValueReferences);                                        \
    }
#define NO_VARIABLES_SET(NAME, TYPE)                                                                  \
    fmi3Status NAME(fmi3Instance instance, const fmi3ValueReference valueReferences[],               \
                    size_t nValueReferences, const TYPE values[], size_t nValues)                    \
    {                                                                                                 \
        (void)values;                                                                                 \
        (void)nValues;                                                                                \
        if (check(instance, #NAME, ALL_SET) != fmi3OK) return fmi3Error;                             \
        return (fmi3Status)fmu_no_variables(as_instance(instance), #NAME, valueReferences,           \
                                            nValueReferences);                                        \
    }

NO_VARIABLES_GET(fmi3GetFloat32, fmi3Float32)
NO_VARIABLES_GET(fmi3GetInt8, fmi3Int8)
NO_VARIABLES_GET(fmi3GetUInt8, fmi3UInt8)
NO_VARIABLES_GET(fmi3GetInt16, fmi3Int16)
NO_VARIABLES_GET(fmi3GetUInt16, fmi3UInt16)
NO_VARIABLES_GET(fmi3GetUInt32, fmi3UInt32)
NO_VARIABLES_GET(fmi3GetInt64, fmi3Int64)
NO_VARIABLES_GET(fmi3GetUInt64, fmi3UInt64)
NO_VARIABLES_GET(fmi3GetString, fmi3String)
NO_VARIABLES_SET(fmi3SetFloat32, fmi3Float32)
NO_VARIABLES_SET(fmi3SetInt8, fmi3Int8)
NO_VARIABLES_SET(fmi3SetUInt8, fmi3UInt8)
NO_VARIABLES_SET(fmi3SetInt16, fmi3Int16)
NO_VARIABLES_SET(fmi3SetUInt16, fmi3UInt16)
NO_VARIABLES_SET(fmi3SetUInt32, fmi3UInt32)
NO_VARIABLES_SET(fmi3SetInt64, fmi3Int64)
NO_VARIABLES_SET(fmi3SetUInt64, fmi3UInt64)
NO_VARIABLES_SET(fmi3SetString, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, size_t valueSizes[], fmi3Binary values[], size_t nValues)
{
    (void)valueSizes; (void)values; (void)nValues;
    if (check(instance, "fmi3GetBinary", ALL_GET) != fmi3OK) return fmi3Error;
    return (fmi3Status)fmu_no_variables(as_instance(instance), "fmi3GetBinary", valueReferences, nValueReferences);
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, const size_t valueSizes[], const fmi3Binary values[],
                         size_t nValues)
{
    (void)valueSizes; (void)values; (void)nValues;
    if (check(instance, "fmi3SetBinary", ALL_SET) != fmi3OK) return fmi3Error;
    return (fmi3Status)fmu_no_variables(as_instance(instance), "fmi3SetBinary", valueReferences, nValueReferences);
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Clock values[])
{
    (void)values;
    if (check(instance, "fmi3GetClock", ALL_GET) != fmi3OK) return fmi3Error;
    return (fmi3Status)fmu_no_variables(as_instance(instance), "fmi3GetClock", valueReferences, nValueReferences);
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Clock values[])
{
    (void)values;
    if (check(instance, "fmi3SetClock", ALL_SET) != fmi3OK) return fmi3Error;
    return (fmi3Status)fmu_no_variables(as_instance(instance), "fmi3SetClock", valueReferences, nValueReferences);
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies)
{
    (void)valueReference; (void)nDependencies;
    return unsupported(instance, "fmi3GetNumberOfVariableDependencies");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[], size_t nDependencies)
{
    (void)dependent; (void)elementIndicesOfDependent; (void)independents;
    (void)elementIndicesOfIndependents; (void)dependencyKinds; (void)nDependencies;
    return unsupported(instance, "fmi3GetVariableDependencies");
}

/* ------------------------------------------------------------------ FMU state */

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    if (check(instance, "fmi3GetFMUState", STATE_MODES) != fmi3OK) return fmi3Error;
    return (fmi3Status)fmu_get_state(as_instance(instance), "fmi3GetFMUState", FMUState);
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState)
{
    if (check(instance, "fmi3SetFMUState", STATE_MODES) != fmi3OK) return fmi3Error;
    return (fmi3Status)fmu_set_state(as_instance(instance), "fmi3SetFMUState", FMUState);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState)
{
    if (check(instance, "fmi3FreeFMUState", MODE_ANY) != fmi3OK) return fmi3Error;
    return (fmi3Status)fmu_free_state(as_instance(instance), "fmi3FreeFMUState", FMUState);
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size)
{
    if (check(instance, "fmi3SerializedFMUStateSize", MODE_ANY) != fmi3OK) return fmi3Error;
    return (fmi3Status)fmu_serialized_size(as_instance(instance), "fmi3SerializedFMUStateSize", FMUState, size);
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size)
{
    if (check(instance, "fmi3SerializeFMUState", MODE_ANY) != fmi3OK) return fmi3Error;
    return (fmi3Status)fmu_serialize(as_instance(instance), "fmi3SerializeFMUState", FMUState,
                                     (char *)serializedState, size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState)
{
    if (check(instance, "fmi3DeserializeFMUState", MODE_ANY) != fmi3OK) return fmi3Error;
    return (fmi3Status)fmu_deserialize(as_instance(instance), "fmi3DeserializeFMUState",
                                       (const char *)serializedState, size, FMUState);
}

/* ------------------------------------------------------------------ unsupported features */

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                        size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                        const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                        size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    return unsupported(instance, "fmi3GetDirectionalDerivative");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                    const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                    size_t nSensitivity)
{
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    return unsupported(instance, "fmi3GetAdjointDerivative");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    return unsupported(instance, "fmi3EnterConfigurationMode");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance)
{
    return unsupported(instance, "fmi3ExitConfigurationMode");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[])
{
    (void)valueReferences; (void)nValueReferences; (void)intervals; (void)qualifiers;
    return unsupported(instance, "fmi3GetIntervalDecimal");
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions; (void)qualifiers;
    return unsupported(instance, "fmi3GetIntervalFraction");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[])
{
    (void)valueReferences; (void)nValueReferences; (void)shifts;
    return unsupported(instance, "fmi3GetShiftDecimal");
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    return unsupported(instance, "fmi3GetShiftFraction");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[])
{
    (void)valueReferences; (void)nValueReferences; (void)intervals;
    return unsupported(instance, "fmi3SetIntervalDecimal");
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    return unsupported(instance, "fmi3SetIntervalFraction");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[])
{
    (void)valueReferences; (void)nValueReferences; (void)shifts;
    return unsupported(instance, "fmi3SetShiftDecimal");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[])
{
    (void)valueReferences; (void)nValueReferences; (void)counters; (void)resolutions;
    return unsupported(instance, "fmi3SetShiftFraction");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance)
{
    return unsupported(instance, "fmi3EvaluateDiscreteStates");
}

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime)
{
    (void)clockReference; (void)activationTime;
    return unsupported(instance, "fmi3ActivateModelPartition");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues)
{
    (void)valueReferences; (void)nValueReferences; (void)orders; (void)values; (void)nValues;
    return unsupported(instance, "fmi3GetOutputDerivatives");
}

/* ------------------------------------------------------------------ model exchange */

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime)
{
    if (check(instance, "fmi3UpdateDiscreteStates", MODE_EVENT) != fmi3OK) return fmi3Error;
    /* every output argument is optional (NULL allowed) */
    if (discreteStatesNeedUpdate) *discreteStatesNeedUpdate = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (nominalsOfContinuousStatesChanged) *nominalsOfContinuousStatesChanged = fmi3False;
    if (valuesOfContinuousStatesChanged) *valuesOfContinuousStatesChanged = fmi3False;
    if (nextEventTimeDefined) *nextEventTimeDefined = fmi3False;
    if (nextEventTime) *nextEventTime = 0.0;
    return fmi3OK;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance)
{
    if (check_kind(instance, "fmi3EnterContinuousTimeMode", MODE_EVENT, KIND_MODEL_EXCHANGE) != fmi3OK)
        return fmi3Error;
    as_instance(instance)->mode = MODE_CONTINUOUS_TIME;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation)
{
    Instance *inst = as_instance(instance);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (check_kind(instance, "fmi3CompletedIntegratorStep", MODE_CONTINUOUS_TIME, KIND_MODEL_EXCHANGE) != fmi3OK)
        return fmi3Error;
    if (fmu_null_arg(inst, "fmi3CompletedIntegratorStep", "enterEventMode", enterEventMode, 1) ||
        fmu_null_arg(inst, "fmi3CompletedIntegratorStep", "terminateSimulation", terminateSimulation, 1))
        return fmi3Error;
    *enterEventMode = fmi3False;
    *terminateSimulation = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time)
{
    if (check_kind(instance, "fmi3SetTime", MODE_EVENT | MODE_CONTINUOUS_TIME, KIND_MODEL_EXCHANGE) != fmi3OK)
        return fmi3Error;
    return (fmi3Status)fmu_set_time(as_instance(instance), "fmi3SetTime", time);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    if (check_kind(instance, "fmi3SetContinuousStates", MODE_CONTINUOUS_TIME, KIND_MODEL_EXCHANGE) != fmi3OK)
        return fmi3Error;
    return (fmi3Status)fmu_set_states(as_instance(instance), "fmi3SetContinuousStates", continuousStates,
                                      nContinuousStates);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates)
{
    if (check_kind(instance, "fmi3GetContinuousStateDerivatives", ME_GET_MODES, KIND_MODEL_EXCHANGE) != fmi3OK)
        return fmi3Error;
    return (fmi3Status)fmu_get_derivatives(as_instance(instance), "fmi3GetContinuousStateDerivatives",
                                           derivatives, nContinuousStates);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators)
{
    (void)eventIndicators;
    if (check_kind(instance, "fmi3GetEventIndicators", ME_GET_MODES, KIND_MODEL_EXCHANGE) != fmi3OK)
        return fmi3Error;
    if (nEventIndicators != 0) {
        fmu_log(as_instance(instance), FMU_ERROR, "logStatusError",
                "fmi3GetEventIndicators: the model has no event indicators, got %lu",
                (unsigned long)nEventIndicators);
        return fmi3Error;
    }
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates)
{
    if (check_kind(instance, "fmi3GetContinuousStates", ME_GET_MODES | MODE_INSTANTIATED,
                   KIND_MODEL_EXCHANGE) != fmi3OK)
        return fmi3Error;
    return (fmi3Status)fmu_get_states(as_instance(instance), "fmi3GetContinuousStates", continuousStates,
                                      nContinuousStates);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates)
{
    if (check_kind(instance, "fmi3GetNominalsOfContinuousStates", ME_GET_MODES | MODE_INSTANTIATED,
                   KIND_MODEL_EXCHANGE) != fmi3OK)
        return fmi3Error;
    return (fmi3Status)fmu_get_nominals(as_instance(instance), "fmi3GetNominalsOfContinuousStates", nominals,
                                        nContinuousStates);
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators)
{
    if (check(instance, "fmi3GetNumberOfEventIndicators", MODE_ANY) != fmi3OK) return fmi3Error;
    if (fmu_null_arg(as_instance(instance), "fmi3GetNumberOfEventIndicators", "nEventIndicators",
                     nEventIndicators, 1))
        return fmi3Error;
    *nEventIndicators = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates)
{
    if (check(instance, "fmi3GetNumberOfContinuousStates", MODE_ANY) != fmi3OK) return fmi3Error;
    if (fmu_null_arg(as_instance(instance), "fmi3GetNumberOfContinuousStates", "nContinuousStates",
                     nContinuousStates, 1))
        return fmi3Error;
    *nContinuousStates = as_instance(instance)->model->n_states;
    return fmi3OK;
}

/* ------------------------------------------------------------------ co-simulation */

fmi3Status fmi3EnterStepMode(fmi3Instance instance)
{
    if (check_kind(instance, "fmi3EnterStepMode", MODE_EVENT, KIND_CO_SIMULATION) != fmi3OK) return fmi3Error;
    as_instance(instance)->mode = MODE_STEP;
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    Instance *inst = as_instance(instance);
    fmi3Status status;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (check_kind(instance, "fmi3DoStep", MODE_STEP, KIND_CO_SIMULATION) != fmi3OK) return fmi3Error;
    if (fmu_null_arg(inst, "fmi3DoStep", "eventHandlingNeeded", eventHandlingNeeded, 1) ||
        fmu_null_arg(inst, "fmi3DoStep", "terminateSimulation", terminateSimulation, 1) ||
        fmu_null_arg(inst, "fmi3DoStep", "earlyReturn", earlyReturn, 1) ||
        fmu_null_arg(inst, "fmi3DoStep", "lastSuccessfulTime", lastSuccessfulTime, 1))
        return fmi3Error;
    status = (fmi3Status)fmu_do_step(inst, "fmi3DoStep", currentCommunicationPoint, communicationStepSize);
    *eventHandlingNeeded = fmi3False;
    /* a request to end the simulation (the instance then accepts terminate, reset, free and gets):
     * terminateSimulation, lastSuccessfulTime the time reached, and earlyReturn when the step ended
     * before its end and the importer allows early returns */
    *terminateSimulation = status == fmi3OK && inst->terminate_requested ? fmi3True : fmi3False;
    *earlyReturn = *terminateSimulation && inst->early_return_allowed &&
                           inst->time < currentCommunicationPoint + communicationStepSize
                       ? fmi3True : fmi3False;
    *lastSuccessfulTime = inst->time;
    return status;
}
