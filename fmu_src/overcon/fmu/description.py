"""modelDescription.xml (FMI 2.0 or 3.0; co-simulation, Model Exchange or both) of a scene's FMU, from the variable table of
:mod:`overcon.fmu.variables` (the same table the slave registers, so value references agree).

Written directly rather than by pythonfmu's ``Fmi2Slave.to_xml``, whose output fails
``fmpy validate`` (no units, no InitialUnknowns, start values on calculated outputs, a random
GUID per build). What is written: CoSimulation capabilities (variable communication step, FMU
state get/set and serialization), UnitDefinitions with SI base-unit exponents, the log categories
of the binary, DefaultExperiment from the scene (stepSize = solver.output_interval,
tolerance = solver.tolerance), the variables, and ModelStructure (Outputs: every output, the
constant pre-check Booleans with no dependencies; InitialUnknowns: the calculated outputs,
depending on the parameters).

With Model Exchange (``kinds`` containing "me", C runtime) also the ModelExchange capabilities
(no event indicators, fmi2/3CompletedIntegratorStep needed: it asks for the event that
re-normalises quaternions) and ModelStructure's Derivatives (FMI 2.0) or ContinuousStateDerivative
(FMI 3.0) entries of the ``der(...)`` variables. FMI 3.0 (:func:`model_description` with
``fmi=3``, C runtime) writes the same variables with FMI 3.0's types (Float64, Int32, Boolean,
String), the instantiation token, the array variables (``Dimension``) and references by value
reference.
"""
from __future__ import annotations

from xml.etree import ElementTree as ET

from .variables import REDUNDANCY_ITEMS, REDUNDANCY_TYPE, UNITS, Var

LOG_CATEGORIES = {
    "logEvents": "Information (fmi2OK): initialization, tolerance used. Only with debug logging on.",
    "logStatusWarning": "Warnings (fmi2Warning): an fmi2SetupExperiment tolerance out of range, friction on a "
                        "joint without equations. Also with debug logging off, unless switched off.",
    "logStatusError": "Errors (fmi2Error): wrong-state calls, bad value references, refused values, a "
                      "step that cannot continue (with its reason). Always logged.",
    "logStatusFatal": "Fatal errors (fmi2Fatal): Python cannot be started. Always logged.",
    "logAll": "All of the above.",
}
"""The categories of native/overcon_fmi2.c (category_names, plus logAll); fmi2SetDebugLogging
switches them."""


def _num(x) -> str:
    return repr(float(x))


KINDS = ("cs", "me")
"""The interface kinds an FMU may offer: co-simulation, Model Exchange."""


