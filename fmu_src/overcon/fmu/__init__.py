"""FMI 2.0 and 3.0 FMUs of scenes (co-simulation and Model Exchange), without Python inside.

- :mod:`overcon.fmu.build`: build one self-contained FMU per scene file (``build_fmu.py``,
  ``overcon build``): pre-check, modelDescription.xml, the model file, the binary, compatibility
  files.
- ``native/``: the FMU binary, the FMI layer (``fmu_*.c`` shared, ``fmi2_*.c``, ``fmi3_*.c``) over
  the compiled core, compiled once when the package is installed (setup.py) and copied into every
  FMU.
- :mod:`overcon.fmu.cmodel`: the model file the binary reads (``resources/overcon_model.bin``).
- :mod:`overcon.fmu.variables`: the variable table (names, units, causality, rules).
- :mod:`overcon.fmu.description`: modelDescription.xml from that table.
- :mod:`overcon.fmu.facts`: the versioned facts record the tooling reads.
- :mod:`overcon.fmu.statecodec`: exact serialization of an in-process run's state (used by the
  Python run's tests; the FMU's state is the core's bytes, core/sim_state.c).

Nothing here is imported by the rest of the package but the build; the builder needs fmpy
(validation, reference results) and no C compiler; the FMU at run time needs nothing but libm.
"""
