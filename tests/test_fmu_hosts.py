"""The FMUs outside fmpy: a plain C host (tests/c_host/fmu_host.c) that knows nothing about Python,
run from an empty environment (no LD_PRELOAD, no PYTHONPATH, no OPENBLAS_* either; the FMU is
loaded with dlopen RTLD_LOCAL), and libcosim (libcosimpy). The host's check that no libpython is
loaded and that the FMU state restores bit for bit is in tests/test_fmu_c.py.

Runtime: the C host runs each friction FMU (planar_f45_wo4, spatial_MN_wo5) once over its whole
default experiment (compared with fmpy from the same empty environment: equal to 1e-12), then
10 processes in a row alternating between the two on 0-0.05 s (every second one exits without
fmi2Terminate/fmi2FreeInstance); the 100-process version is a ``stress`` test (``-m stress``).
"""
from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")

from overcon.fmu.build import build_all  # noqa: E402

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]
MECH = ROOT / "mechanisms"
FRICTION = ("planar_f45_wo4", "spatial_MN_wo5")


class Fmu:
    def __init__(self, path: Path, unz: Path):
        self.path, self.unz = path, unz
        self.md = fmpy.read_model_description(str(unz))
        self.id = self.md.coSimulation.modelIdentifier
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.outputs = [v for v in self.md.modelVariables if v.causality == "output" and v.type == "Real"]
        ex = self.md.defaultExperiment
        self.start, self.stop, self.step, self.tol = (float(ex.startTime), float(ex.stopTime),
                                                      float(ex.stepSize), float(ex.tolerance))

    def host_args(self, stop=None, *flags, tol=None):
        """The host's arguments; ``tol``: the fmi2SetupExperiment tolerance (default the
        DefaultExperiment's; <= 0: none passed)."""
        return [*flags, str(self.unz), self.id, self.md.guid, repr(self.start),
                repr(self.stop if stop is None else stop), repr(self.step), repr(self.tol if tol is None else tol),
                *(f"{v.valueReference}:{v.name}" for v in self.outputs)]


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmus_hosts")
    code, _ = build_all([str(MECH / f"{n}.toml") for n in FRICTION], out, refs=False, echo=lambda s: None,
                        echo_err=lambda s: None)
    assert code == 0
    return {n: Fmu(out / f"{n}.fmu", Path(fmpy.extract(str(out / f"{n}.fmu"), str(out / f"unz_{n}"))))
            for n in FRICTION}


@pytest.fixture(scope="module")
def host(tmp_path_factory):
    cc = shutil.which("cc")
    if cc is None:
        pytest.skip("needs a C compiler (cc) for the test host")
    exe = tmp_path_factory.mktemp("c_host") / "fmu_host"
    subprocess.run([cc, "-O2", "-Wall", "-o", str(exe), str(ROOT / "tests" / "c_host" / "fmu_host.c"), "-ldl", "-lm"],
                   check=True, capture_output=True)
    return exe


def run_host(host, args, env=None, timeout=300):
    """The host from an empty environment (env -i): nothing of this Python's setup is inherited."""
    return subprocess.run([str(host), *args], capture_output=True, text=True, timeout=timeout, env=env or {})


def parse_csv(text: str) -> tuple[list[str], np.ndarray]:
    lines = text.splitlines()
    return lines[0], np.array([[float(x) for x in line.split(",")] for line in lines[1:]])


FMPY_CLEAN = r'''
import sys, fmpy, numpy as np
fmu, stop, names = sys.argv[1], float(sys.argv[2]), sys.argv[3:]
res = fmpy.simulate_fmu(fmu, stop_time=stop, output=names)
np.savetxt(sys.stdout, np.column_stack([res[n] for n in ["time", *names]]), fmt="%.17g", delimiter=",")
'''


def fmpy_clean(fmu: Fmu, stop: float) -> np.ndarray:
    """fmpy's result from the same empty environment (BLAS kernels chosen alike)."""
    proc = subprocess.run([sys.executable, "-c", FMPY_CLEAN, str(fmu.path), repr(stop),
                           *(v.name for v in fmu.outputs)], capture_output=True,
                          text=True, timeout=600, env={})
    assert proc.returncode == 0, proc.stderr
    return np.loadtxt(proc.stdout.splitlines(), delimiter=",", ndmin=2)


