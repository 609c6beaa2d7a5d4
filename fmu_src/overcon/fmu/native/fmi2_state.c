/* The FMI 2.0 FMU state functions (fmi2GetFMUstate ... fmi2DeSerializeFMUstate) of an overcon FMU
 * without Python, over the shared state code of fmu_state.c. */
#include "fmu_common.h"


FMU_EXPORT fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *state) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2GetFMUstate", FMU_ANY_MODE(c))) return fmi2Error;
    return fmu_state_get(c, "fmi2GetFMUstate", state);
}

FMU_EXPORT fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate state) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2SetFMUstate", FMU_ANY_MODE(c))) return fmi2Error;
    return fmu_state_set(c, "fmi2SetFMUstate", state);
}

FMU_EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *state) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2FreeFMUstate", FMU_ANY_MODE(c))) return fmi2Error;
    return fmu_state_free(c, "fmi2FreeFMUstate", state);
}

FMU_EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate state, size_t *size) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2SerializedFMUstateSize", FMU_ANY_MODE(c))) return fmi2Error;
    return fmu_state_size(c, "fmi2SerializedFMUstateSize", state, size);
}

FMU_EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2SerializeFMUstate", FMU_ANY_MODE(c))) return fmi2Error;
    return fmu_state_serialize(c, "fmi2SerializeFMUstate", state, bytes, size);
}

FMU_EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte bytes[], size_t size,
                                              fmi2FMUstate *state) {
    fmu_inst *c = comp;
    if (!c || !fmu_allowed(c, "fmi2DeSerializeFMUstate", FMU_ANY_MODE(c))) return fmi2Error;
    return fmu_state_deserialize(c, "fmi2DeSerializeFMUstate", bytes, size, state);
}
