/* The FMI 2.0 Model Exchange functions of an overcon FMU without Python, over fmu_me.c: the
 * continuous states y = [q, h], their derivatives, no event indicators, the event mode that
 * re-normalises quaternions (fmu_me.c says why and when). */
#include "fmu_common.h"

#define EVENT_OR_CONTINUOUS (M_EVENT | M_CONTINUOUS)

FMU_EXPORT fmi2Status fmi2SetTime(fmi2Component comp, fmi2Real time) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2SetTime", EVENT_OR_CONTINUOUS)) return fmi2Error;
    return fmu_me_set_time(c, "fmi2SetTime", time);
}

FMU_EXPORT fmi2Status fmi2SetContinuousStates(fmi2Component comp, const fmi2Real x[], size_t nx) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2SetContinuousStates", EVENT_OR_CONTINUOUS)) return fmi2Error;
    return fmu_me_set_states(c, "fmi2SetContinuousStates", x, nx);
}

FMU_EXPORT fmi2Status fmi2GetContinuousStates(fmi2Component comp, fmi2Real x[], size_t nx) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2GetContinuousStates", FMU_READABLE(c))) return fmi2Error;
    return fmu_me_get_states(c, "fmi2GetContinuousStates", x, nx);
}

FMU_EXPORT fmi2Status fmi2GetDerivatives(fmi2Component comp, fmi2Real derivatives[], size_t nx) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2GetDerivatives", FMU_READABLE(c))) return fmi2Error;
    return fmu_me_get_derivatives(c, "fmi2GetDerivatives", derivatives, nx);
}

FMU_EXPORT fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component comp, fmi2Real x_nominal[], size_t nx) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2GetNominalsOfContinuousStates", FMU_ANY_MODE(c))) return fmi2Error;
    return fmu_me_get_nominals(c, "fmi2GetNominalsOfContinuousStates", x_nominal, nx);
}

FMU_EXPORT fmi2Status fmi2GetEventIndicators(fmi2Component comp, fmi2Real eventIndicators[], size_t ni) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2GetEventIndicators", FMU_READABLE(c))) return fmi2Error;
    return fmu_me_event_indicators(c, "fmi2GetEventIndicators", eventIndicators, ni);
}

FMU_EXPORT fmi2Status fmi2EnterEventMode(fmi2Component comp) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2EnterEventMode", EVENT_OR_CONTINUOUS)) return fmi2Error;
    c->mode = M_EVENT;
    return fmi2OK;
}

FMU_EXPORT fmi2Status fmi2NewDiscreteStates(fmi2Component comp, fmi2EventInfo *info) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2NewDiscreteStates", M_EVENT)) return fmi2Error;
    if (!info) return fmu_log(c, fmi2Error, "fmi2NewDiscreteStates: fmi2eventInfo is NULL"), fmi2Error;
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmu_me_correct(c) ? fmi2True : fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    return fmi2OK;
}

FMU_EXPORT fmi2Status fmi2EnterContinuousTimeMode(fmi2Component comp) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2EnterContinuousTimeMode", M_EVENT)) return fmi2Error;
    c->mode = M_CONTINUOUS;
    return fmi2OK;
}

FMU_EXPORT fmi2Status fmi2CompletedIntegratorStep(fmi2Component comp, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                                  fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2CompletedIntegratorStep", M_CONTINUOUS)) return fmi2Error;
    if (!enterEventMode || !terminateSimulation)
        return fmu_log(c, fmi2Error, "fmi2CompletedIntegratorStep: enterEventMode or terminateSimulation is NULL"),
               fmi2Error;
    *enterEventMode = fmu_me_needs_correction(c) ? fmi2True : fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}
