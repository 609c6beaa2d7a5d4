"""Tests of overcon.scene: the shipped mechanism/scene files, validation problems, overrides, fuzz."""
from __future__ import annotations

import copy
import dataclasses
import json
import math
import random
import re
import tomllib
from pathlib import Path

import pytest

from overcon import spec as S
from overcon.joints import TYPES as JOINT_TYPES
from overcon.scene import Problem, SceneError, as_scene, load, parse_eliminate, parse_joint_list
from overcon.spec import FrictionSpec, MechanismSpec, SceneSpec

ROOT = Path(__file__).resolve().parent.parent
MECH_DIR = ROOT / "mechanisms"
PLANAR = MECH_DIR / "planar_sliders.toml"
SPATIAL = MECH_DIR / "spatial_parallelogram.toml"
ALL_FILES = sorted(MECH_DIR.glob("*.toml"))
SCENE_FILES = [p for p in ALL_FILES if p not in (PLANAR, SPATIAL)]

PLANAR_POSITIONS = ("slider1.x", "slider1.y", "slider2.x", "slider2.y", "link3.x", "link3.y",
                    "link3.phi", "link4.x", "link4.y", "link4.phi")
PLANAR_FRICTION = {"none": (), "f45": ("joint4", "joint5"), "f1": ("joint1",),
                   "f145": ("joint1", "joint4", "joint5")}
SPATIAL_FRICTION = {"none": (), "MN": ("M", "N"), "GH": ("G", "H"), "GHMN": ("G", "H", "M", "N")}
FIGURES = {"planar_none": "Fig. 3", "planar_f45": "Fig. 3", "planar_f1": "Fig. 4",
           "planar_f145": "Fig. 5", "spatial_none": "Fig. 7", "spatial_GH": "Fig. 8",
           "spatial_GHMN": "Fig. 9", "spatial_MN": "4.2.3"}


# ------------------------------------------------------------------------------------------------
# helpers: a minimal TOML writer (inline tables only) so tests can mutate parsed documents


