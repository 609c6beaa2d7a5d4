"""``check`` says which equations belong to which joint and, when it refuses an elimination,
which ones are valid (issue 37, item 7): in the table, in the message and in the JSON document
(keys added, none renamed)."""
from __future__ import annotations

import json
from pathlib import Path

from overcon.cli import main

ROOT = Path(__file__).resolve().parents[1]
PLANAR = ROOT / "mechanisms" / "planar_f1_wo4.toml"


def test_table_and_json_show_each_joints_equations(capsys):
    assert main(["check", str(PLANAR)]) == 1  # friction on a non-unique reaction
    table = capsys.readouterr().out
    assert "joint      type           equations unique  rank   svd    qr     friction" in table
    assert "joint2     translational  3-4       no" in table and "joint6     revolute       11-12     yes" in table
    main(["check", str(PLANAR), "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert [j["equations"] for j in doc["joints"]] == [[1, 2], [3, 4], [5, 6], [7, 8], [9, 10], [11, 12]]
    assert list(doc["joints"][0])[:6] == ["name", "unique", "methods", "rank_defect", "agree", "type"]  # kept


def test_a_refused_elimination_lists_the_valid_ones(capsys):
    assert main(["check", str(PLANAR), "--eliminate", "1"]) == 2
    err = capsys.readouterr().err
    assert ("--eliminate: eliminating Phi1 removes an independent equation: rank of the kept equations is 10 < "
            "rank 11 of all 12; the mechanism would gain 1 DOF. Valid eliminations at q0: [2]; [4]; [6], or "
            "eliminate = \"auto\". Equations per joint: joint1 Phi1-Phi2, joint2 Phi3-Phi4") in err, err
    assert main(["check", str(PLANAR), "--eliminate", "1", "--json"]) == 2
    doc = json.loads(capsys.readouterr().out)
    assert doc["valid_eliminations"] == [[2], [4], [6]] and doc["valid_eliminations_complete"] is True
    assert doc["joint_equations"]["joint3"] == [5, 6]
    assert doc["error"].startswith(f"{PLANAR}: --eliminate: eliminating Phi1")


def test_too_few_eliminated_lists_the_valid_ones_too(capsys):
    """spatial_MN_wo5 has 36 equations of rank 35: keeping all is refused, and with one equation to
    remove, every one of the first ten is valid; the list says it may go on."""
    assert main(["check", str(ROOT / "mechanisms" / "spatial_MN_wo5.toml"), "--eliminate", "none"]) == 2
    err = capsys.readouterr().err
    assert "leaves 36 equations of rank 35: 1 more must be eliminated" in err, err
    assert "Valid eliminations at q0 (the first found; there may be more): [1]; [2]; [3]" in err
