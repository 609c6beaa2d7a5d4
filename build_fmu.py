#!/usr/bin/env python3
"""Build one FMU per scene file (FMI 2.0 or 3.0, co-simulation and Model Exchange; no Python inside):

    python build_fmu.py mechanisms/ --out dist/fmus [--allow-nonunique] [--no-ref] [paths...]

Same as ``overcon build``; the work is done by :func:`overcon.fmu.build.build_all`.
"""
import sys
from pathlib import Path

try:
    from overcon.fmu.build import main
except ImportError:  # not installed: use the source tree next to this script
    sys.path.insert(0, str(Path(__file__).resolve().parent / "fmu_src"))
    from overcon.fmu.build import main

if __name__ == "__main__":
    sys.exit(main())