def test_binary_has_no_undefined_python_symbols(fmus):
    nm = shutil.which("nm")
    if nm is None:
        pytest.skip("needs nm (binutils)")
    for f in fmus.values():
        so = f.unz / "binaries" / "linux64" / f"{f.id}.so"
        undefined = subprocess.run([nm, "-D", "--undefined-only", str(so)], capture_output=True, text=True,
                                   check=True).stdout.split()
        assert not [s for s in undefined if s.startswith(("Py", "_Py"))], undefined
        exported = subprocess.run([nm, "-D", "--defined-only", str(so)], capture_output=True, text=True,
                                  check=True).stdout
        assert " T fmi2DoStep" in exported and " T fmi2Instantiate" in exported


@pytest.mark.parametrize("name", FRICTION)
def test_c_host_whole_default_experiment_matches_fmpy(fmus, host, name):
    f = fmus[name]
    proc = run_host(host, f.host_args(None, "-q"))
    assert proc.returncode == 0, proc.stderr
    header, c_values = parse_csv(proc.stdout)
    assert header == ",".join(f'"{n}"' for n in ["time", *(v.name for v in f.outputs)])
    n_rows = round((f.stop - f.start) / f.step) + 1
    assert c_values.shape == (n_rows, 1 + len(f.outputs))  # every row written
    assert c_values[-1, 0] == f.stop
    py_values = fmpy_clean(f, f.stop)
    assert py_values.shape == c_values.shape
    assert np.max(np.abs(c_values - py_values)) <= 1e-12


@pytest.mark.parametrize("runs", [10, pytest.param(100, marks=pytest.mark.stress)])
def test_c_host_runs_in_a_row(fmus, host, runs):
    """``runs`` host processes (10 in the default run, 100 as the stress test of ``.ci/run``),
    alternating planar and spatial FMU on 0-0.05 s; every second one exits right after the last
    step (no fmi2Terminate/fmi2FreeInstance/dlclose): exit code 0 and every row each time, the
    same numbers each time."""
    first: dict[str, np.ndarray] = {}
    failures = []
    for k in range(runs):
        f = fmus[FRICTION[k % 2]]
        flags = ("-q", "-x") if k % 4 >= 2 else ("-q",)
        proc = run_host(host, f.host_args(0.05, *flags))
        if proc.returncode != 0:
            failures.append(f"run {k} ({f.id} {' '.join(flags)}): exit {proc.returncode}: {proc.stderr[-500:]}")
            continue
        _, values = parse_csv(proc.stdout)
        if values.shape != (6, 1 + len(f.outputs)):
            failures.append(f"run {k} ({f.id}): {values.shape[0]} rows instead of 6")
        elif not np.array_equal(values, first.setdefault(f.id, values)):
            failures.append(f"run {k} ({f.id}): values differ from the first run")
    assert not failures, "\n".join(failures)


def test_c_host_failed_run_exits_nonzero_with_the_reason(fmus, host):
    """joint4.mu = 3e5: fmi2DoStep returns fmi2Error; the reason reaches the host's logger with
    debug logging off."""
    f = fmus["planar_f45_wo4"]
    proc = run_host(host, f.host_args(0.5, "-q", "-s", f"{f.vr['joint4.mu']}=3e5"))
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert "fmu_host: fmi2DoStep returned error" in proc.stderr
    assert "[error]" in proc.stderr and "fmi2DoStep(" in proc.stderr and "did not converge" in proc.stderr


