"""FMI 2.0 co-simulation FMUs of scenes (pythonfmu runtime).

- :mod:`overcon.fmu.build`: build one self-contained FMU per scene file (``build_fmu.py``,
  ``overcon build``), with the pre-check, modelDescription.xml and compatibility files.
- :mod:`overcon.fmu.slave`: the ``Fmi2Slave`` facade that runs inside the FMU.
- :mod:`overcon.fmu.variables`: the variable table (names, units, causality) both share.
- :mod:`overcon.fmu.description`: modelDescription.xml from that table.
- :mod:`overcon.fmu.statecodec`: exact serialization of the FMU state.

Nothing here is imported by the rest of the package; the slave needs pythonfmu (bundled in each
FMU), the builder needs pythonfmu's binaries and fmpy (validation, reference results).
"""
