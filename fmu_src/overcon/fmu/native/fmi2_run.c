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
    char a[40], b[40];
    fmu_repr(startTime, a, sizeof a);
    fmu_repr(stopTime, b, sizeof b);
    if (!isfinite(startTime)) {
        fmu_log(c, fmi2Error, "fmi2SetupExperiment: start time %s refused (not finite)", a);
        return fmi2Error;
    }
    if (stopTimeDefined && !(stopTime >= startTime)) {
        fmu_log(c, fmi2Error, "fmi2SetupExperiment: stop time %s is before the start time %s", b, a);
        return fmi2Error;
    }
    c->start_time = startTime;
    c->sim_valid = c->have_outputs = 0;
    return toleranceDefined ? fmu_host_tolerance(c, "fmi2SetupExperiment", tolerance) : fmi2OK;
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
    if (!c || !fmu_allowed(c, "fmi2Terminate", M_STEPPING | M_ERROR)) return fmi2Error;
    c->mode = M_TERMINATED;
    return fmi2OK;
}
