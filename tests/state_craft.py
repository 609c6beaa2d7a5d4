"""Crafted FMU states: where the fields of a serialized state of the C-runtime FMUs are, and bytes
with one field changed (the CRC-32 re-sealed, as someone writing a state on purpose would).

The layout is fmu_src/overcon/fmu/native/fmu_state.c's (the header and STATE_FIELDS) followed by
the run's bytes of fmu_src/overcon/core/sim_state.c (io_sim). Every offset is found from the bytes
themselves and the model (the run's "OVKSIM" magic and its header give ny, ncols and m; the
scene's compiled model the kept rows and joints), and checked (`layout` asserts what it assumes),
so a change of either layout fails here loudly instead of crafting the wrong field.

The regression inputs of tests/data/untrusted/states.json are such patches: one field, one value,
on one of the fuzz targets (tests/c_host/fuzz_targets.py); test_untrusted.py replays them on the
shipped binaries and ci/sanitize.sh under ASan/UBSan (``python tests/state_craft.py``).
"""
from __future__ import annotations

import json
import struct
import sys
import zlib
from pathlib import Path

HERE = Path(__file__).resolve().parent
REGRESSION = HERE / "data" / "untrusted" / "states.json"
FMU_FIELDS = ["mode", "tol_source", "have_outputs", "derived_stale", "has_y", "has_sim", "has_failed"]


def layout(data: bytes, guid: str, nparam: int, nR: int, nj: int) -> dict[str, tuple[int, str]]:
    """Offsets and struct formats of the fields of a serialized state (a run without events)."""
    g = 8 + len(guid.encode()) + 1
    assert data[:8] == b"OVKFMUS2" and data[8:g - 1] == guid.encode(), "not a state of this FMU's format"
    payload = g + 24
    at: dict[str, tuple[int, str]] = {"version": (g, "I"), "kind": (g + 4, "I"), "crc": (g + 8, "I")}
    for k, name in enumerate(FMU_FIELDS):
        at[name] = (payload + 4 * k, "i")
    at["start_time"], at["t"], at["stable_step"] = (payload + 28, "d"), (payload + 36, "d"), (payload + 44, "d")
    sim = data.index(b"OVKSIM\0\0", payload)
    _, method, ny, ncols, m = struct.unpack_from("5i", data, sim + 8)
    rest = sim - payload - 52 - 12 * nparam - 8 * ny - 8  # the outputs (then y, and u_dirty, u_pending: no inputs)
    assert rest >= 0 and rest % 8 == 0, "the fields before the run do not add up"
    nout = rest // 8
    for k in range(nparam):
        at[f"pval[{k}]"] = (payload + 52 + 8 * k, "d")
        at[f"pset[{k}]"] = (payload + 52 + 8 * nparam + 4 * k, "i")
    at["outputs[0]"] = (payload + 52 + 12 * nparam, "d")
    at["y[0]"] = (payload + 52 + 12 * nparam + 8 * nout, "d")
    rk = sim + 28
    # io_rk: 9 ints (has_K ... dense_kept), 6 counters, 9 reals, then the arrays
    at["sim.has_K"], at["sim.k"], at["sim.t"], at["sim.h"] = (rk, "i"), (rk + 36, "q"), (rk + 84, "d"), (rk + 92, "d")
    at["sim.dense_kept"] = (rk + 32, "i")
    if method == 3:  # OVK_METHOD_RADAU: piv and pivc after y, f, y_old, f_old, J, LU, LUc
        at["sim.piv[0]"] = (rk + 156 + 8 * (4 * ny + 4 * ny * ny), "i")
        at["sim.pivc[0]"] = (rk + 156 + 8 * (4 * ny + 4 * ny * ny) + 4 * ny, "i")
    end = len(data)
    assert struct.unpack_from("i", data, end - 4)[0] == 0, "a state with events: the kept list is not at the end"
    kept = end - 4 - 8 - 4 * nj - 4 - 4 * nR
    got = struct.unpack_from(f"{nR}i", data, kept)
    assert list(got) == sorted(set(got)) and all(0 <= r < m for r in got), f"not the kept rows: {got}"
    at["sim.kept[0]"], at["sim.kept[last]"] = (kept, "i"), (kept + 4 * (nR - 1), "i")
    at["sim.along_rank"] = (kept + 4 * nR, "i")
    at["sim.nevents"] = (end - 4, "i")
    return at


