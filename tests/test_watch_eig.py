"""The C run's watch without a full SVD (core/watch_eig.c): the tracked sigma_min and sigma_max of
the weighted kept rows (Phi_h equilibrated as core/watch_scale.c states, unit-norm rows) equal a dense SVD's to the accuracy the file
states, along a paper scene and near the N-four-bar's flat position, warm-started as the run does
and from a cold start; and the N-four-bar still stops at its first flat position at the same time
whatever the tolerance (issue 26's acceptance, on the C run)."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from overcon import kernel
from overcon import scene as scene_mod
from overcon.checks import compile_checked

ROOT = Path(__file__).resolve().parents[1]

REL, FLOOR, ROUND = 1e-9, 1e-13, 1e-14  # watch_eig.c: EIG_REL, EIG_FLOOR, EIG_ROUND
CERTIFIED = 1e-6  # r down to which sigma_min is certified the smallest (sqrt of CERT_FLOOR)
SVD_SLACK = 64 * np.finfo(float).eps  # numpy's own error, relative to sigma_max


def _spec(path: Path):
    return scene_mod.as_scene(scene_mod.load(path))


def _nfourbar(tmp_path: Path, n: int, tolerance: float, singular: str | None):
    spec = importlib.util.spec_from_file_location("nfourbar", ROOT / "mechanisms" / "examples" / "nfourbar.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    _, path = mod.write(n, tmp_path / f"n{n}_{tolerance:g}", stop_time=2.0, tolerance=tolerance, singular=singular)
    return _spec(path)


def _equilibrated(W: np.ndarray) -> np.ndarray:
    """core/watch_scale.c's rule written again on a dense array: round-off rows and columns
    (max-norm <= 100 max(k, n) eps max|W|) zeroed, Ruiz sweeps to unit max-norms within 1e-3 (at
    most 50), then unit-norm rows."""
    W = W.copy()
    amax = np.abs(W).max()
    floor = 100 * max(W.shape) * np.finfo(float).eps * amax
    W[:, np.abs(W).max(axis=0) <= floor] = 0.0
    W[np.abs(W).max(axis=1) <= floor, :] = 0.0
    for _ in range(50):
        rn, cn = np.abs(W).max(axis=1), np.abs(W).max(axis=0)
        dev = max(np.abs(1 - rn[rn > 0]).max(initial=0.0), np.abs(1 - cn[cn > 0]).max(initial=0.0))
        if dev <= 1e-3:
            break
        rf = np.where(rn > 0, 1 / np.sqrt(np.where(rn > 0, rn, 1)), 1.0)
        cf = np.where(cn > 0, 1 / np.sqrt(np.where(cn > 0, cn, 1)), 1.0)
        W = rf[:, None] * W * cf[None, :]
    norms = np.linalg.norm(W, axis=1)
    return W / np.where(norms > 0, norms, 1.0)[:, None]


def _dense(run: kernel.Run, model, y: np.ndarray) -> np.ndarray:
    """The singular values of the watched rows at y by LAPACK, largest first."""
    _, J, _ = run.kernel.rows(y)
    W = _equilibrated(J[list(model.retained)])
    return np.linalg.svd(W, compute_uv=False)


def _check(run: kernel.Run, model, y: np.ndarray) -> float:
    """Both estimates (warm and cold) against the dense SVD at y; the dense r."""
    sv = _dense(run, model, y)
    big, small = sv[0], sv[-1]
    for cold in (False, True):
        smin, smax = run.watch_extremes(y, cold=cold)
        # sigma_max: a Rayleigh quotient (never above) certified within REL of the largest
        assert smax <= big * (1 + SVD_SLACK)
        assert big - smax <= REL * big + SVD_SLACK * big, (cold, smax, big)
        # sigma_min: within the residual's bound; below CERTIFIED only that it is that small
        bound = REL * small + FLOOR * big + ROUND * big * big / max(smin, 1e-300) + SVD_SLACK * big
        if small >= CERTIFIED * big:
            assert abs(smin - small) <= bound, (cold, smin, small, bound)
        else:
            assert small <= smin + bound and smin <= CERTIFIED * big * 1.01, (cold, smin, small)
    return small / big


def test_tracked_extremes_equal_a_dense_svd_along_a_paper_scene():
    spec = _spec(ROOT / "mechanisms" / "spatial_MN_wo5.toml")
    model = compile_checked(spec)
    run = kernel.Run(model, spec.solver)
    for t in np.linspace(0.05, 2.0, 40):
        _check(run, model, run.advance(float(t)))
    info = run.info
    assert info["watch_capped"] == 0
    assert 0.0 < info["watch_time"] <= info["wall_time"]


def test_tracked_extremes_equal_a_dense_svd_near_the_nfourbar_flat_position(tmp_path):
    """N = 10 under "pass": states on the dense output closing in on the first flat position
    (t* = 0.7203 s, where 10 singular values fall to 0 together), r down to below 1e-5."""
    spec = _nfourbar(tmp_path, 10, 1e-9, "pass")
    model = compile_checked(spec)
    run = kernel.Run(model, spec.solver)
    run.advance(0.70)
    flat = 0.72030819  # the located minimum of the run's watch (info["last_singular"])
    ratios = [_check(run, model, run.advance(flat - d)) for d in np.geomspace(2e-2, 1e-6, 25)]
    assert min(ratios) < 1e-5  # the states reach into the flat position's neighbourhood
    ratios += [_check(run, model, run.advance(flat + d)) for d in np.geomspace(1e-6, 2e-2, 25)]
    assert run.info["watch_capped"] == 0


def test_c_run_stops_at_the_first_flat_position_whatever_the_tolerance(tmp_path):
    """Issue 26's acceptance on the C run: the N-four-bar (N = 2) under the default method stops
    at its first flat position at the same time (within 1e-3 s) for tolerances 1e-9 and 1e-12."""
    times = []
    for tol in (1e-9, 1e-12):
        spec = _nfourbar(tmp_path, 2, tol, None)
        run = kernel.Run(compile_checked(spec), spec.solver)
        with pytest.raises(kernel.RunStopped, match=r"the mechanism's constraint Jacobian is rank deficient") as exc:
            run.advance(2.0)
        assert exc.value.status == 12  # OVK_SINGULAR_POSITION
        times.append(float(str(exc.value).split("t = ")[1].split(" s")[0]))
    assert abs(times[0] - times[1]) < 1e-3
    assert 0.70 < times[0] < 0.73
