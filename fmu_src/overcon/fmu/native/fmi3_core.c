/* The FMI 3.0 functions of an overcon FMU without Python, co-simulation and Model Exchange, over the
 * code the FMI versions share (fmu_*.c, see fmu_common.h): instances, initialization (the
 * tolerance rule of fmi2SetupExperiment applies to fmi3EnterInitializationMode's tolerance),
 * fmi3DoStep, the Model Exchange calls (fmu_me.c), reset and termination. Co-simulation has no event
 * mode and no intermediate update; there are no clocks (fmi3InstantiateScheduledExecution returns
 * NULL). Statuses, messages and log categories are the FMI 2.0 layer's, with fmi3 names. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_common.h"

#define EVENT_OR_CONTINUOUS (M_EVENT | M_CONTINUOUS)

FMU_EXPORT const char *fmi3GetVersion(void) { return "3.0"; }

FMU_EXPORT fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                                          const fmi3String categories[]) {
    fmu_inst *c = fmu_checked(instance, "fmi3SetDebugLogging");
    if (!c) return fmi3Error;
    return fmu_set_debug_logging(c, "fmi3SetDebugLogging", loggingOn, nCategories, categories) ? fmi3OK : fmi3Error;
}

/* An instance of either kind; resourcePath is a directory path (FMI 3.0), a file: URI accepted too. */
static fmu_inst *instantiate(const char *fn, int me, fmi3String instanceName, fmi3String instantiationToken,
                             fmi3String resourcePath, fmi3Boolean loggingOn, fmi3InstanceEnvironment env,
                             fmi3LogMessageCallback logMessage) {
    fmu_inst tmp = {0};
    tmp.name = (char *)(instanceName ? instanceName : "");
    tmp.log3 = logMessage, tmp.env = env, tmp.fmi3 = 1, tmp.me = me;
    fmu_default_categories(&tmp, loggingOn);
    char resources[4096];
    if (!instanceName || !instanceName[0]) {
        fmu_log(&tmp, fmi2Error, "%s: instanceName is empty", fn);
        return NULL;
    }
    if (!resourcePath || !fmu_resource_dir(resourcePath, resources, sizeof resources)) {
        fmu_log(&tmp, fmi2Error, "%s: resourcePath %s is not the absolute path of the FMU's resources folder", fn,
                resourcePath ? resourcePath : "(NULL)");
        return NULL;
    }
    fmu_inst *c = fmu_instantiate(&tmp, fn, resources, instantiationToken, loggingOn);
    if (c && me && !c->fm.me) {
        fmu_log(c, fmi2Error, "%s: this FMU supports co-simulation only (built with --kind cs; overcon build --kind me "
                "or both offers Model Exchange)", fn);
        fmu_free_inst(c);
        return NULL;
    }
    return c;
}

FMU_EXPORT fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                                     fmi3String resourcePath, fmi3Boolean visible,
                                                     fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                                     fmi3LogMessageCallback logMessage) {
    (void)visible;
    return instantiate("fmi3InstantiateModelExchange", 1, instanceName, instantiationToken, resourcePath, loggingOn,
                       instanceEnvironment, logMessage);
}

FMU_EXPORT fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath, fmi3Boolean visible,
    fmi3Boolean loggingOn, fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
    const fmi3ValueReference requiredIntermediateVariables[], size_t nRequiredIntermediateVariables,
    fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage,
    fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)visible, (void)earlyReturnAllowed, (void)requiredIntermediateVariables, (void)intermediateUpdate;
    fmu_inst *c = instantiate("fmi3InstantiateCoSimulation", 0, instanceName, instantiationToken, resourcePath,
                              loggingOn, instanceEnvironment, logMessage);
    if (c && (eventModeUsed || nRequiredIntermediateVariables)) {
        fmu_log(c, fmi2Error, "fmi3InstantiateCoSimulation: %s is not supported by this FMU (hasEventMode and "
                "providesIntermediateUpdate are false)", eventModeUsed ? "eventModeUsed" : "intermediate variables");
        fmu_free_inst(c);
        return NULL;
    }
    return c;
}

