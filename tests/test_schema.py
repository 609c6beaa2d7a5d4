"""The JSON Schema of the file formats (overcon.schema, ``overcon schema``): valid draft-07, shipped
in the package as generated, accepts every TOML file the repository ships, and rejects what the
validator (overcon.scene) rejects on a sample of bad files, each made from a good one by one edit."""
from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import jsonschema
import pytest

from overcon import schema
from overcon import scene as sc

ROOT = Path(__file__).resolve().parent.parent
SHIPPED_TOML = sorted((ROOT / "mechanisms").rglob("*.toml")) + sorted((ROOT / "tests" / "data").rglob("*.toml"))
PLANAR = ROOT / "mechanisms" / "planar_sliders.toml"
SPATIAL = ROOT / "mechanisms" / "spatial_parallelogram.toml"
QUATERNION = next((ROOT / "tests" / "data" / "quaternion").glob("*.toml"), None)
SCENE = ROOT / "mechanisms" / "planar_f45_wo4.toml"


@pytest.fixture(scope="module")
def validator():
    return jsonschema.Draft7Validator(schema.schema("any"))


def test_schemas_are_valid_draft7_and_shipped_as_generated():
    for kind in schema.KINDS_OF_FILE:
        jsonschema.Draft7Validator.check_schema(schema.schema(kind))
        assert schema.shipped(kind).read_text(encoding="utf-8") == schema.text(kind), \
            f"{schema.shipped(kind)} is stale: python -m overcon.schema --write"


def test_the_command_prints_the_schema(tmp_path):
    p = subprocess.run([sys.executable, "-m", "overcon.cli", "schema", "mechanism"], capture_output=True, text=True)
    assert p.returncode == 0 and json.loads(p.stdout) == schema.mechanism_schema()
    out = tmp_path / "scene.json"
    p = subprocess.run([sys.executable, "-m", "overcon.cli", "schema", "scene", "--out", str(out)],
                       capture_output=True, text=True)
    assert p.returncode == 0 and json.loads(out.read_text()) == schema.scene_schema()
    p = subprocess.run([sys.executable, "-m", "overcon.cli", "schema", "nothing"], capture_output=True, text=True)
    assert p.returncode == 2


@pytest.mark.parametrize("path", SHIPPED_TOML, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_shipped_toml_is_valid(path, validator):
    errors = [f"{'.'.join(map(str, e.absolute_path))}: {e.message}" for e in validator.iter_errors(
        tomllib.loads(path.read_text(encoding="utf-8")))]
    assert errors == []


BAD = [  # (file, text replaced, replacement): each edit makes a file the validator refuses
    (PLANAR, 'kind = "planar"', 'kind = "planer"'),
    (PLANAR, 'kind = "planar"', 'kind = "planar"\nrotation = "quaternion"'),
    (PLANAR, "[mechanism]", "[mechanism]\ncolour = \"red\""),
    (PLANAR, "mass = 3.0", "mass = 0.0"),
    (PLANAR, "mass = 3.0", "mass = \"3\""),
    (PLANAR, "mass = 3.0", "mass = 3.0\nvolume = 1.0"),
    (PLANAR, 'name = "slider1"', 'name = "base"'),
    (PLANAR, 'name = "slider1"', 'name = "1slider"'),
    (PLANAR, "gravity = [0.0, -9.81]", "gravity = [0.0, -9.81, 0.0]"),
    (PLANAR, 'type = "translational"', 'type = "spherical"'),
    (PLANAR, 'type = "translational"', 'type = "prismatic"'),
    (PLANAR, "v = [0.0, 1.0]", "v = [0.0, 0.0]"),
    (PLANAR, "mu = ", "mu = -1.0\nold_mu = "),
    (PLANAR, "\nv_reg = 1e-3", "\nv_reg = 0.0"),
    (PLANAR, 'law = "regularised"', 'law = "stribeck"'),
    (PLANAR, 'law = "regularised"', 'law = "viscous"'),
    (PLANAR, "[[loads]]", "[[loads]]\ntype = \"magnet\"\nbody = \"slider1\"\n[[loads]]"),
    (SPATIAL, "inertia = [", "inertia = 1.0\nold_inertia = ["),
    (SPATIAL, 'type = "spherical"', 'type = "translational"'),
    (SCENE, "[scene]", "[scene]\nauthor = \"me\""),
    (SCENE, "stop_time = 4.0", "stop_time = \"4 s\""),
    (SCENE, "eliminate = [4]", "eliminate = \"some\""),
    (SCENE, "eliminate = [4]", "eliminate = [0]"),
    (SCENE, "eliminate = [4]", "redundancy = \"eliminate\""),
    (SCENE, "eliminate = [4]", "eliminate = [4]\nredundancy = \"least-squares\""),
    (SCENE, "[outputs]", "[outputs]\nenergy = \"yes\""),
    (SCENE, "[outputs]", "[outputs]\naccelerations = \"all\""),
    (SCENE, "tolerance = 1e-9", "tolerance = 1.0"),
    (SCENE, "tolerance = 1e-9", "tolerance = 1e-9\nmethod = \"euler\""),
    (SCENE, "tolerance = 1e-9", "tolerance = 1e-9\nfriction_max_iter = 0"),
    (SCENE, "tolerance = 1e-9", "tolerance = 1e-9\nbaumgarte = -1.0"),
    (SCENE, "tolerance = 1e-9", "tolerance = 1e-9\nstep_size = 0.001"),
]


@pytest.mark.parametrize("path,old,new", BAD, ids=[f"{p.stem}:{n.splitlines()[0][:30]}" for p, _o, n in BAD])
def test_the_schema_rejects_what_the_validator_rejects(path, old, new, tmp_path, validator):
    text = path.read_text(encoding="utf-8")
    assert old in text, old
    bad = tmp_path / path.name
    bad.write_text(text.replace(old, new, 1), encoding="utf-8")
    if path == SCENE:  # the scene's mechanism beside it
        (tmp_path / PLANAR.name).write_text(PLANAR.read_text(encoding="utf-8"), encoding="utf-8")
    with pytest.raises(sc.SceneError):
        sc.load(bad)
    doc = tomllib.loads(bad.read_text(encoding="utf-8"))
    assert list(validator.iter_errors(doc)), f"the schema accepts {new!r}"


def test_a_key_the_validator_gains_is_accepted_until_described(monkeypatch):
    """A section or key added to scene.py's tables (by a later feature) is taken by the schema with
    any value, so the schema never refuses what the validator accepts; one it drops is refused."""
    doc = tomllib.loads(SCENE.read_text(encoding="utf-8"))
    doc["actuators"] = [{"name": "u"}]  # a section no validator table has (yet)
    assert list(jsonschema.Draft7Validator(schema.scene_schema()).iter_errors(doc))
    monkeypatch.setattr(sc, "SCENE_SECTIONS", sc.SCENE_SECTIONS + ("actuators",))
    assert list(jsonschema.Draft7Validator(schema.scene_schema()).iter_errors(doc)) == []