def model_description(scene, table: list[Var], *, guid: str, generation_tool: str,
                      version: str = "", fmi: int = 2, kinds=("cs",), source_files=()) -> bytes:
    """The XML document (UTF-8 bytes) for ``scene`` (name, description and the default
    experiment, from its solver options) with the variables of ``table``, for FMI ``fmi`` (2 or 3)
    offering ``kinds`` (a subset of :data:`KINDS`, not empty). ``source_files``: the C files under
    the FMU's ``sources/`` (paths relative to it) listed in FMI 2.0's ``<SourceFiles>`` of each
    interface (FMI 3.0 lists them in ``sources/buildDescription.xml`` instead)."""
    if fmi not in (2, 3) or not kinds or set(kinds) - set(KINDS):
        raise ValueError(f"model_description: fmi {fmi!r}, kinds {kinds!r}: FMI 2 or 3, kinds among {KINDS}")
    if fmi == 3:
        return _fmi3(scene, table, guid=guid, generation_tool=generation_tool, version=version, kinds=kinds)
    attrib = {"fmiVersion": "2.0", "modelName": scene.name, "guid": guid}
    if scene.description:
        attrib["description"] = scene.description
    if version:
        attrib["version"] = version
    attrib.update(generationTool=generation_tool, variableNamingConvention="structured")
    if "me" in kinds:
        attrib["numberOfEventIndicators"] = "0"
    root = ET.Element("fmiModelDescription", attrib)
    if "me" in kinds:
        me = ET.SubElement(root, "ModelExchange", {
            "modelIdentifier": scene.name,
            "needsExecutionTool": "false",
            "completedIntegratorStepNotNeeded": "false",
            "canBeInstantiatedOnlyOncePerProcess": "false",
            "canNotUseMemoryManagementFunctions": "true",
            "canGetAndSetFMUstate": "true",
            "canSerializeFMUstate": "true",
            "providesDirectionalDerivative": "false",
        })
        _source_files(me, source_files)
    if "cs" in kinds:
        cs = ET.SubElement(root, "CoSimulation", {
            "modelIdentifier": scene.name,
            "needsExecutionTool": "false",  # the compiled binary alone (C11 and libm)
            "canHandleVariableCommunicationStepSize": "true",
            "canInterpolateInputs": "true" if any(v.causality == "input" for v in table) else "false",
            "maxOutputDerivativeOrder": "0",
            "canRunAsynchronuously": "false",
            "canBeInstantiatedOnlyOncePerProcess": "false",
            "canNotUseMemoryManagementFunctions": "true",
            "canGetAndSetFMUstate": "true",
            "canSerializeFMUstate": "true",
            "providesDirectionalDerivative": "false",
        })
        _source_files(cs, source_files)
    _units_categories_experiment(root, scene, table, "fmi2")
    mv = ET.SubElement(root, "ModelVariables")
    for vr, v in enumerate(table):
        if v.size != 1:
            continue  # arrays are FMI 3.0's
        sv = ET.SubElement(mv, "ScalarVariable", {
            "name": v.name, "valueReference": str(vr), "description": v.description,
            "causality": v.causality, "variability": v.variability,
            **({"initial": v.initial} if v.initial else {})})  # an input has no initial
        typ = {}
        if v.unit is not None:
            typ["unit"] = v.unit
        if v.derivative is not None:
            typ["derivative"] = str(v.derivative + 1)
        if v.start is not None:
            if v.type == "Real":
                typ["start"] = _num(v.start)
            elif v.type == "Boolean":
                typ["start"] = "true" if v.start else "false"
            else:
                typ["start"] = str(v.start)
        if v.type == "Enumeration":
            typ["declaredType"] = REDUNDANCY_TYPE
        ET.SubElement(sv, v.type, typ)
    _fmi2_structure(root, table)
    ET.indent(root)
    text = ET.tostring(root, encoding="unicode")
    return ('<?xml version="1.0" encoding="UTF-8"?>\n' + text + "\n").encode("utf-8")


def _units_categories_experiment(root, scene, table: list[Var], api: str) -> None:
    """UnitDefinitions, LogCategories (their texts naming the calls of ``api``, "fmi2" or "fmi3") and
    DefaultExperiment, the same in both FMI versions."""
    used = sorted({v.unit for v in table if v.unit is not None})
    units = ET.SubElement(root, "UnitDefinitions")
    for name in used:
        u = ET.SubElement(units, "Unit", {"name": name})
        ET.SubElement(u, "BaseUnit", {k: str(e) for k, e in UNITS[name].items()})
    if api == "fmi2" and any(v.type == "Enumeration" for v in table):  # the redundancy parameter's type
        st = ET.SubElement(ET.SubElement(root, "TypeDefinitions"), "SimpleType", {
            "name": REDUNDANCY_TYPE, "description": "how the redundant constraints are handled ([scene] redundancy)"})
        enum = ET.SubElement(st, "Enumeration")
        for value, (name, text) in enumerate(REDUNDANCY_ITEMS.items(), start=1):
            ET.SubElement(enum, "Item", {"name": name, "value": str(value), "description": text})
    cats = ET.SubElement(root, "LogCategories")
    for name, text in LOG_CATEGORIES.items():
        ET.SubElement(cats, "Category", {"name": name, "description": text.replace("fmi2", api)})
    ET.SubElement(root, "DefaultExperiment", {
        "startTime": _num(scene.start_time), "stopTime": _num(scene.stop_time),
        "tolerance": _num(scene.solver.tolerance), "stepSize": _num(scene.solver.output_interval)})


def _fmi2_structure(root, table: list[Var]) -> None:
    """FMI 2.0's ModelStructure: Outputs (constants without dependencies), Derivatives,
    InitialUnknowns (the calculated outputs and derivatives), by 1-based index."""
    ms = ET.SubElement(root, "ModelStructure")
    outputs = ET.SubElement(ms, "Outputs")
    initial = []
    states = " ".join(str(i) for i, v in enumerate(table, start=1) if v.key and v.key[0] == "state")
    for i, v in enumerate(table, start=1):
        if v.causality != "output":
            continue
        a = {"index": str(i)}
        if v.variability == "constant":
            a["dependencies"] = ""
        elif v.feedthrough is False:  # a function of the state: no direct dependency on the inputs
            a["dependencies"] = states
        ET.SubElement(outputs, "Unknown", a)
        if v.initial in ("approx", "calculated"):
            initial.append(i)
    derivatives = [i for i, v in enumerate(table, start=1) if v.derivative is not None]
    if derivatives:
        ders = ET.SubElement(ms, "Derivatives")
        for i in derivatives:
            ET.SubElement(ders, "Unknown", {"index": str(i)})
        initial = sorted(initial + derivatives)
    if initial:
        iu = ET.SubElement(ms, "InitialUnknowns")
        for i in initial:
            ET.SubElement(iu, "Unknown", {"index": str(i)})


