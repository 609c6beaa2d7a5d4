"""FMI 2.0 co-simulation FMUs of scenes.

- :mod:`overcon.fmu.build`: build one self-contained FMU per scene file (``build_fmu.py``,
  ``overcon build``): pre-check, modelDescription.xml, the compiled binary, compatibility files.
- ``native/overcon_fmi2.c``: the FMU binary; starts or joins a Python interpreter and forwards
  every FMI call to the slave.
- :mod:`overcon.fmu.boot`: the binary's entry into Python (sys.path, then the slave).
- :mod:`overcon.fmu.pyinfo`: the interpreter facts the binary needs (libpython, site-packages).
- :mod:`overcon.fmu.slave`: the slave that runs inside the FMU (FMI state machine, variables).
- :mod:`overcon.fmu.variables`: the variable table (names, units, causality) both share.
- :mod:`overcon.fmu.description`: modelDescription.xml from that table.
- :mod:`overcon.fmu.statecodec`: exact serialization of the FMU state.

Nothing here is imported by the rest of the package; the builder needs a C compiler and fmpy
(validation, reference results); the FMU at run time needs only numpy and scipy.
"""