def _val(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_val(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_val(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def dump(doc: dict) -> str:
    return "".join(f"{json.dumps(k)} = {_val(v)}\n" for k, v in doc.items())


def read(path: Path) -> dict:
    return tomllib.loads(path.read_text(encoding="utf-8"))


def field_re(field: str) -> str:
    """A regular expression for ``field`` as a problem shows it: a named body, joint or load's
    name may follow its index (``joints[0] (joint1).psi``)."""
    item, dot, rest = field.partition(".")
    return re.escape(item) + r"( \([^)]*\))?" + re.escape(dot + rest)


def problem_fields(exc: SceneError) -> set[tuple[str, str]]:
    return {(p.file, p.field) for p in exc.problems}


# constraint equations straight from the paper (Eq. 34, 36, 41), to check the data files' q0


def _rot2(phi):
    c, s = math.cos(phi), math.sin(phi)
    return ((c, -s), (s, c))


def _mul(R, v):
    return tuple(sum(R[r][k] * v[k] for k in range(len(v))) for r in range(len(R)))


def _matmul(A, B):
    n = len(A)
    return tuple(tuple(sum(A[r][k] * B[k][c] for k in range(n)) for c in range(n)) for r in range(n))


def _rot3(a, b, g):
    def rz(t):
        c, s = math.cos(t), math.sin(t)
        return ((c, -s, 0.0), (s, c, 0.0), (0.0, 0.0, 1.0))

    def rx(t):
        c, s = math.cos(t), math.sin(t)
        return ((1.0, 0.0, 0.0), (0.0, c, -s), (0.0, s, c))

    return _matmul(_matmul(rz(a), rx(b)), rz(g))


def _pose(mech: MechanismSpec, name: str):
    dim = 2 if mech.kind == "planar" else 3
    if name == "base":
        return (0.0,) * dim, (0.0,), tuple(tuple(float(r == c) for c in range(dim)) for r in range(dim))
    body = next(b for b in mech.bodies if b.name == name)
    if mech.kind == "planar":
        return body.q0[:2], (body.q0[2],), _rot2(body.q0[2])
    return body.q0[:3], body.q0[3:], _rot3(*body.q0[3:])


def constraint_residuals(mech: MechanismSpec) -> list[float]:
    out = []
    for j in mech.joints:
        ri, ai, Ri = _pose(mech, j.body_i)
        rj, aj, Rj = _pose(mech, j.body_j)
        p = j.params
        if j.type == "translational":
            d = [a + b - c - e for a, b, c, e in zip(ri, _mul(Ri, p["s_A"]), rj, _mul(Rj, p["s_B"]))]
            out.append(sum(x * y for x, y in zip(d, _mul(Rj, p["v"]))))
            out.append(ai[0] - aj[0] - p["psi"])
        else:
            out.extend(a + b - c - e for a, b, c, e in
                       zip(ri, _mul(Ri, p["s_i"]), rj, _mul(Rj, p["s_j"])))
    return out


# ------------------------------------------------------------------------------------------------
# the shipped files


def test_file_list_complete():
    names = {p.stem for p in SCENE_FILES}
    expected = {f"planar_{f}_wo{e}" for f in PLANAR_FRICTION for e in (4, 6)}
    expected |= {f"spatial_{f}_wo{e}" for f in SPATIAL_FRICTION for e in (5, 9, 18)}
    assert names == expected
    assert len(SCENE_FILES) == 20


@pytest.mark.parametrize("path", ALL_FILES, ids=lambda p: p.name)
def test_every_file_loads(path):
    spec = load(path)
    if path in (PLANAR, SPATIAL):
        assert isinstance(spec, MechanismSpec)
        assert spec.source == str(path)
        return
    assert isinstance(spec, SceneSpec)
    assert spec.name == path.stem
    assert spec.source == str(path)
    kind, fset, wo = path.stem.split("_")
    elim = int(wo[2:])
    assert spec.eliminate == (elim,)
    assert spec.group == f"{kind}_{fset}"
    assert FIGURES[spec.group] in spec.description
    assert spec.solver.tolerance == 1e-9 and spec.solver.output_interval == 0.01
    assert spec.start_time == 0.0
    assert set(spec.friction_params) == set(spec.friction)
    if kind == "planar":
        assert spec.mechanism.name == "planar_sliders"
        assert spec.mechanism.source == str(PLANAR)
        assert spec.friction == PLANAR_FRICTION[fset]
        assert spec.stop_time == 4.0
        assert spec.positions == PLANAR_POSITIONS
        assert spec.reactions == tuple(f"joint{k}" for k in range(1, 7))
    else:
        assert spec.mechanism.name == "spatial_parallelogram"
        assert spec.friction == SPATIAL_FRICTION[fset]
        assert spec.stop_time == 10.0
        assert spec.positions == ("platform.x", "platform.y", "platform.z")
        assert spec.reactions == ("G", "H", "M", "N")
        for fs in spec.friction_params.values():
            assert fs == FrictionSpec(mu=0.3, size=0.1, law="regularised", v_reg=1e-3)


def test_planar_mechanism_values():
    m = load(PLANAR)
    assert m.name == "planar_sliders" and m.kind == "planar"
    assert m.gravity == (0.0, -9.81)
    assert [b.name for b in m.bodies] == ["slider1", "slider2", "link3", "link4"]
    assert all(b.mass == 3.0 and b.inertia == (1.0,) and b.h0 == (0.0, 0.0, 0.0) for b in m.bodies)
    assert [b.q0 for b in m.bodies] == [(2.0, 0.0, 0.0), (0.0, 2.0, 0.0), (2.0, 1.0, 0.0),
                                        (1.0, 2.0, 0.0)]
    assert [j.name for j in m.joints] == [f"joint{k}" for k in range(1, 7)]
    assert [j.type for j in m.joints] == ["translational"] * 3 + ["revolute"] * 3
    assert sum(JOINT_TYPES[j.type].n_equations for j in m.joints) == 12
    assert [(j.body_i, j.body_j) for j in m.joints] == [
        ("slider1", "base"), ("slider2", "base"), ("slider1", "slider2"),
        ("slider1", "link3"), ("slider2", "link4"), ("link3", "link4")]
    j1, j2, j3, j4, j5, j6 = m.joints
    assert j1.params == {"s_A": (0.0, 0.0), "s_B": (0.0, 0.0), "v": (0.0, 1.0), "psi": 0.0}
    assert j2.params["v"] == (1.0, 0.0) and j3.params["v"] == (1.0, 1.0)
    assert (j4.params["s_i"], j4.params["s_j"]) == ((0.0, 0.0), (0.0, -1.0))
    assert (j5.params["s_i"], j5.params["s_j"]) == ((0.0, 0.0), (-1.0, 0.0))
    assert (j6.params["s_i"], j6.params["s_j"]) == ((0.0, 1.0), (1.0, 0.0))
    for j in (j1, j2, j3):
        assert j.friction == FrictionSpec(mu=0.01, size=0.2, law="regularised", v_reg=1e-3)
    for j in (j4, j5, j6):
        assert j.friction == FrictionSpec(mu=0.1, size=0.15, law="regularised", v_reg=1e-3)
    torque1, torque2, spring = m.loads
    assert torque1.type == "torque" and torque1.params == {"body": "slider1", "value": 10.0}
    assert torque2.type == "torque" and torque2.params == {"body": "slider2", "value": 30.0}
    assert spring.type == "spring"
    assert spring.params == {"body_i": "slider2", "body_j": "base", "stiffness": 30.0,
                             "free_length": 3.0, "s_i": (0.0, 0.0), "s_j": (0.0, 0.0)}
    # the paper's explicit equations B.1-B.6 vanish at q0
    assert max(abs(x) for x in constraint_residuals(m)) == 0.0


def test_spatial_mechanism_values():
    m = load(SPATIAL)
    assert m.kind == "spatial" and m.gravity == (0.0, 0.0, -9.81)
    assert [b.name for b in m.bodies] == [f"link{k}" for k in range(1, 7)] + ["platform"]
    assert len(m.bodies) == 7 and sum(len(b.q0) for b in m.bodies) == 42
    for b in m.bodies[:6]:
        assert b.mass == 1.0 and b.inertia == (2 / 3, 2 / 3, 2 / 300)
    assert m.bodies[6].mass == 10.0 and m.bodies[6].inertia == (10 / 3, 20 / 3, 10 / 3)
    assert all(b.h0 == (0.0,) * 6 for b in m.bodies)
    th = -math.pi / 4
    s, c = math.sin(th), math.cos(th)
    assert m.bodies[0].q0 == (-s, c, 1.0, th, -math.pi / 4, 0.0)
    assert m.bodies[4].q0 == (-s, 1 + c, 3.0, th, math.pi / 4, 0.0)
    assert m.bodies[6].q0 == (1 - 2 * s, 1 + 2 * c, 2.0, math.pi / 2, math.pi / 2, 0.0)
    assert [j.name for j in m.joints] == list("ABCDEFGHKLMN")
    assert len(m.joints) == 12 and all(j.type == "spherical" for j in m.joints)
    assert sum(JOINT_TYPES[j.type].n_equations for j in m.joints) == 36
    assert all(j.body_i.startswith("link") for j in m.joints)
    assert m.joints[0].params["s_i"] == (0.0, 0.0, -math.sqrt(2))
    assert m.joints[8].params == {"s_i": (0.0, 0.0, math.sqrt(2)), "s_j": (0.0, 1.0, 4.0)}
    assert all(j.friction == FrictionSpec(mu=0.3, size=0.1) for j in m.joints)
    force, torque = m.loads
    assert force.params == {"body": "platform", "value": (0.0, 40.0, 0.0)}
    assert torque.type == "torque" and torque.params == {"body": "platform", "value": (0.0, 300.0, 0.0)}
    # Eq. 41 at q* (B.17) vanishes to machine precision
    assert max(abs(x) for x in constraint_residuals(m)) < 1e-14


# ------------------------------------------------------------------------------------------------
# "all" expansion, defaults


def _write_scene(tmp_path, scene_doc, mech_doc=None, mech_src=PLANAR):
    mech = tmp_path / "mech.toml"
    if mech_doc is None:
        mech.write_text(mech_src.read_text(encoding="utf-8"), encoding="utf-8")
    else:
        mech.write_text(dump(mech_doc), encoding="utf-8")
    scene = tmp_path / "scene.toml"
    scene.write_text(dump(scene_doc), encoding="utf-8")
    return scene


def _planar_scene_doc():
    doc = read(MECH_DIR / "planar_f145_wo4.toml")
    doc["scene"]["mechanism"] = "mech.toml"
    return doc


def _spatial_scene_doc():
    doc = read(MECH_DIR / "spatial_GHMN_wo9.toml")
    doc["scene"]["mechanism"] = "mech.toml"
    return doc


def test_all_expansion(tmp_path):
    doc = _planar_scene_doc()
    doc["outputs"] = {"positions": "all", "reactions": "all"}
    s = load(_write_scene(tmp_path, doc))
    assert s.positions == tuple(f"{b}.{c}" for b in ("slider1", "slider2", "link3", "link4")
                                for c in ("x", "y", "phi"))
    assert s.reactions == tuple(f"joint{k}" for k in range(1, 7))
    doc = _spatial_scene_doc()
    doc["outputs"] = {"positions": "all", "reactions": "all"}
    s = load(_write_scene(tmp_path, doc, mech_src=SPATIAL))
    assert len(s.positions) == 42 and s.positions[-1] == "platform.gamma"
    assert s.reactions == tuple("ABCDEFGHKLMN")


def test_missing_outputs_and_solver_default(tmp_path):
    doc = _planar_scene_doc()
    del doc["outputs"], doc["solver"]
    del doc["scene"]["start_time"]
    s = load(_write_scene(tmp_path, doc))
    assert len(s.positions) == 12 and len(s.reactions) == 6
    assert s.solver == S.SolverSpec() and s.start_time == 0.0


def test_ints_accepted_as_floats(tmp_path):
    doc = read(PLANAR)
    doc["bodies"][0]["mass"] = 3
    doc["bodies"][0]["q0"] = [2, 0, 0]
    doc["mechanism"]["gravity"] = [0, -10]
    path = tmp_path / "m.toml"
    path.write_text(dump(doc), encoding="utf-8")
    m = load(path)
    assert m.bodies[0].mass == 3.0 and isinstance(m.bodies[0].mass, float)
    assert m.bodies[0].q0 == (2.0, 0.0, 0.0) and all(isinstance(x, float) for x in m.bodies[0].q0)
    assert m.gravity == (0.0, -10.0)


def test_scene_friction_params_merge(tmp_path):
    doc = _planar_scene_doc()
    doc["scene"]["friction_params"] = {"joint4": {"mu": 0.2}, "joint1": {"law": "stribeck",
                                       "mu_static": 0.02, "v_stribeck": 0.01}}
    s = load(_write_scene(tmp_path, doc))
    assert s.friction_params["joint4"] == FrictionSpec(mu=0.2, size=0.15)
    assert s.friction_params["joint5"] == FrictionSpec(mu=0.1, size=0.15)
    assert s.friction_params["joint1"] == FrictionSpec(mu=0.01, size=0.2, law="stribeck",
                                                       mu_static=0.02, v_stribeck=0.01)


def test_scene_friction_params_for_joint_without_mechanism_table(tmp_path):
    mech = read(PLANAR)
    del mech["joints"][0]["friction"]
    doc = _planar_scene_doc()
    doc["scene"]["friction_params"] = {"joint1": {"mu": 0.05, "length": 0.3}}
    s = load(_write_scene(tmp_path, doc, mech))
    assert s.friction_params["joint1"] == FrictionSpec(mu=0.05, size=0.3)
    # without the size key it is an error
    doc["scene"]["friction_params"] = {"joint1": {"mu": 0.05}}
    with pytest.raises(SceneError, match=r"scene\.toml: scene\.friction_params\.joint1\.length: ") as err:
        load(_write_scene(tmp_path, doc, mech))
    assert (str(tmp_path / "scene.toml"), "scene.friction_params.joint1.length") in problem_fields(err.value)


# ------------------------------------------------------------------------------------------------
# as_scene, parse_*


def test_as_scene_from_mechanism():
    m = load(PLANAR)
    s = as_scene(m)
    assert s.name == "planar_sliders" and s.mechanism is m
    assert s.friction == () and s.friction_params == {} and s.eliminate == "auto"
    assert s.stop_time == 1.0 and s.start_time == 0.0
    assert len(s.positions) == 12 and s.reactions == tuple(j.name for j in m.joints)
    s = as_scene(m, friction=["joint1", "joint5"], eliminate=[4], stop_time=2.5, tolerance=1e-6)
    assert s.friction == ("joint1", "joint5")
    assert s.friction_params == {"joint1": m.joints[0].friction, "joint5": m.joints[4].friction}
    assert s.eliminate == (4,) and s.stop_time == 2.5 and s.solver.tolerance == 1e-6
    s = as_scene(m, friction="joint4,joint5", eliminate="4,6")
    assert s.friction == ("joint4", "joint5") and s.eliminate == (4, 6)
    assert as_scene(m, eliminate="auto").eliminate == "auto"


def test_as_scene_overrides_scene():
    sc = load(MECH_DIR / "planar_f1_wo4.toml")
    s = as_scene(sc, friction=[], eliminate=[6], stop_time=1.0)
    assert s.friction == () and s.friction_params == {} and s.eliminate == (6,)
    assert s.stop_time == 1.0 and s.positions == sc.positions and s.name == sc.name
    assert s.solver == sc.solver and s.source == sc.source
    assert as_scene(sc) == sc
    sp = as_scene(load(MECH_DIR / "spatial_none_wo5.toml"), friction=["G", "H"], eliminate=[18])
    assert sp.friction == ("G", "H") and sp.eliminate == (18,)
    assert sp.friction_params["G"] == FrictionSpec(mu=0.3, size=0.1)


@pytest.mark.parametrize("kwargs, field", [
    ({"friction": ["joint9"]}, "--friction"),
    ({"friction": ["joint1", "joint1"]}, "--friction"),
    ({"friction": [3]}, "--friction"),
    ({"eliminate": [0]}, "--eliminate"),
    ({"eliminate": [13]}, "--eliminate"),
    ({"eliminate": [4, 4]}, "--eliminate"),
    ({"eliminate": [True]}, "--eliminate"),
    ({"eliminate": "4,x"}, "--eliminate"),
    ({"eliminate": 4}, "--eliminate"),
    ({"stop_time": 0.0}, "--stop-time"),
    ({"stop_time": -1}, "--stop-time"),
    ({"stop_time": float("nan")}, "--stop-time"),
    ({"tolerance": 1.0}, "--tolerance"),
    ({"tolerance": 0}, "--tolerance"),
    ({"tolerance": float("inf")}, "--tolerance"),
    ({"tolerance": "1e-6"}, "--tolerance"),
])
def test_as_scene_errors(kwargs, field):
    with pytest.raises(SceneError, match=rf"^<command line>: {re.escape(field)}: ") as err:
        as_scene(load(PLANAR), **kwargs)
    assert {p.field for p in err.value.problems} == {field}
    assert all(p.file == "<command line>" for p in err.value.problems)


def test_as_scene_joint_without_friction_parameters():
    m = load(PLANAR)
    m = dataclasses.replace(m, joints=(dataclasses.replace(m.joints[0], friction=None),) + m.joints[1:])
    with pytest.raises(SceneError, match=r"^cli: --friction: .*friction parameters") as err:
        as_scene(m, friction=["joint1"], source="cli")
    assert [(p.file, p.field) for p in err.value.problems] == [("cli", "--friction")]
    assert "friction parameters" in err.value.problems[0].message


def test_as_scene_reports_all_errors():
    with pytest.raises(SceneError, match=r"--friction: (.|\n)*--eliminate: (.|\n)*--stop-time: (.|\n)*--tolerance: ") as err:
        as_scene(load(SPATIAL), friction=["Z"], eliminate=[37], stop_time=-1, tolerance=2)
    assert [p.field for p in err.value.problems] == ["--friction", "--eliminate", "--stop-time",
                                                     "--tolerance"]


def test_parse_helpers():
    assert parse_joint_list("none") == () and parse_joint_list("") == ()
    assert parse_joint_list("joint4,joint5") == ("joint4", "joint5")
    assert parse_joint_list(" G , H ") == ("G", "H")
    assert parse_eliminate("auto") == "auto"
    assert parse_eliminate("4,6") == (4, 6)
    assert parse_eliminate("18") == (18,)
    for bad in ("4.5", "4,,6", "4;6", "joint 6"):
        with pytest.raises(SceneError, match=r"--eliminate: ") as err:
            parse_eliminate(bad)
        assert err.value.problems[0].field == "--eliminate"


def test_problem_and_error_strings():
    p = Problem("a.toml", "bodies[2].mass", "must be > 0")
    assert str(p) == "a.toml: bodies[2].mass: must be > 0"
    e = SceneError([p, Problem("b.toml", "scene.name", "bad")])
    assert str(e).splitlines() == ["a.toml: bodies[2].mass: must be > 0", "b.toml: scene.name: bad"]
    assert e.problems[1].file == "b.toml"


# ------------------------------------------------------------------------------------------------
# malformed variants: each mutates one thing of a valid file


def _set(*path_value):
    *path, value = path_value

    def mutate(doc):
        node = doc
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
    return mutate


def _del(*path):
    def mutate(doc):
        node = doc
        for key in path[:-1]:
            node = node[key]
        del node[path[-1]]
    return mutate


def _both(*mutations):
    def mutate(doc):
        for m in mutations:
            m(doc)
    return mutate


NAN, INF = float("nan"), float("inf")

# (id, base, mechanism mutation, scene mutation, file with the problem, field)
#   base: "planar"/"spatial" loads the mechanism file; "planar_scene"/"spatial_scene" the scene.
MALFORMED = [
    # --- mechanism, planar
    ("mass_string", "planar", _set("bodies", 1, "mass", "3"), None, "mech", "bodies[1].mass"),
    ("mass_bool", "planar", _set("bodies", 1, "mass", True), None, "mech", "bodies[1].mass"),
    ("mass_zero", "planar", _set("bodies", 1, "mass", 0.0), None, "mech", "bodies[1].mass"),
    ("mass_negative", "planar", _set("bodies", 0, "mass", -3), None, "mech", "bodies[0].mass"),
    ("mass_nan", "planar", _set("bodies", 2, "mass", NAN), None, "mech", "bodies[2].mass"),
    ("mass_missing", "planar", _del("bodies", 2, "mass"), None, "mech", "bodies[2].mass"),
    ("inertia_inf", "planar", _set("bodies", 0, "inertia", INF), None, "mech", "bodies[0].inertia"),
    ("inertia_list_planar", "planar", _set("bodies", 0, "inertia", [1.0]), None, "mech",
     "bodies[0].inertia"),
    ("q0_length", "planar", _set("bodies", 0, "q0", [2.0, 0.0]), None, "mech", "bodies[0].q0"),
    ("q0_string_item", "planar", _set("bodies", 0, "q0", [2.0, "0", 0.0]), None, "mech",
     "bodies[0].q0[1]"),
    ("h0_length", "planar", _set("bodies", 3, "h0", [0.0] * 4), None, "mech", "bodies[3].h0"),
    ("body_duplicate", "planar", _set("bodies", 1, "name", "slider1"), None, "mech",
     "bodies[1].name"),
    ("body_base", "planar", _set("bodies", 0, "name", "base"), None, "mech", "bodies[0].name"),
    ("body_unknown_key", "planar", _set("bodies", 0, "colour", "red"), None, "mech",
     "bodies[0].colour"),
    ("body_is_string", "planar", _set("bodies", 2, "link3"), None, "mech", "bodies[2]"),
    ("bodies_table", "planar", _set("bodies", {"name": "x"}), None, "mech", "bodies"),
    ("bodies_empty", "planar", _set("bodies", []), None, "mech", "bodies"),
    ("top_unknown_key", "planar", _set("extra", 1), None, "mech", "extra"),
    ("mechanism_unknown_key", "planar", _set("mechanism", "units", "SI"), None, "mech",
     "mechanism.units"),
    ("mechanism_name", "planar", _set("mechanism", "name", "planar sliders"), None, "mech",
     "mechanism.name"),
    ("kind_unknown", "planar", _set("mechanism", "kind", "planer"), None, "mech", "mechanism.kind"),
    ("gravity_length", "planar", _set("mechanism", "gravity", [0.0, 0.0, -9.81]), None, "mech",
     "mechanism.gravity"),
    ("joint_unknown_body", "planar", _set("joints", 2, "body_j", "slidr2"), None, "mech",
     "joints[2].body_j"),
    ("joint_same_bodies", "planar", _set("joints", 3, "body_j", "slider1"), None, "mech",
     "joints[3].body_j"),
    ("joint_unknown_type", "planar", _set("joints", 0, "type", "prismatic"), None, "mech",
     "joints[0].type"),
    ("joint_type_kind", "planar", _set("joints", 3, "type", "spherical"), None, "mech",
     "joints[3].type"),
    ("joint_duplicate", "planar", _set("joints", 1, "name", "joint1"), None, "mech",
     "joints[1].name"),
    ("joint_missing_field", "planar", _del("joints", 0, "s_A"), None, "mech", "joints[0].s_A"),
    ("joint_unknown_key", "planar", _set("joints", 3, "s_A", [0.0, 0.0]), None, "mech",
     "joints[3].s_A"),
    ("v_zero", "planar", _set("joints", 0, "v", [0.0, 0.0]), None, "mech", "joints[0].v"),
    ("psi_string", "planar", _set("joints", 0, "psi", "0"), None, "mech", "joints[0].psi"),
    ("friction_string", "planar", _set("joints", 0, "friction", "coulomb"), None, "mech",
     "joints[0].friction"),
    ("friction_law", "planar", _set("joints", 0, "friction", "law", "viscous"), None, "mech",
     "joints[0].friction.law"),
    ("friction_radius_on_translational", "planar",
     _both(_del("joints", 0, "friction", "length"), _set("joints", 0, "friction", "radius", 0.2)),
     None, "mech", "joints[0].friction.radius"),
    ("friction_length_on_revolute", "planar", _set("joints", 3, "friction", "length", 0.2), None,
     "mech", "joints[3].friction.length"),
    ("friction_mu_negative", "planar", _set("joints", 3, "friction", "mu", -0.1), None, "mech",
     "joints[3].friction.mu"),
    ("friction_mu_missing", "planar", _del("joints", 3, "friction", "mu"), None, "mech",
     "joints[3].friction.mu"),
    ("friction_v_reg_zero", "planar", _set("joints", 1, "friction", "v_reg", 0.0), None, "mech",
     "joints[1].friction.v_reg"),
    ("stribeck_incomplete", "planar", _set("joints", 0, "friction", "law", "stribeck"), None,
     "mech", "joints[0].friction.mu_static"),
    ("stribeck_mu_static_low", "planar",
     _both(_set("joints", 0, "friction", "law", "stribeck"),
           _set("joints", 0, "friction", "mu_static", 0.001),
           _set("joints", 0, "friction", "v_stribeck", 0.01)),
     None, "mech", "joints[0].friction.mu_static"),
    ("load_unknown_body", "planar", _set("loads", 0, "body", "slider3"), None, "mech",
     "loads[0].body"),
    ("load_on_base", "planar", _set("loads", 0, "body", "base"), None, "mech", "loads[0].body"),
    ("load_unknown_type", "planar", _set("loads", 0, "type", "moment"), None, "mech",
     "loads[0].type"),
    ("torque_vector_planar", "planar", _set("loads", 1, "value", [0.0, 0.0, 30.0]), None, "mech",
     "loads[1].value"),
    ("spring_negative", "planar", _set("loads", 2, "stiffness", -30.0), None, "mech",
     "loads[2].stiffness"),
    ("spring_same_body", "planar", _set("loads", 2, "body_j", "slider2"), None, "mech",
     "loads[2].body_j"),
    # --- mechanism, spatial
    ("spatial_inertia_length", "spatial", _set("bodies", 6, "inertia", [1.0, 2.0]), None, "mech",
     "bodies[6].inertia"),
    ("spatial_inertia_zero", "spatial", _set("bodies", 6, "inertia", [1.0, 0.0, 1.0]), None,
     "mech", "bodies[6].inertia[1]"),
    ("spatial_s_j_length", "spatial", _set("joints", 11, "s_j", [0.0, 1.0]), None, "mech",
     "joints[11].s_j"),
    ("spatial_translational", "spatial", _set("joints", 2, "type", "translational"), None, "mech",
     "joints[2].type"),
    ("spatial_revolute_without_axes", "spatial", _set("joints", 2, "type", "revolute"), None, "mech",
     "joints[2].axis_i"),
    ("spatial_torque_scalar", "spatial", _set("loads", 1, "value", 300.0), None, "mech",
     "loads[1].value"),
    ("spatial_length_key", "spatial", _set("joints", 6, "friction", "length", 0.1), None, "mech",
     "joints[6].friction.length"),
    # --- scene
    ("scene_friction_unknown", "planar_scene", None, _set("scene", "friction", ["joint7"]), "scene",
     "scene.friction[0]"),
    ("scene_friction_no_params", "planar_scene", _del("joints", 3, "friction"),
     _set("scene", "friction", ["joint1", "joint4"]), "scene", "scene.friction[1]"),
    ("scene_friction_not_list", "planar_scene", None, _set("scene", "friction", "joint1"), "scene",
     "scene.friction"),
    ("scene_friction_params_unknown", "planar_scene", None,
     _set("scene", "friction_params", {"joint9": {"mu": 0.1}}), "scene",
     "scene.friction_params.joint9"),
    ("scene_friction_params_wrong_size", "planar_scene", None,
     _set("scene", "friction_params", {"joint1": {"radius": 0.1}}), "scene",
     "scene.friction_params.joint1.radius"),
    ("scene_friction_params_mu_static", "planar_scene", None,
     _set("scene", "friction_params", {"joint1": {"law": "stribeck", "mu_static": 0.001,
                                                  "v_stribeck": 0.1}}),
     "scene", "scene.friction_params.joint1.mu_static"),
    ("eliminate_zero", "planar_scene", None, _set("scene", "eliminate", [0]), "scene",
     "scene.eliminate[0]"),
    ("eliminate_too_big", "planar_scene", None, _set("scene", "eliminate", [4, 13]), "scene",
     "scene.eliminate[1]"),
    ("eliminate_duplicate", "planar_scene", None, _set("scene", "eliminate", [4, 4]), "scene",
     "scene.eliminate[1]"),
    ("eliminate_float", "planar_scene", None, _set("scene", "eliminate", [4.0]), "scene",
     "scene.eliminate[0]"),
    ("eliminate_bool", "planar_scene", None, _set("scene", "eliminate", [True]), "scene",
     "scene.eliminate[0]"),
    ("eliminate_string", "planar_scene", None, _set("scene", "eliminate", "all"), "scene",
     "scene.eliminate"),
    ("eliminate_spatial_37", "spatial_scene", None, _set("scene", "eliminate", [37]), "scene",
     "scene.eliminate[0]"),
    ("positions_unknown_body", "planar_scene", None,
     _set("outputs", "positions", ["slider1.x", "slider2.y", "link3.x", "link5.x"]), "scene",
     "outputs.positions[3]"),
    ("positions_unknown_coordinate", "planar_scene", None,
     _set("outputs", "positions", ["slider1.z"]), "scene", "outputs.positions[0]"),
    ("positions_spatial_phi", "spatial_scene", None, _set("outputs", "positions", ["platform.phi"]),
     "scene", "outputs.positions[0]"),
    ("positions_no_dot", "planar_scene", None, _set("outputs", "positions", ["slider1"]), "scene",
     "outputs.positions[0]"),
    ("positions_string", "planar_scene", None, _set("outputs", "positions", "every"), "scene",
     "outputs.positions"),
    ("reactions_unknown", "spatial_scene", None, _set("outputs", "reactions", ["G", "J"]), "scene",
     "outputs.reactions[1]"),
    ("outputs_unknown_key", "planar_scene", None, _set("outputs", "accelerations", "all"), "scene",
     "outputs.accelerations"),
    ("stop_before_start", "planar_scene", None, _set("scene", "stop_time", 0.0), "scene",
     "scene.stop_time"),
    ("stop_missing", "planar_scene", None, _del("scene", "stop_time"), "scene", "scene.stop_time"),
    ("tolerance_one", "planar_scene", None, _set("solver", "tolerance", 1.0), "scene",
     "solver.tolerance"),
    ("tolerance_zero", "planar_scene", None, _set("solver", "tolerance", 0), "scene",
     "solver.tolerance"),
    ("step_zero", "planar_scene", None, _set("solver", "step", 0.0), "scene", "solver.step"),
    ("output_interval_negative", "planar_scene", None, _set("solver", "output_interval", -0.01),
     "scene", "solver.output_interval"),
    ("baumgarte_negative", "planar_scene", None, _set("solver", "baumgarte", -1.0), "scene",
     "solver.baumgarte"),
    ("friction_tol_zero", "planar_scene", None, _set("solver", "friction_tol", 0.0), "scene",
     "solver.friction_tol"),
    ("friction_max_iter_zero", "planar_scene", None, _set("solver", "friction_max_iter", 0),
     "scene", "solver.friction_max_iter"),
    ("friction_max_iter_float", "planar_scene", None, _set("solver", "friction_max_iter", 50.0),
     "scene", "solver.friction_max_iter"),
    ("max_step_zero", "planar_scene", None, _set("solver", "max_step", 0.0), "scene",
     "solver.max_step"),
    ("method_unknown", "planar_scene", None, _set("solver", "method", "euler"), "scene",
     "solver.method"),
    ("solver_unknown_key", "planar_scene", None, _set("solver", "rtol", 1e-6), "scene",
     "solver.rtol"),
    ("solver_string", "planar_scene", None, _set("solver", "fast"), "scene", "solver"),
    ("scene_unknown_key", "planar_scene", None, _set("scene", "duration", 4.0), "scene",
     "scene.duration"),
    ("scene_name", "planar_scene", None, _set("scene", "name", "1planar"), "scene", "scene.name"),
    ("mechanism_missing_file", "planar_scene", None, _set("scene", "mechanism", "nope.toml"),
     "scene", "scene.mechanism"),
    ("mechanism_not_string", "planar_scene", None, _set("scene", "mechanism", ["mech.toml"]),
     "scene", "scene.mechanism"),
    ("mechanism_problem_reported_on_mechanism", "planar_scene", _set("bodies", 0, "mass", -1.0),
     None, "mech", "bodies[0].mass"),
    ("mechanism_is_scene", "planar_scene", None, _set("scene", "mechanism", "scene.toml"), "scene",
     "(file)"),
]


@pytest.mark.parametrize("case", MALFORMED, ids=[c[0] for c in MALFORMED])
def test_malformed(tmp_path, case):
    _id, base, mech_mut, scene_mut, where, field = case
    mech_doc = read(SPATIAL if base.startswith("spatial") else PLANAR)
    if mech_mut:
        mech_mut(mech_doc)
    mech_path = tmp_path / "mech.toml"
    mech_path.write_text(dump(mech_doc), encoding="utf-8")
    target = mech_path
    if base.endswith("_scene"):
        scene_doc = _spatial_scene_doc() if base.startswith("spatial") else _planar_scene_doc()
        if scene_mut:
            scene_mut(scene_doc)
        target = tmp_path / "scene.toml"
        target.write_text(dump(scene_doc), encoding="utf-8")
    expected_file = str(mech_path if where == "mech" else tmp_path / "scene.toml")
    with pytest.raises(SceneError, match=field_re(field)) as err:
        load(target)
    assert (expected_file, field) in problem_fields(err.value), str(err.value)
    assert all(isinstance(p, Problem) and p.message for p in err.value.problems)


@pytest.mark.parametrize("content, message", [
    (b"[mechanism\nname = 'x'\n", "invalid TOML"),
    (b"name = 'x'\n", "neither"),
    (b"[mechanism]\nname = 'x'\n[scene]\nname = 'y'\n", "both"),
    (b"[mechanism]\nname = '\xff\xfe'\n", "UTF-8"),
    (b"", "neither"),
    (b"a = " + b"[" * 5000 + b"]" * 5000 + b"\n", "invalid TOML"),
])
def test_file_level_problems(tmp_path, content, message):
    path = tmp_path / "f.toml"
    path.write_bytes(content)
    with pytest.raises(SceneError, match=r"\(file\): .*" + re.escape(message)) as err:
        load(path)
    assert [(p.file, p.field) for p in err.value.problems] == [(str(path), "(file)")]
    assert message in err.value.problems[0].message


def test_dates_are_not_numbers_or_strings(tmp_path):
    text = PLANAR.read_text(encoding="utf-8")
    text = text.replace('name = "slider1"', "name = 1979-05-27", 1)
    text = text.replace("mass = 3.0", "mass = 07:32:00", 1)
    path = tmp_path / "m.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(SceneError, match=r"bodies\[0\]\.name: .*date/time") as err:
        load(path)
    assert {p.field for p in err.value.problems} >= {"bodies[0].name", "bodies[0].mass"}
    assert "date/time" in err.value.problems[0].message


def test_file_not_found_or_directory(tmp_path):
    for path in (tmp_path / "missing.toml", tmp_path):
        with pytest.raises(SceneError, match=r": \(file\): ") as err:
            load(path)
        assert [(p.file, p.field) for p in err.value.problems] == [(str(path), "(file)")]


def test_multiple_problems_all_reported(tmp_path):
    mech = read(PLANAR)
    mech["bodies"][0]["mass"] = -1.0
    mech["bodies"][3]["q0"] = [1.0, 2.0]
    mech["joints"][5]["body_i"] = "link9"
    mech["loads"][0]["value"] = "10"
    scene = _planar_scene_doc()
    scene["scene"]["stop_time"] = -1.0
    scene["solver"]["method"] = "euler"
    scene["outputs"]["bogus"] = 1
    path = _write_scene(tmp_path, scene, mech)
    with pytest.raises(SceneError, match=r"mech\.toml: bodies\[0\]( \(\w+\))?\.mass: ") as err:
        load(path)
    m, s = str(tmp_path / "mech.toml"), str(path)
    assert problem_fields(err.value) >= {
        (m, "bodies[0].mass"), (m, "bodies[3].q0"), (m, "joints[5].body_i"), (m, "loads[0].value"),
        (s, "scene.stop_time"), (s, "solver.method"), (s, "outputs.bogus")}
    assert len(err.value.problems) == 7
    assert len(str(err.value).splitlines()) == 7


# ------------------------------------------------------------------------------------------------
# fuzz: load() returns a spec or raises SceneError, never anything else

_RANDOM_VALUES = [
    "", "x", "all", "auto", "base", "slider1", "joint1", "G", "platform.x", "1e-3", "\u00e9\u4e2d",
    0, 1, -1, 13, 37, 2 ** 62, 0.0, -0.0, 1.5, -2.5, 1e308, 1e-320, float("nan"), float("inf"),
    float("-inf"), True, False, [], [1], [1, 2], [1.0, 2.0, 3.0], [0, 0, 0, 0, 0, 0], ["a", 1],
    [[1, 2], [3]], [True], {}, {"x": 1}, {"mu": 0.1}, {"a": {"b": {"c": []}}}, [{"name": "x"}],
    [{}, {"type": "spring"}],
]


def _paths(node, prefix=()):
    """Every (container, key) path in a parsed document."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            out.append(prefix + (k,))
            out.extend(_paths(v, prefix + (k,)))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.append(prefix + (i,))
            out.extend(_paths(v, prefix + (i,)))
    return out


def _container(doc, path):
    node = doc
    for key in path[:-1]:
        node = node[key]
    return node


def _mutate(rng: random.Random, doc: dict) -> None:
    paths = _paths(doc)
    path = rng.choice(paths)
    parent, key = _container(doc, path), path[-1]
    op = rng.random()
    if op < 0.3:
        del parent[key]
    elif op < 0.85:
        parent[key] = copy.deepcopy(rng.choice(_RANDOM_VALUES))
    else:  # add an unexpected key or element
        target = parent[key]
        if isinstance(target, dict):
            target[rng.choice(["extra", "name", "mu", "radius", "length", "h0"])] = copy.deepcopy(
                rng.choice(_RANDOM_VALUES))
        elif isinstance(target, list):
            target.append(copy.deepcopy(rng.choice(_RANDOM_VALUES)))
        else:
            parent[key] = {"nested": {"table": target}}


def test_fuzz_never_raises_other_exceptions(tmp_path):
    rng = random.Random(0)
    bases = [PLANAR, SPATIAL, MECH_DIR / "planar_f145_wo6.toml", MECH_DIR / "spatial_GHMN_wo18.toml"]
    outcomes = {"ok": 0, "error": 0}
    for i in range(200):
        base = rng.choice(bases)
        is_scene = base not in (PLANAR, SPATIAL)
        mech_doc = read(SPATIAL if "spatial" in base.name else PLANAR)
        scene_doc = read(base) if is_scene else None
        if scene_doc is not None:
            scene_doc.setdefault("scene", {})["mechanism"] = "mech.toml"
        doc = scene_doc if is_scene and rng.random() < 0.7 else mech_doc
        for _ in range(rng.randint(1, 3)):
            if _paths(doc):
                _mutate(rng, doc)
        mech_text, scene_text = dump(mech_doc), dump(scene_doc) if is_scene else None
        if rng.random() < 0.15:  # truncate or corrupt the text
            which = "scene" if is_scene and doc is scene_doc else "mech"
            text = scene_text if which == "scene" else mech_text
            cut = rng.randrange(len(text) + 1)
            text = text[:cut] if rng.random() < 0.6 else text[:cut] + rng.choice("[]{}=\"'\n#,") + text[cut:]
            if which == "scene":
                scene_text = text
            else:
                mech_text = text
        case_dir = tmp_path / f"case{i}"
        case_dir.mkdir()
        (case_dir / "mech.toml").write_text(mech_text, encoding="utf-8")
        target = case_dir / "mech.toml"
        if is_scene:
            target = case_dir / "scene.toml"
            target.write_text(scene_text, encoding="utf-8")
        try:
            result = load(target)
        except SceneError as exc:
            assert exc.problems and all(isinstance(p, Problem) for p in exc.problems)
            assert all(p.file in (str(case_dir / "mech.toml"), str(case_dir / "scene.toml"))
                       for p in exc.problems)
            outcomes["error"] += 1
        else:
            assert isinstance(result, (MechanismSpec, SceneSpec))
            outcomes["ok"] += 1
    assert outcomes["error"] > 100  # the mutations really do break files


# ------------------------------------------------------------------------------------------------
# conveniences: angles in degrees (<field>_deg), joint names in eliminate


def _planar_mech_doc(**joint0):
    """The planar mechanism with joint1 (translational) updated by ``joint0`` (None: key removed)."""
    doc = read(PLANAR)
    for key, value in joint0.items():
        if value is None:
            doc["joints"][0].pop(key, None)
        else:
            doc["joints"][0][key] = value
    return doc


def _load_mech(tmp_path, doc):
    path = tmp_path / "mech.toml"
    path.write_text(dump(doc), encoding="utf-8")
    return load(path)


@pytest.mark.parametrize("deg", [90, 30.5, -1e-3, 0])
def test_psi_deg_gives_the_radians_spec(tmp_path, deg):
    rad = _load_mech(tmp_path, _planar_mech_doc(psi=math.radians(deg)))
    via_deg = _load_mech(tmp_path, _planar_mech_doc(psi=None, psi_deg=deg))
    assert via_deg.joints == rad.joints
    assert via_deg.joints[0].params["psi"] == math.radians(deg)


def test_psi_and_psi_deg_both_given(tmp_path):
    with pytest.raises(SceneError, match=r"joints\[0\] \(joint1\)\.psi_deg: .*'psi'") as err:
        _load_mech(tmp_path, _planar_mech_doc(psi=0.0, psi_deg=0))
    [p] = err.value.problems
    assert (p.field, p.file) == ("joints[0].psi_deg", str(tmp_path / "mech.toml"))
    assert "'psi'" in p.message and "'psi_deg'" in p.message


def test_psi_deg_checked_as_a_number(tmp_path):
    with pytest.raises(SceneError, match=r"joints\[0\] \(joint1\)\.psi_deg: ") as err:
        _load_mech(tmp_path, _planar_mech_doc(psi=None, psi_deg="90"))
    assert [p.field for p in err.value.problems] == ["joints[0].psi_deg"]


@pytest.mark.parametrize("where,key", [("joints", "v_deg"), ("joints", "s_A_deg"), ("bodies", "q0_deg"),
                                       ("bodies", "h0_deg"), ("joints", "theta_deg")])
def test_deg_form_only_for_angle_fields(tmp_path, where, key):
    doc = read(PLANAR)
    doc[where][0][key] = 1.0
    with pytest.raises(SceneError, match=rf"{where}\[0\]( \(\w+\))?\.{key}: unknown key") as err:
        _load_mech(tmp_path, doc)
    [p] = err.value.problems
    assert p.field == f"{where}[0].{key}" and p.message.startswith("unknown key")
    assert ("no degrees form" in p.message) == (key != "theta_deg")


def test_psi_deg_not_allowed_on_a_revolute_joint(tmp_path):
    doc = read(PLANAR)
    doc["joints"][3]["psi_deg"] = 0  # joint4: revolute
    with pytest.raises(SceneError, match=r"joints\[3\] \(joint4\)\.psi_deg: ") as err:
        _load_mech(tmp_path, doc)
    assert [p.field for p in err.value.problems] == ["joints[3].psi_deg"]


@pytest.mark.parametrize("names,numbers", [(["joint6"], (11, 12)), (["joint2", 1], (3, 4, 1)),
                                           ([1, "joint2"], (1, 3, 4))])
def test_eliminate_by_joint_name(tmp_path, names, numbers):
    doc = _planar_scene_doc()
    doc["scene"]["eliminate"] = names
    by_name = load(_write_scene(tmp_path, doc))
    doc["scene"]["eliminate"] = list(numbers)
    assert by_name == load(_write_scene(tmp_path, doc))
    assert by_name.eliminate == numbers


def test_eliminate_by_joint_name_spatial(tmp_path):
    doc = _spatial_scene_doc()
    doc["scene"]["eliminate"] = ["N"]
    scene = load(_write_scene(tmp_path, doc, mech_src=SPATIAL))
    names = [j.name for j in scene.mechanism.joints]
    first = 3 * names.index("N") + 1
    assert scene.eliminate == (first, first + 1, first + 2)


@pytest.mark.parametrize("value,field,message", [
    (["joint9"], "scene.eliminate[0]", "unknown joint 'joint9'"),
    ([4, "joint2"], "scene.eliminate[1]", "equation 4 listed twice"),
    (["joint2", "joint2"], "scene.eliminate[1]", "joint 'joint2' listed twice"),
    ([1.5], "scene.eliminate[0]", "equation index (integer) or a joint name"),
])
def test_eliminate_name_errors(tmp_path, value, field, message):
    doc = _planar_scene_doc()
    doc["scene"]["eliminate"] = value
    path = _write_scene(tmp_path, doc)
    with pytest.raises(SceneError, match=field_re(field) + ": .*" + re.escape(message)) as err:
        load(path)
    assert [(p.file, p.field) for p in err.value.problems] == [(str(path), field)]
    assert message in err.value.problems[0].message


def test_cli_eliminate_by_joint_name():
    mech = load(PLANAR)
    assert parse_eliminate("joint6, 2") == ("joint6", 2)
    assert as_scene(mech, eliminate="joint6,2").eliminate == (11, 12, 2)
    assert as_scene(mech, eliminate=("joint1",)).eliminate == (1, 2)
    with pytest.raises(SceneError, match=r"--eliminate: .*unknown joint 'joint9'") as err:
        as_scene(mech, eliminate="joint9")
    [p] = err.value.problems
    assert p.field == "--eliminate" and "unknown joint 'joint9'" in p.message


def test_problems_name_the_body_and_joint_the_file_names(tmp_path):
    """A problem inside a named body or joint shows its name after the index,
    ``joints[0] (joint1).psi``; the field itself stays the path; an item without a name shows the
    index alone."""
    doc = read(PLANAR)
    doc["bodies"][0]["mass"] = -1.0
    doc["joints"][0]["psi"] = "ninety"
    del doc["joints"][1]["name"]
    path = tmp_path / "mech.toml"
    path.write_text(dump(doc), encoding="utf-8")
    body, joint = doc["bodies"][0]["name"], doc["joints"][0]["name"]
    with pytest.raises(SceneError, match=rf"mech\.toml: bodies\[0\] \({body}\)\.mass: ") as err:
        load(path)
    text = str(err.value)
    assert f"mech.toml: joints[0] ({joint}).psi: " in text
    assert "mech.toml: joints[1].name: " in text and "joints[1] (" not in text
    assert {(p.field, p.name) for p in err.value.problems} >= {
        ("bodies[0].mass", body), ("joints[0].psi", joint), ("joints[1].name", "")}
