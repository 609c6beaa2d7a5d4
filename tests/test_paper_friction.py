"""Paper §4.1.3 and §4.2.3: friction on unique-reaction joints gives unique motion; friction on
non-unique ones makes the motion depend on the eliminated equation; the pre-check predicts which."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from overcon.paper import run_group, scene_groups

MECH = Path(__file__).resolve().parent.parent / "mechanisms"
GROUPS = scene_groups(MECH)
_cache = {}


def group_run(name):
    if name not in _cache:
        _cache[name] = run_group(GROUPS[name])
    return _cache[name]


def test_every_paper_group_present():
    expected = {"planar_none": 2, "planar_f45": 2, "planar_f1": 2, "planar_f145": 2,
                "spatial_none": 3, "spatial_MN": 3, "spatial_GH": 3, "spatial_GHMN": 3}
    assert {g: len(v) for g, v in GROUPS.items()} == expected


UNIQUE = ["planar_none", "planar_f45", "spatial_none", "spatial_MN"]
NONUNIQUE = ["planar_f1", "planar_f145", "spatial_GH", "spatial_GHMN"]


@pytest.mark.parametrize("name", UNIQUE)
def test_unique_groups_agree_to_1e_9_m_in_lockstep(name):
    """Every elimination on the same fixed grid (overcon.verdict): a unique friction set gives the
    same motion to round-off. The bound 1e-9 m is the contract; round-off gives about 1e-13 m, so no
    CPU's rounding pattern comes near it."""
    g = group_run(name)
    assert g.predicted_unique
    assert max(g.max_diff.values()) <= 1e-9, g.max_diff
    assert g.observed_unique()


@pytest.mark.parametrize("name", NONUNIQUE)
def test_nonunique_groups_differ_by_1e_3_m_in_lockstep(name):
    g = group_run(name)
    assert not g.predicted_unique
    assert max(g.max_diff.values()) >= 1e-3, g.max_diff
    assert not g.observed_unique()


def test_adaptive_difference_is_reported_beside_the_verdict():
    """The adaptive runs (the scenes' own solver) are compared too; their difference for a unique
    group is the integration error, far above the lockstep round-off and far below the non-unique
    differences. Bounds are physical (the global error of tolerance 1e-9, measured 4e-8 m), not
    round-off: 1e-5 m and 0.1 m."""
    unique, nonunique = group_run("planar_f45"), group_run("planar_f1")
    assert 0 < max(unique.adaptive_diff.values()) < 1e-5
    assert max(nonunique.adaptive_diff.values()) > 0.1
    assert unique.labels == ["without eq. 4 of joint2", "without eq. 6 of joint3"]  # the joint named


OWN = scene_groups(Path(__file__).resolve().parent / "data" / "drawer")


@pytest.mark.parametrize("name, unique", [("drawer_pivot", True), ("drawer_rail", False)])
def test_lockstep_verdict_on_a_mechanism_of_our_own(name, unique):
    """A drawer on two parallel rails with a pendulum (tests/data/drawer): friction in the pivot
    (unique reaction) gives unique motion, friction on a rail (non-unique reaction) does not."""
    g = run_group(OWN[name], adaptive=False)
    assert g.predicted_unique is unique
    d = max(g.max_diff.values())
    assert (d <= 1e-9) if unique else (d >= 1e-3), g.max_diff
    assert g.observed_unique() is unique


@pytest.mark.parametrize("name, unique", [("spatial_MN", True), ("spatial_GH", False)])
def test_spatial_unique_with_fixed_steps(name, unique):
    """Another grid (rk4, 2 ms, 2 s): the verdict does not depend on the lockstep step."""
    g = run_group(GROUPS[name], adaptive=False, lockstep_step=2e-3, stop_time=2.0, outputs=("platform.x",))
    diff = g.max_diff["platform.x"]
    if unique:
        assert diff <= 1e-9
    else:
        assert diff > 1e-2


@pytest.mark.parametrize("name, output", [("planar_f1", "slider1.x"), ("planar_f145", "slider1.x"),
                                          ("spatial_GH", "platform.x"), ("spatial_GHMN", "platform.x")])
def test_nonunique_groups_differ_clearly(name, output):
    """Paper Figs. 4, 5, 8, 9: differences of order 0.1 m and more (0.3-0.6 m measured)."""
    g = group_run(name)
    assert g.max_diff[output] > 0.1
    assert not g.predicted_unique
    # every pair of variants differs, not just one
    cols = [r.column(output) for r in g.results]
    for i in range(len(cols)):
        for j in range(i + 1, len(cols)):
            assert np.max(np.abs(cols[i] - cols[j])) > 0.05


@pytest.mark.parametrize("name", sorted(GROUPS))
def test_precheck_verdict_matches_observed(name):
    g = group_run(name)
    assert g.predicted_unique == g.observed_unique(), (name, g.max_diff)
