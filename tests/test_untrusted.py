"""Untrusted input to the FMUs (docs/untrusted-input.md): serialized FMU states that
crashed, hung or were accepted before the state validator, replayed on the shipped C-runtime
binaries through fmpy's low-level API; the smaller FMI items (a NULL GUID, %00 in the resource
URI, a step below the time's resolution); and the seeded fuzzer (tests/c_host/fuzz_fmu.c) on
every integrator and the quaternion door: 1,000 mutated states each here, 10,000 in the stress
run (``pytest -m stress``). ci/sanitize.sh runs the same inputs under ASan/UBSan."""
from __future__ import annotations

import ctypes
import subprocess
import sys
from pathlib import Path

import pytest

fmpy = pytest.importorskip("fmpy")

from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

import state_craft  # noqa: E402
from test_fmu import Logs  # noqa: E402

pytestmark = pytest.mark.integration

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "c_host"))
import fuzz_targets  # noqa: E402


@pytest.fixture(scope="module")
def targets(tmp_path_factory):
    """The fuzz targets (one FMU per integrator and the quaternion door), unzipped, with their scenes."""
    out = tmp_path_factory.mktemp("untrusted")
    fmus = fuzz_targets.build(out)
    unz = {name: Path(fmpy.extract(str(f), str(out / name))) for name, f in fmus.items()}
    scenes = {p.stem: p for p in fuzz_targets.scenes(out / "scenes")}
    return unz, scenes, out