def test_c_host_strict_uses_the_setup_experiment_tolerance(fmus, host):
    """A host as strict as OMSimulator (-w: any status but fmi2OK fails) passes tolerances 1e-4,
    1e-6 and 1e-9 to fmi2SetupExperiment: every call returns fmi2OK, the log says which tolerance
    the run uses, and the run equals the run with that tolerance set as the parameter
    solver.tolerance (no host tolerance), bit for bit. The parameter wins over the host's."""
    f = fmus["planar_f45_wo4"]
    tol_vr = f.vr["solver.tolerance"]
    runs = {}
    for tol in (1e-4, 1e-6, 1e-9):
        proc = run_host(host, f.host_args(0.3, "-w", tol=tol))
        assert proc.returncode == 0, proc.stderr
        assert f"fmi2SetupExperiment: tolerance {tol!r} used as solver.tolerance" in proc.stderr
        assert f"tolerance {tol!r} (from fmi2SetupExperiment)" in proc.stderr
        runs[tol] = parse_csv(proc.stdout)[1]
        by_param = run_host(host, f.host_args(0.3, "-w", "-s", f"{tol_vr}={tol!r}", tol=0))
        assert by_param.returncode == 0, by_param.stderr
        assert f"tolerance {tol!r} (from the parameter solver.tolerance)" in by_param.stderr
        assert np.array_equal(parse_csv(by_param.stdout)[1], runs[tol])
    assert np.max(np.abs(runs[1e-4] - runs[1e-9])) > 1e-7  # the host's tolerance does reach the integrator
    both = run_host(host, f.host_args(0.3, "-w", "-s", f"{tol_vr}=1e-9", tol=1e-4))
    assert both.returncode == 0, both.stderr
    assert "tolerance 1e-09 (from the parameter solver.tolerance)" in both.stderr
    assert np.array_equal(parse_csv(both.stdout)[1], runs[1e-9])


def test_four_slash_resource_uri(fmus, host):
    """A host that writes the resource URI as "file:///" + an absolute path (four slashes): the FMU
    finds its model file there and runs (exit 0, every row, the values of the three-slash URI)."""
    f = fmus["planar_f45_wo4"]
    four = run_host(host, f.host_args(0.02, "-q", "-4"))
    three = run_host(host, f.host_args(0.02, "-q"))
    assert four.returncode == 0 and three.returncode == 0, four.stderr + three.stderr
    assert np.array_equal(parse_csv(four.stdout)[1], parse_csv(three.stdout)[1])
    assert parse_csv(four.stdout)[1].shape[0] == round(0.02 / f.step) + 1


LIBCOSIM = r'''
import sys
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimSlave import CosimLocalSlave
fmu, stop, step = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
vrs = [int(v) for v in sys.argv[4:]]
ex = CosimExecution.from_step_size(round(step * 1e9))
idx = ex.add_local_slave(CosimLocalSlave(fmu_path=fmu, instance_name="overcon"))
obs = CosimObserver.create_last_value()
ex.add_observer(obs)
for k in range(round(stop / step)):
    assert ex.step(), f"libcosim step {k} failed"
    print("ROW," + ",".join(repr(x) for x in obs.last_real_values(idx, vrs)))
'''


@pytest.mark.parametrize("name", FRICTION)
def test_libcosim_matches_fmpy(fmus, name):
    if importlib.util.find_spec("libcosimpy") is None:
        pytest.skip(f"libcosimpy is not installed (no wheel for Python {sys.version.split()[0]} on this "
                    "platform?): pip install libcosimpy")
    f = fmus[name]
    stop = 0.5
    proc = subprocess.run([sys.executable, "-c", LIBCOSIM, str(f.path), repr(stop), repr(f.step),
                           *(str(v.valueReference) for v in f.outputs)], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    cosim = np.array([[float(x) for x in line.split(",")[1:]] for line in proc.stdout.splitlines()
                      if line.startswith("ROW,")])  # libcosim logs to stdout too
    res = fmpy.simulate_fmu(str(f.path), stop_time=stop)
    ref = np.column_stack([res[v.name] for v in f.outputs])[1:]
    assert cosim.shape == ref.shape
    # libcosim's communication points are integer nanoseconds (k * 10 ms rounded once), fmpy's are
    # k * h in floating point: at some k (0.35, 0.41, 0.47 s) they differ by one ulp, so the
    # outputs are read at times 6e-17 s apart. The positions then agree to round-off; the reactions
    # come from a friction solve converged to friction_tol = 1e-12 (relative to the multipliers),
    # so they agree to that tolerance relative to their size (measured 1.2e-12 N on 155 N).
    assert np.all(np.abs(cosim - ref) <= 1e-12 * (1.0 + np.abs(ref)))
