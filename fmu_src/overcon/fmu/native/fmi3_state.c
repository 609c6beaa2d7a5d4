/* The FMI 3.0 FMU state functions (fmi3GetFMUState ... fmi3DeserializeFMUState) of an overcon FMU
 * without Python, over the shared state code of fmu_state.c (the same bytes as FMI 2.0's). */
#include "fmu_common.h"

FMU_EXPORT fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3GetFMUState", FMU_ANY_MODE(c))) return fmi3Error;
    return (fmi3Status)fmu_state_get(c, "fmi3GetFMUState", FMUState);
}

FMU_EXPORT fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3SetFMUState", FMU_ANY_MODE(c))) return fmi3Error;
    return (fmi3Status)fmu_state_set(c, "fmi3SetFMUState", FMUState);
}

FMU_EXPORT fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3FreeFMUState", FMU_ANY_MODE(c))) return fmi3Error;
    return (fmi3Status)fmu_state_free(c, "fmi3FreeFMUState", FMUState);
}

FMU_EXPORT fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3SerializedFMUStateSize", FMU_ANY_MODE(c))) return fmi3Error;
    return (fmi3Status)fmu_state_size(c, "fmi3SerializedFMUStateSize", FMUState, size);
}

FMU_EXPORT fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                            size_t size) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3SerializeFMUState", FMU_ANY_MODE(c))) return fmi3Error;
    return (fmi3Status)fmu_state_serialize(c, "fmi3SerializeFMUState", FMUState, (fmi2Byte *)serializedState, size);
}

FMU_EXPORT fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                              fmi3FMUState *FMUState) {
    fmu_inst *c = instance;
    if (!c || !fmu_allowed(c, "fmi3DeserializeFMUState", FMU_ANY_MODE(c))) return fmi3Error;
    return (fmi3Status)fmu_state_deserialize(c, "fmi3DeserializeFMUState", (const fmi2Byte *)serializedState, size,
                                             FMUState);
}