class Co:
    """A co-simulation instance stepped to t = 0.1 s (as the regression states were taken)."""

    def __init__(self, d: Path, name="u"):
        self.md = fmpy.read_model_description(str(d))
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.logs = Logs()
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=str(d), modelIdentifier=self.md.coSimulation.modelIdentifier,
                             instanceName=name)
        self.fmu.instantiate(callbacks=self.logs.callbacks)
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        for k in range(10):
            self.fmu.doStep(0.01 * k, 0.01)

    def errors(self) -> str:
        return "\n".join(m for s, _, m in self.logs.records if s >= 3)

    def free(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


@pytest.fixture(scope="module")
def crafted(targets):
    unz, scenes, out = targets
    return state_craft.craft_all(unz, scenes, out / "crafted")


@pytest.mark.parametrize("n", range(len(state_craft.regression_cases())))
def test_regression_state_is_refused_or_runs(targets, crafted, n):
    """Each crafted state: refused at the stage and with the reason recorded, the instance then
    continuing from the state it had (the same bits as an instance that never saw it); or
    accepted and stepped within the doStep budget."""
    unz, _, _ = targets
    case = state_craft.regression_cases()[n]
    data = crafted[n].read_bytes()
    inst, clean = Co(unz[case["target"]]), Co(unz[case["target"]], "clean")
    outputs = [v.valueReference for v in inst.md.modelVariables if v.causality == "output" and v.type == "Real"]
    if case["stage"] == "deserialize":
        with pytest.raises(FMICallException):
            inst.fmu.deSerializeFMUstate(data)
        assert case["message"] in inst.errors(), inst.errors()
    elif case["stage"] == "set":
        state = inst.fmu.deSerializeFMUstate(data)
        with pytest.raises(FMICallException):
            inst.fmu.setFMUstate(state)
        assert case["message"] in inst.errors(), inst.errors()
        assert "the instance keeps the state it had before" in inst.errors()
        inst.fmu.freeFMUstate(state)
    else:
        state = inst.fmu.deSerializeFMUstate(data)
        inst.fmu.setFMUstate(state)
        inst.fmu.setReal([inst.vr["solver.max_wall_time"]], [1.0])
        try:
            inst.fmu.doStep(0.1, 0.01)
        except FMICallException:
            assert "BudgetExhausted" in inst.errors() or "SimulationError" in inst.errors(), inst.errors()
        inst.fmu.freeFMUstate(state)
        inst.fmu.freeInstance()
        clean.free()
        return
    inst.fmu.doStep(0.1, 0.01)  # the instance goes on from its own state
    clean.fmu.doStep(0.1, 0.01)
    assert inst.fmu.getReal(outputs) == clean.fmu.getReal(outputs)
    inst.free()
    clean.free()


def test_unaltered_state_round_trips_on_every_target(targets):
    """The validator accepts every real state: each integrator's and the door's, bit for bit."""
    unz, _, _ = targets
    for name, d in unz.items():
        a = Co(d, "a")
        data = a.fmu.serializeFMUstate(a.fmu.getFMUstate())
        outputs = [v.valueReference for v in a.md.modelVariables if v.causality == "output" and v.type == "Real"]
        a.fmu.doStep(0.1, 0.01)
        want = a.fmu.getReal(outputs)
        b = Co(d, "b")
        b.fmu.doStep(0.1, 0.01)
        b.fmu.setFMUstate(b.fmu.deSerializeFMUstate(data))
        b.fmu.doStep(0.1, 0.01)
        assert b.fmu.getReal(outputs) == want, name
        a.free()
        b.free()


def test_flipped_byte_fails_the_checksum(targets):
    unz, _, _ = targets
    inst = Co(unz["f45_dopri5"])
    data = bytearray(inst.fmu.serializeFMUstate(inst.fmu.getFMUstate()))
    data[-100] ^= 0x10
    with pytest.raises(FMICallException):
        inst.fmu.deSerializeFMUstate(bytes(data))
    assert "checksum mismatch (CRC-32" in inst.errors()
    with pytest.raises(FMICallException):
        inst.fmu.deSerializeFMUstate(bytes(data[:-3]))
    assert "truncated or malformed" in inst.errors()
    inst.free()


def test_model_exchange_state_into_co_simulation_is_refused(targets):
    from fmpy.fmi2 import FMU2Model
    unz, _, _ = targets
    d = unz["f45_dopri5"]
    md = fmpy.read_model_description(str(d))
    me = FMU2Model(guid=md.guid, unzipDirectory=str(d), modelIdentifier=md.modelExchange.modelIdentifier,
                   instanceName="me")
    me.instantiate()
    me.setupExperiment(startTime=0.0)
    me.enterInitializationMode()
    me.exitInitializationMode()
    data = me.serializeFMUstate(me.getFMUstate())
    me.terminate()
    me.freeInstance()
    cs = Co(d)
    with pytest.raises(FMICallException):
        cs.fmu.deSerializeFMUstate(data)
    assert "a state of a Model Exchange instance, this one is co-simulation" in cs.errors()
    cs.fmu.reset()  # still usable
    cs.fmu.freeInstance()


def _instantiate(d: Path, guid, uri: bytes, logs: Logs):
    md = fmpy.read_model_description(str(d))
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=str(d), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="x")
    return fmu, fmu.fmi2Instantiate(b"x", 1, guid, uri, ctypes.byref(logs.callbacks), 0, 0)


def test_null_guid_is_refused(targets):
    unz, _, _ = targets
    d = unz["f45_dopri5"]
    logs = Logs()
    _, component = _instantiate(d, None, (d / "resources").as_uri().encode(), logs)
    assert not component
    assert "the GUID (instantiationToken) is NULL" in logs.text()


def test_nul_escape_in_resource_uri_is_refused(targets):
    unz, _, _ = targets
    d = unz["f45_dopri5"]
    md = fmpy.read_model_description(str(d))
    logs = Logs()
    _, component = _instantiate(d, md.guid.encode(), ((d / "resources").as_uri() + "%00/elsewhere").encode(), logs)
    assert not component
    assert "is not a file: URI of the FMU's resources folder" in logs.text()


def test_step_below_the_time_resolution_is_refused(targets):
    unz, _, _ = targets
    d = unz["f45_dopri5"]
    md = fmpy.read_model_description(str(d))
    logs = Logs()
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=str(d), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="late")
    fmu.instantiate(callbacks=logs.callbacks)
    fmu.setupExperiment(startTime=1e17)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    with pytest.raises(FMICallException):
        fmu.doStep(1e17, 0.01)
    assert "the communication step 0.01 s is below the resolution of the time 1e+17 s (t + h rounds to t)" in logs.text()
    fmu.freeInstance()