def reseal(data: bytearray, guid: str) -> bytearray:
    """The CRC-32 of the payload written again into the header."""
    g = 8 + len(guid.encode()) + 1
    struct.pack_into("I", data, g + 8, zlib.crc32(bytes(data[g + 24:])) & 0xFFFFFFFF)
    return data


def patched(data: bytes, at: dict, guid: str, field: str, value, seal: bool = True) -> bytes:
    """data with field set to value (the CRC re-sealed unless seal is False)."""
    out = bytearray(data)
    offset, fmt = at[field]
    struct.pack_into(fmt, out, offset, value)
    return bytes(reseal(out, guid) if seal else out)


def model_counts(scene: Path) -> tuple[int, int]:
    """nR (the kept rows) and nj (the joints) of a scene's compiled model."""
    from overcon import scene as scene_mod
    from overcon.checks import compile_checked
    model = compile_checked(scene_mod.load(scene))
    return len(model.retained), len(model.joints)


def regression_cases() -> list[dict]:
    """The regression inputs: {"target", "field", "value", "why"} (value "nan" / "inf" as text)."""
    cases = json.loads(REGRESSION.read_text())["cases"]
    for c in cases:
        if isinstance(c["value"], str):
            c["value"] = float(c["value"])
    return cases


def param_index(md, name: str) -> int:
    """The index of a parameter in the state's pval (the order of the parameter variables)."""
    names = [v.name for v in md.modelVariables if v.causality == "parameter"]
    return names.index(name)


def craft_all(unzipped: dict[str, Path], scenes: dict[str, Path], out: Path) -> list[Path]:
    """Every regression case as a file out/<n>-<target>-<field>.bin (for fuzz_fmu replay); the
    state taken at t = 0.1 s as fuzz_fmu takes it."""
    import fmpy
    from fmpy.fmi2 import FMU2Slave
    out.mkdir(parents=True, exist_ok=True)
    files = []
    states = {}
    for n, case in enumerate(regression_cases()):
        target = case["target"]
        d = unzipped[target]
        md = fmpy.read_model_description(str(d))
        if target not in states:
            fmu = FMU2Slave(guid=md.guid, unzipDirectory=str(d), modelIdentifier=md.coSimulation.modelIdentifier,
                            instanceName="craft")
            fmu.instantiate()
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
            fmu.exitInitializationMode()
            for k in range(10):
                fmu.doStep(0.01 * k, 0.01)
            data = fmu.serializeFMUstate(fmu.getFMUstate())
            fmu.terminate()
            fmu.freeInstance()
            nparam = sum(v.causality == "parameter" for v in md.modelVariables)
            states[target] = (bytes(data), layout(bytes(data), md.guid, nparam, *model_counts(scenes[target])))
        data, at = states[target]
        field = case["field"]
        if field.startswith("param:"):
            field = f"pval[{param_index(md, field[6:])}]"
        path = out / f"{n:02d}-{target}-{case['field'].replace(':', '_')}.bin"
        path.write_bytes(patched(data, at, md.guid, field, case["value"]))
        files.append(path)
    return files


if __name__ == "__main__":  # ci/sanitize.sh: python tests/state_craft.py TARGETS_LIST OUT
    lines = [line.split() for line in Path(sys.argv[1]).read_text().splitlines() if line.strip()]
    sys.path.insert(0, str(HERE / "c_host"))
    from fuzz_targets import scenes as target_scenes
    scene_dir = Path(sys.argv[2]) / "scenes"
    by_name = {p.stem: p for p in target_scenes(scene_dir)}
    for f in craft_all({parts[0]: Path(parts[1]) for parts in lines}, by_name, Path(sys.argv[2])):
        print(f.name.split("-")[1], f)
