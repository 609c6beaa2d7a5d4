"""The facts record of an FMU (overcon.fmu.facts) without building one: what the build writes for
a scene is what the tooling reads back; records of another format or with a bad key are refused
naming the FMU and the key."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from overcon import scene as scene_mod
from overcon.checks import compile_checked
from overcon.fmu import facts
from overcon.precheck import precheck

MECH = Path(__file__).resolve().parent.parent / "mechanisms"


def _record(scene):
    model = compile_checked(scene)
    return facts.record(scene, model, precheck(model, scene.name)), model


def test_round_trip_of_a_given_and_an_auto_elimination():
    given = scene_mod.load(MECH / "planar_f45_wo4.toml")
    auto = scene_mod.as_scene(scene_mod.load(MECH / "planar_sliders.toml"), friction=["joint4"])
    for spec, eliminate in ((given, (4,)), (auto, "auto")):
        rec, model = _record(spec)
        back = facts.decode(facts.encode(rec), "x.fmu")
        assert back["eliminate"] == eliminate and back["friction"] == tuple(spec.friction)
        assert back["group"] == (spec.group or spec.name) and back["mechanism"] == "planar_sliders"
        assert back["outputs"] == tuple(model.output_names())
        assert back["solver"]["method"] == spec.solver.method and back["solver"]["stop_time"] == spec.stop_time
        assert rec["eliminated"] == list(model.eliminated) and rec["format"] == facts.FORMAT
    assert back["reaction_unique"] and all(isinstance(v, bool) for v in back["reaction_unique"].values())


@pytest.mark.parametrize("change, message", [
    (lambda r: r.update(format=2), r"x\.fmu: resources/overcon_facts\.json has format 2; this overcon reads format 1"),
    (lambda r: r.pop("format"), r"has format None; this overcon reads format 1"),
    (lambda r: r.pop("motion_unique"), r"x\.fmu: resources/overcon_facts\.json: key 'motion_unique' missing"),
    (lambda r: r.update(friction="joint4"), r"key 'friction' has the wrong type \(str\)"),
    (lambda r: r.update(eliminate="all"), r"key 'eliminate' is 'all', not a list or \"auto\""),
])
def test_bad_records_are_refused_naming_the_key(change, message):
    rec, _ = _record(scene_mod.load(MECH / "planar_f45_wo4.toml"))
    change(rec)
    with pytest.raises(facts.FactsError, match=message):
        facts.decode(json.dumps(rec).encode(), "x.fmu")


def test_not_json_is_refused():
    with pytest.raises(facts.FactsError, match=r"x\.fmu: resources/overcon_facts\.json is not JSON"):
        facts.decode(b"{", "x.fmu")
    with pytest.raises(facts.FactsError, match=r"is not a JSON object"):
        facts.decode(b"[1]", "x.fmu")