@pytest.fixture(scope="module")
def fuzzer(tmp_path_factory):
    exe = tmp_path_factory.mktemp("fuzz") / "fuzz_fmu"
    subprocess.run(["cc", "-O2", "-Wall", "-Wextra", "-Werror", "-o", str(exe), str(HERE / "c_host" / "fuzz_fmu.c"),
                    "-ldl", "-lm"], check=True)
    return exe


def _fuzz(fuzzer, targets, mode, cases, seconds, seed=1):
    unz, _, out = targets
    for name, d in unz.items():
        guid, args = fuzz_targets.fuzz_args(d)
        proc = subprocess.run([str(fuzzer), mode, str(d), name, guid, str(seed), str(cases), str(seconds), *args,
                               "-o", str(out / f"fuzz_{mode}_{name}")], capture_output=True, text=True,
                              timeout=seconds + 120)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        assert f"{cases} " in proc.stdout, proc.stdout  # every case ran (not cut by the time limit)


def test_fuzzed_states_crash_nothing_and_keep_their_rules(fuzzer, targets):
    """1,000 mutated states per target (about 1 s each): no crash, every accepted state within its
    parameters' rules, every doStep within its budget, every refused one leaves the instance as it was."""
    _fuzz(fuzzer, targets, "states", 1000, 120)


def test_fuzzed_model_files_and_calls_crash_nothing(fuzzer, targets):
    _fuzz(fuzzer, targets, "model", 200, 120)
    _fuzz(fuzzer, targets, "calls", 2000, 120)


@pytest.mark.stress
def test_ten_thousand_mutated_states_per_integrator(fuzzer, targets):
    """The acceptance's 10,000 mutations of each integrator's state and the door's (about 50 s in all
    on the shipped binaries)."""
    _fuzz(fuzzer, targets, "states", 10000, 600, seed=2)


def test_fmi3_refuses_a_crafted_kept_list_and_an_fmi2_state(targets, tmp_path):
    """The kept-list crash hit fmi3SetFMUState too: the same bytes checks in FMI 3.0; and an FMI 2.0
    state is not an FMI 3.0 instance's."""
    from fmpy.fmi3 import FMU3Slave
    from overcon.fmu import build as fmu_build
    unz, scenes, _ = targets
    code, results = fmu_build.build_all([str(scenes["f45_dopri5"])], tmp_path, refs=False, validate=False,
                                        allow_nonunique=True, runtime="c", fmi=3, echo=lambda s: None,
                                        echo_err=lambda s: None)
    assert code == 0
    d = Path(fmpy.extract(str(results[0].fmu), str(tmp_path / "u3")))
    md = fmpy.read_model_description(str(d))
    messages = []
    s = FMU3Slave(guid=md.guid, unzipDirectory=str(d), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName="f3")
    s.instantiate(logMessage=lambda env, status, category, message: messages.append(message.decode()))
    s.enterInitializationMode(startTime=0.0)
    s.exitInitializationMode()
    for k in range(10):
        s.doStep(0.01 * k, 0.01)
    data = bytes(s.serializeFMUState(s.getFMUState()))
    nparam = sum(v.causality == "parameter" for v in md.modelVariables)
    at = state_craft.layout(data, md.guid, nparam, *state_craft.model_counts(scenes["f45_dopri5"]))
    state = s.deserializeFMUState(state_craft.patched(data, at, md.guid, "sim.kept[0]", 1_000_000))
    with pytest.raises(FMICallException):
        s.setFMUState(state)
    assert any("fmi3SetFMUState: the state is refused" in m and "kept equation 0 = 1000000" in m for m in messages)
    s.doStep(0.1, 0.01)  # still usable
    fmi2 = Co(unz["f45_dopri5"])
    two = bytes(fmi2.fmu.serializeFMUstate(fmi2.fmu.getFMUstate()))
    fmi2.free()
    with pytest.raises(FMICallException):
        s.deserializeFMUState(two)  # another GUID as well as another version: refused at the GUID
    assert any("fmi3DeserializeFMUState: the bytes are refused" in m for m in messages), messages
    s.terminate()
    s.freeInstance()