FMU_EXPORT fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath, fmi3Boolean visible,
    fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage,
    fmi3ClockUpdateCallback clockUpdate, fmi3LockPreemptionCallback lockPreemption,
    fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instantiationToken, (void)resourcePath, (void)visible, (void)clockUpdate, (void)lockPreemption,
        (void)unlockPreemption;
    fmu_inst tmp = {0};
    tmp.name = (char *)(instanceName ? instanceName : "");
    tmp.log3 = logMessage, tmp.env = instanceEnvironment, tmp.fmi3 = 1;
    fmu_default_categories(&tmp, loggingOn);
    fmu_log(&tmp, fmi2Error, "fmi3InstantiateScheduledExecution: this FMU offers co-simulation and Model Exchange "
            "only (no clocks)");
    return NULL;
}

FMU_EXPORT void fmi3FreeInstance(fmi3Instance instance) {
    fmu_inst *c = fmu_checked(instance, "fmi3FreeInstance");
    if (c) fmu_free_inst(c);
}

FMU_EXPORT fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                                  fmi3Float64 tolerance, fmi3Float64 startTime,
                                                  fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3EnterInitializationMode", M_INSTANTIATED)) return fmi3Error;
    fmi2Status s = fmu_setup(c, "fmi3EnterInitializationMode", toleranceDefined, tolerance, startTime,
                             stopTimeDefined, stopTime);
    if (s <= fmi2Warning) c->mode = M_INITIALIZATION;
    return (fmi3Status)s;
}

FMU_EXPORT fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3ExitInitializationMode", M_INITIALIZATION)) return fmi3Error;
    return (fmi3Status)fmu_exit_init(c, "fmi3ExitInitializationMode");
}

FMU_EXPORT fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3EnterEventMode", c->me ? EVENT_OR_CONTINUOUS : 0)) return fmi3Error;
    c->mode = M_EVENT;
    return fmi3OK;
}

FMU_EXPORT fmi3Status fmi3Terminate(fmi3Instance instance) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3Terminate", FMU_RUNNING(c) | M_ERROR)) return fmi3Error;
    c->mode = M_TERMINATED;
    return fmi3OK;
}

FMU_EXPORT fmi3Status fmi3Reset(fmi3Instance instance) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3Reset", FMU_ANY_MODE(c))) return fmi3Error;
    fmu_init_fields(c);
    return fmi3OK;
}

FMU_EXPORT fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    fmu_inst *c = instance;
    if (!c) return fmi3Error;
    fmu_log(c, fmi2Error, "fmi3EnterStepMode: this FMU has no event mode in co-simulation (it is in step mode after "
            "fmi3ExitInitializationMode)");
    return fmi3Error;
}

FMU_EXPORT fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                                 fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                 fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                                 fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    (void)noSetFMUStatePriorToCurrentPoint;
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3DoStep", M_STEPPING)) return fmi3Error;
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime)
        return fmu_log(c, fmi2Error, "fmi3DoStep: an output argument (eventHandlingNeeded, terminateSimulation, "
                       "earlyReturn, lastSuccessfulTime) is NULL"), fmi3Error;
    fmi2Status s = fmu_do_step(c, "fmi3DoStep", currentCommunicationPoint, communicationStepSize);
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = s != fmi2OK;
    *earlyReturn = fmi3False;
    *lastSuccessfulTime = c->t;
    return (fmi3Status)s;
}

/* Model Exchange (fmu_me.c) */

FMU_EXPORT fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3EnterContinuousTimeMode", M_EVENT)) return fmi3Error;
    c->mode = M_CONTINUOUS;
    return fmi3OK;
}

