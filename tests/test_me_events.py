"""The Model Exchange drift event under the host's integrator (issue 37, item 8; decided, see
docs/held-out.md "Model Exchange: the drift event"): the FMU asks for an event when the
constraint drift max |Phi| exceeds 1e-6 (m or rad), whatever step the host takes, and the event
projects the state back onto the constraints. Under an adaptive host (fmpy's CVode) the drift
stays far below it: no event at all. Under fixed-step explicit Euler (the FMI Compliance
Checker's solver) the first-order steps drift by more than 1e-6 and the events correct them: the
state is back on the constraints after each one, so the motion stays close to CVode's."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")
from fmpy.fmi2 import FMU2Model  # noqa: E402

from overcon.fmu import build as fmu_build  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "mechanisms" / "spatial_MN_wo5.toml"

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def fmu(tmp_path_factory):
    lines = []
    code, results = fmu_build.build_all([str(SCENE)], tmp_path_factory.mktemp("me_events"), refs=False,
                                        validate=False, kind="me", echo=lines.append, echo_err=lines.append)
    assert code == 0, lines
    return str(results[0].fmu)


def _events(monkeypatch) -> list:
    """Every step event the FMU asks for (fmi2CompletedIntegratorStep's enterEventMode)."""
    asked = []
    real = FMU2Model.completedIntegratorStep

    def spy(self, *a, **kw):
        out = real(self, *a, **kw)
        asked.append(bool(out[0]))
        return out

    monkeypatch.setattr(FMU2Model, "completedIntegratorStep", spy)
    return asked


def test_cvode_runs_event_free_and_euler_runs_are_corrected(fmu, monkeypatch):
    asked = _events(monkeypatch)
    ref = fmpy.simulate_fmu(fmu, fmi_type="ModelExchange", solver="CVode", stop_time=1.0, output_interval=0.01,
                            relative_tolerance=1e-8, output=["platform.x"])
    assert len(asked) > 50 and not any(asked)  # every completed step, none asking for an event
    asked.clear()
    euler = fmpy.simulate_fmu(fmu, fmi_type="ModelExchange", solver="Euler", step_size=1e-3, stop_time=1.0,
                              output_interval=1e-3, output=["platform.x"])
    assert len(asked) >= 1000 and sum(asked) > 100, sum(asked)  # the first-order steps drift past 1e-6
    # corrected every time: the explicit Euler motion stays within its own O(h) of CVode's
    t, x = euler["time"], euler["platform.x"]
    at = [np.flatnonzero(np.isclose(t, tr, rtol=0, atol=1e-9))[-1] for tr in ref["time"]]  # after any event
    err = np.max(np.abs(x[at] - ref["platform.x"]))
    assert err < 5e-3, err