_FMI3_TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String", "Enumeration": "Int32"}


def _source_files(interface, files) -> None:
    """FMI 2.0's ``<SourceFiles>`` of an interface element: one ``<File>`` per C file of sources/."""
    if files:
        sf = ET.SubElement(interface, "SourceFiles")
        for name in files:
            ET.SubElement(sf, "File", {"name": name})


def _fmi3(scene, table: list[Var], *, guid: str, generation_tool: str, version: str, kinds) -> bytes:
    """The FMI 3.0 document (see :func:`model_description`): value references are table positions."""
    attrib = {"fmiVersion": "3.0", "modelName": scene.name, "instantiationToken": guid}
    if scene.description:
        attrib["description"] = scene.description
    if version:
        attrib["version"] = version
    attrib.update(generationTool=generation_tool, variableNamingConvention="structured")
    root = ET.Element("fmiModelDescription", attrib)
    common = {"modelIdentifier": scene.name, "needsExecutionTool": "false",
              "canBeInstantiatedOnlyOncePerProcess": "false", "canGetAndSetFMUState": "true",
              "canSerializeFMUState": "true", "providesDirectionalDerivatives": "false",
              "providesAdjointDerivatives": "false"}
    if "me" in kinds:
        ET.SubElement(root, "ModelExchange", {**common, "needsCompletedIntegratorStep": "true"})
    if "cs" in kinds:
        ET.SubElement(root, "CoSimulation", {**common, "canHandleVariableCommunicationStepSize": "true",
                                             "maxOutputDerivativeOrder": "0", "hasEventMode": "false",
                                             "providesIntermediateUpdate": "false",
                                             "canReturnEarlyAfterIntermediateUpdate": "false"})
    _units_categories_experiment(root, scene, table, "fmi3")
    mv = ET.SubElement(root, "ModelVariables")
    for vr, v in enumerate(table):
        a = {"name": v.name, "valueReference": str(vr), "description": v.description.replace("fmi2", "fmi3"),
             "causality": v.causality, "variability": v.variability}
        if v.initial:
            a["initial"] = v.initial
        if v.unit is not None and v.type == "Real":
            a["unit"] = v.unit
        if v.derivative is not None:
            a["derivative"] = str(v.derivative)
        if v.start is not None and v.type != "String":
            a["start"] = (_num(v.start) if v.type == "Real" else ("true" if v.start else "false")
                          if v.type == "Boolean" else str(v.start))
        if v.type == "Enumeration":  # FMI 3.0 reads Enumerations through Int64 calls; the layer has Int32
            a.update(min="1", max=str(len(REDUNDANCY_ITEMS)))  # a value the scene cannot take is refused by the layer
        el = ET.SubElement(mv, _FMI3_TYPES[v.type], a)
        if v.start is not None and v.type == "String":
            ET.SubElement(el, "Start", {"value": str(v.start)})
        if v.size != 1:
            ET.SubElement(el, "Dimension", {"start": str(v.size)})
    ms = ET.SubElement(root, "ModelStructure")
    states = " ".join(str(vr) for vr, v in enumerate(table) if v.key and v.key[0] == "state")
    for vr, v in enumerate(table):
        if v.causality == "output":
            deps = "" if v.variability == "constant" else states if v.feedthrough is False else None
            ET.SubElement(ms, "Output", {"valueReference": str(vr), **({"dependencies": deps}
                                                                        if deps is not None else {})})
    for vr, v in enumerate(table):
        if v.derivative is not None:
            ET.SubElement(ms, "ContinuousStateDerivative", {"valueReference": str(vr)})
    for vr, v in enumerate(table):
        if (v.causality == "output" or v.derivative is not None) and v.initial in ("approx", "calculated"):
            ET.SubElement(ms, "InitialUnknown", {"valueReference": str(vr)})
    ET.indent(root)
    text = ET.tostring(root, encoding="unicode")
    return ('<?xml version="1.0" encoding="UTF-8"?>\n' + text + "\n").encode("utf-8")
