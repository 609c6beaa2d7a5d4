/* The FMI 2.0 run functions of an overcon FMU without Python: fmi2SetupExperiment (its tolerance
 * rule), initialization, fmi2DoStep, fmi2Terminate, over the shared run code of fmu_run.c. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_common.h"

FMU_EXPORT fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                                          fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    fmu_inst *c = comp;
    if (!c) return fmi2Error;
    if (!fmu_allowed(c, "fmi2SetupExperiment", M_INSTANTIATED)) return fmi2Error;
    return fmu_setup(c, "fmi2SetupExperiment", toleranceDefined, tolerance, startTime, stopTimeDefined, stopTime);
}

FMU_EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2EnterInitializationMode", M_INSTANTIATED)) return fmi2Error;
    c->mode = M_INITIALIZATION;
    return fmi2OK;
}

FMU_EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2ExitInitializationMode", M_INITIALIZATION)) return fmi2Error;
    return fmu_exit_init(c, "fmi2ExitInitializationMode");
}

FMU_EXPORT fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real currentCommunicationPoint,
                                 fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    (void)noSetFMUStatePriorToCurrentPoint;
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2DoStep", M_STEPPING)) return fmi2Error;
    return fmu_do_step(c, "fmi2DoStep", currentCommunicationPoint, communicationStepSize);
}

FMU_EXPORT fmi2Status fmi2Terminate(fmi2Component comp) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2Terminate", FMU_RUNNING(c) | M_ERROR)) return fmi2Error;
    c->mode = M_TERMINATED;
    return fmi2OK;
}
