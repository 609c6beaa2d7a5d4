/* The FMI 2.0 instance functions of an overcon FMU without Python (see fmu_common.h): version,
 * instantiate, free, debug logging, over the shared instance code of fmu_inst.c. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_common.h"

FMU_EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
FMU_EXPORT const char *fmi2GetVersion(void) { return "2.0"; }

FMU_EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String guid,
                                         fmi2String resourceLocation, const fmi2CallbackFunctions *functions,
                                         fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)visible;
    fmu_inst tmp = {0};
    tmp.name = (char *)(instanceName ? instanceName : "");
    if (functions) tmp.logger = functions->logger, tmp.env = functions->componentEnvironment;
    fmu_default_categories(&tmp, loggingOn);
    char resources[4096];
    if (!instanceName || !instanceName[0]) {
        fmu_log(&tmp, fmi2Error, "fmi2Instantiate: instanceName is empty");
        return NULL;
    }
    if (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange) {
        fmu_log(&tmp, fmi2Error, "fmi2Instantiate: fmuType %d is neither fmi2ModelExchange nor fmi2CoSimulation",
                fmuType);
        return NULL;
    }
    tmp.me = fmuType == fmi2ModelExchange;
    if (!resourceLocation || !fmu_resource_dir(resourceLocation, resources, sizeof resources)) {
        fmu_log(&tmp, fmi2Error, "fmi2Instantiate: fmuResourceLocation %s is not a file: URI of the FMU's resources "
                "folder", resourceLocation ? resourceLocation : "(NULL)");
        return NULL;
    }
    fmu_inst *c = fmu_instantiate(&tmp, "fmi2Instantiate", resources, guid, loggingOn);
    if (c && c->me && !c->fm.me) {
        fmu_log(c, fmi2Error, "fmi2Instantiate: this FMU supports co-simulation only (built with --kind cs; overcon "
                "build --kind me or both offers Model Exchange)");
        fmu_free_inst(c);
        return NULL;
    }
    return c;
}

FMU_EXPORT void fmi2FreeInstance(fmi2Component comp) {
    fmu_inst *c = fmu_checked(comp, "fmi2FreeInstance");
    if (c) fmu_free_inst(c);
}

FMU_EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t nCategories,
                                          const fmi2String categories[]) {
    fmu_inst *c = fmu_checked(comp, "fmi2SetDebugLogging");
    if (!c) return fmi2Error;
    return fmu_set_debug_logging(c, "fmi2SetDebugLogging", loggingOn, nCategories, categories) ? fmi2OK : fmi2Error;
}
