"""The shipped spatial examples (docs/examples.md): the pre-check of each mechanism file (rank, DOF,
redundant equations, unique joints), and the whole chain for three groups — FMUs built from the
scene files, run with fmpy in lockstep, compared: friction on a non-unique hinge (door_h1) is
predicted and observed NOT unique; the frictionless door and the friction in the unique rocker
hinge of a redundant loop (loop_D) are predicted and observed unique under the sharp (lockstep)
comparison."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from overcon.cli import main
from overcon.fmu.build import build_all
from overcon.tooling.pipeline import compare_paths

ROOT = Path(__file__).resolve().parent.parent
MECH = ROOT / "mechanisms" / "examples"
QUIET = dict(echo=lambda s: None, echo_err=lambda s: None)

# mechanism: (n_coordinates (velocity coordinates), n_equations, rank, dof, redundant, unique joints, other joints)
EXPECTED = {
    "door": (6, 10, 5, 1, 5, [], ["hinge1", "hinge2"]),
    "fourbar": (18, 20, 17, 1, 3, [], ["A", "B", "C", "D"]),
    "carriage": (6, 9, 5, 1, 4, [], ["guide", "rod"]),
    "loop": (18, 21, 16, 2, 5, ["B", "C", "D"], ["A1", "A2"]),
}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_precheck_of_the_example_mechanisms(name, capsys):
    assert main(["check", "--json", str(MECH / f"{name}.toml")]) == 0
    doc = json.loads(capsys.readouterr().out)
    n, m, rank, dof, redundant, unique, other = EXPECTED[name]
    assert (doc["n_coordinates"], doc["n_equations"], doc["rank"], doc["dof"], doc["redundant"]) == \
        (n, m, rank, dof, redundant)
    assert sorted(j["name"] for j in doc["joints"] if j["unique"]) == unique
    assert sorted(j["name"] for j in doc["joints"] if not j["unique"]) == other
    assert all(j["agree"] for j in doc["joints"])


def test_every_example_scene_predicts_from_its_friction_set(capsys):
    """Scenes of a group share the friction set and the prediction; friction only on unique
    joints (or none) predicts unique motion."""
    groups: dict[str, set] = {}
    for f in sorted(MECH.glob("*.toml")):
        if not f.stem.startswith(tuple(f"{k}_" for k in EXPECTED)):
            continue
        code = main(["check", "--json", str(f)])
        doc = json.loads(capsys.readouterr().out)
        assert code in (0, 1), doc
        groups.setdefault(f.stem.rsplit("_wo", 1)[0], set()).add((tuple(doc["friction"]), doc["motion_unique"]))
    assert len(groups) == 8 and all(len(v) == 1 for v in groups.values()), groups
    verdict = {g: next(iter(v))[1] for g, v in groups.items()}
    assert verdict == {"door_none": True, "door_h1": False, "fourbar_none": True, "fourbar_A": False,
                       "carriage_none": True, "carriage_guide": False, "loop_D": True, "loop_A1": False}


@pytest.mark.integration
def test_door_and_loop_verdicts_through_fmus(tmp_path):
    scenes = [MECH / f"{g}_{e}.toml" for g, es in (("door_none", ("wo_hinge2", "wo3_4_5_9_10")),
                                                   ("door_h1", ("wo_hinge2", "wo3_4_5_9_10")),
                                                   ("loop_D", ("wo_A2", "wo3_4_5_9_10"))) for e in es]
    code, res = build_all(scenes, tmp_path / "fmus", allow_nonunique=True, refs=False, validate=False, **QUIET)
    assert code == 0, [m for r in res for m in r.messages]
    out = compare_paths([tmp_path / "fmus"], tmp_path / "cmp", stop_time=1.0, echo=lambda s: None)
    by = {c.group: c for c in out.comparisons}
    assert set(by) == {"door_none", "door_h1", "loop_D"}
    for g, unique in (("door_none", True), ("door_h1", False), ("loop_D", True)):
        c = by[g]
        assert c.mode == "lockstep" and c.failure is None, (g, c.failure)
        assert c.predicted is unique and c.observed is unique and c.matches, g
    # the non-unique door differs by far more than any round-off: centimetres within 1 s
    worst = by["door_h1"].worst()
    assert worst.max_abs > 1e-3, worst