FMU_EXPORT fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                               fmi3Boolean *terminateSimulation,
                                               fmi3Boolean *nominalsOfContinuousStatesChanged,
                                               fmi3Boolean *valuesOfContinuousStatesChanged,
                                               fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3UpdateDiscreteStates", M_EVENT)) return fmi3Error;
    if (!discreteStatesNeedUpdate || !terminateSimulation || !nominalsOfContinuousStatesChanged ||
        !valuesOfContinuousStatesChanged || !nextEventTimeDefined || !nextEventTime)
        return fmu_log(c, fmi2Error, "fmi3UpdateDiscreteStates: an output argument is NULL"), fmi3Error;
    *discreteStatesNeedUpdate = fmi3False;
    *terminateSimulation = fmi3False;
    *nominalsOfContinuousStatesChanged = fmi3False;
    *valuesOfContinuousStatesChanged = fmu_me_correct(c) ? fmi3True : fmi3False;
    *nextEventTimeDefined = fmi3False;
    *nextEventTime = 0.0;
    return fmi3OK;
}

FMU_EXPORT fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                                  fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3CompletedIntegratorStep", M_CONTINUOUS)) return fmi3Error;
    if (!enterEventMode || !terminateSimulation)
        return fmu_log(c, fmi2Error, "fmi3CompletedIntegratorStep: enterEventMode or terminateSimulation is NULL"),
               fmi3Error;
    *enterEventMode = fmu_me_needs_correction(c) ? fmi3True : fmi3False;
    *terminateSimulation = fmi3False;
    return fmi3OK;
}

FMU_EXPORT fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3SetTime", EVENT_OR_CONTINUOUS)) return fmi3Error;
    return (fmi3Status)fmu_me_set_time(c, "fmi3SetTime", time);
}

FMU_EXPORT fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                              size_t nContinuousStates) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3SetContinuousStates", EVENT_OR_CONTINUOUS)) return fmi3Error;
    return (fmi3Status)fmu_me_set_states(c, "fmi3SetContinuousStates", continuousStates, nContinuousStates);
}

FMU_EXPORT fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                              size_t nContinuousStates) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3GetContinuousStates", FMU_READABLE(c))) return fmi3Error;
    return (fmi3Status)fmu_me_get_states(c, "fmi3GetContinuousStates", continuousStates, nContinuousStates);
}

FMU_EXPORT fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                                        size_t nContinuousStates) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3GetContinuousStateDerivatives", FMU_READABLE(c))) return fmi3Error;
    return (fmi3Status)fmu_me_get_derivatives(c, "fmi3GetContinuousStateDerivatives", derivatives, nContinuousStates);
}

FMU_EXPORT fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                                        size_t nContinuousStates) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3GetNominalsOfContinuousStates", FMU_ANY_MODE(c))) return fmi3Error;
    return (fmi3Status)fmu_me_get_nominals(c, "fmi3GetNominalsOfContinuousStates", nominals, nContinuousStates);
}

FMU_EXPORT fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[],
                                             size_t nEventIndicators) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3GetEventIndicators", FMU_READABLE(c))) return fmi3Error;
    return (fmi3Status)fmu_me_event_indicators(c, "fmi3GetEventIndicators", eventIndicators, nEventIndicators);
}

FMU_EXPORT fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    fmu_inst *c = instance;
    if (!c) return fmi3Error;
    if (!nContinuousStates) return fmu_log(c, fmi2Error, "fmi3GetNumberOfContinuousStates: argument is NULL"), fmi3Error;
    *nContinuousStates = c->fm.me ? (size_t)c->fm.ny : 0;
    return fmi3OK;
}

FMU_EXPORT fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    fmu_inst *c = instance;
    if (!c) return fmi3Error;
    if (!nEventIndicators) return fmu_log(c, fmi2Error, "fmi3GetNumberOfEventIndicators: argument is NULL"), fmi3Error;
    *nEventIndicators = 0;
    return fmi3OK;
}
