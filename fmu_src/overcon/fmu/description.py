"""modelDescription.xml (FMI 2.0 co-simulation) of a scene's FMU, from the variable table of
:mod:`overcon.fmu.variables` (the same table the slave registers, so value references agree).

Written directly rather than by pythonfmu's ``Fmi2Slave.to_xml``, whose output fails
``fmpy validate`` (no units, no InitialUnknowns, start values on calculated outputs, a random
GUID per build). What is written: CoSimulation capabilities (variable communication step, FMU
state get/set and serialization), UnitDefinitions with SI base-unit exponents, the log categories
of the binary, DefaultExperiment from the scene (stepSize = solver.output_interval,
tolerance = solver.tolerance), the variables, and ModelStructure (Outputs: every output, the
constant pre-check Booleans with no dependencies; InitialUnknowns: the calculated outputs,
depending on the parameters).
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


def model_description(scene, table: list[Var], *, guid: str, generation_tool: str,
                      version: str = "") -> bytes:
    """The XML document (UTF-8 bytes) for ``scene`` (name, description and the default
    experiment, from its solver options) with the variables of ``table``."""
    attrib = {"fmiVersion": "2.0", "modelName": scene.name, "guid": guid}
    if scene.description:
        attrib["description"] = scene.description
    if version:
        attrib["version"] = version
    attrib.update(generationTool=generation_tool, variableNamingConvention="structured")
    root = ET.Element("fmiModelDescription", attrib)
    ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": scene.name,
        "needsExecutionTool": "true",  # a Python interpreter with numpy and scipy
        "canHandleVariableCommunicationStepSize": "true",
        "canInterpolateInputs": "false",
        "maxOutputDerivativeOrder": "0",
        "canRunAsynchronuously": "false",
        "canBeInstantiatedOnlyOncePerProcess": "false",
        "canNotUseMemoryManagementFunctions": "true",
        "canGetAndSetFMUstate": "true",
        "canSerializeFMUstate": "true",
        "providesDirectionalDerivative": "false",
    })
    used = sorted({v.unit for v in table if v.unit is not None})
    units = ET.SubElement(root, "UnitDefinitions")
    for name in used:
        u = ET.SubElement(units, "Unit", {"name": name})
        ET.SubElement(u, "BaseUnit", {k: str(e) for k, e in UNITS[name].items()})
    if any(v.type == "Enumeration" for v in table):  # the redundancy parameter's type
        st = ET.SubElement(ET.SubElement(root, "TypeDefinitions"), "SimpleType", {
            "name": REDUNDANCY_TYPE, "description": "how the redundant constraints are handled ([scene] redundancy)"})
        enum = ET.SubElement(st, "Enumeration")
        for value, (name, text) in enumerate(REDUNDANCY_ITEMS.items(), start=1):
            ET.SubElement(enum, "Item", {"name": name, "value": str(value), "description": text})
    cats = ET.SubElement(root, "LogCategories")
    for name, text in LOG_CATEGORIES.items():
        ET.SubElement(cats, "Category", {"name": name, "description": text})
    ET.SubElement(root, "DefaultExperiment", {
        "startTime": _num(scene.start_time), "stopTime": _num(scene.stop_time),
        "tolerance": _num(scene.solver.tolerance), "stepSize": _num(scene.solver.output_interval)})
    mv = ET.SubElement(root, "ModelVariables")
    for vr, v in enumerate(table):
        sv = ET.SubElement(mv, "ScalarVariable", {
            "name": v.name, "valueReference": str(vr), "description": v.description,
            "causality": v.causality, "variability": v.variability, "initial": v.initial})
        typ = {}
        if v.unit is not None:
            typ["unit"] = v.unit
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
    ms = ET.SubElement(root, "ModelStructure")
    outputs = ET.SubElement(ms, "Outputs")
    initial = []
    for i, v in enumerate(table, start=1):
        if v.causality != "output":
            continue
        a = {"index": str(i)}
        if v.variability == "constant":
            a["dependencies"] = ""
        ET.SubElement(outputs, "Unknown", a)
        if v.initial in ("approx", "calculated"):
            initial.append(i)
    if initial:
        iu = ET.SubElement(ms, "InitialUnknowns")
        for i in initial:
            ET.SubElement(iu, "Unknown", {"index": str(i)})
    ET.indent(root)
    text = ET.tostring(root, encoding="unicode")
    return ('<?xml version="1.0" encoding="UTF-8"?>\n' + text + "\n").encode("utf-8")
