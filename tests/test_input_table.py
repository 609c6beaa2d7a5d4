"""Input tables (overcon.tooling.inputs): reading, the checks that make a bad table bad input
(file, column and row named), the signal's semantics, and agreement with fmpy's own reading of the
same structured array (fmpy.simulation.Input)."""
from __future__ import annotations

import numpy as np
import pytest

from overcon.tooling import InputError
from overcon.tooling.inputs import MAX_ROWS, InputTable, read_input_table


def write(tmp_path, text, name="in.csv"):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_reads_columns_in_any_order_quoted_or_not(tmp_path):
    p = write(tmp_path, '"force","time",motor\n1.5,0,2\n-1,0.5,3\n\n4,2.0,5e-1\n')
    tab = read_input_table(p, ["motor", "force"])
    assert tab.names == ["motor", "force"]  # the caller's order, not the file's
    assert np.array_equal(tab.time, [0.0, 0.5, 2.0])
    assert np.array_equal(tab.values["motor"], [2.0, 3.0, 0.5])
    assert np.array_equal(tab.values["force"], [1.5, -1.0, 4.0])
    s = tab.structured()
    assert s.dtype == np.dtype([("time", "<f8"), ("motor", "<f8"), ("force", "<f8")])
    assert np.array_equal(s["time"], tab.time) and np.array_equal(s["force"], tab.values["force"])
    with pytest.raises(ValueError):
        tab.time[0] = 1.0  # the table is read-only, like the frozen dataclass holding it


@pytest.mark.parametrize("text, names, expect", [
    ("time,motor,brake\n0,1,2\n", ["motor"], ["'brake'", "not an input", "column 3"]),
    ("time,motor\n0,1\n", ["motor", "brake"], ["brake", "no column"]),
    ("motor\n1\n", ["motor"], ['"time"']),
    ("time,motor\n0,1\n1,nan\n", ["motor"], ["'motor'", "row 3", "non-finite"]),
    ("time,motor\n0,1\n1,inf\n", ["motor"], ["'motor'", "row 3", "non-finite"]),
    ("time,motor\n0,1\n1,abc\n", ["motor"], ["'motor'", "row 3", "not a number"]),
    ("time,motor\n0,1\n0,2\n", ["motor"], ["'time'", "row 3", "increase"]),
    ("time,motor\n0,1\n1,2\n0.5,3\n", ["motor"], ["'time'", "row 4", "increase"]),
    ("time,motor\n0,1\n1\n", ["motor"], ["row 3", "1 value"]),
    ("time,motor\n0,1,7\n", ["motor"], ["row 2", "3 value"]),
    ("", ["motor"], ["empty"]),
    ("\n \n", ["motor"], ["empty"]),
    ("time,motor\n", ["motor"], ["no rows"]),
    ("time,motor,motor\n0,1,1\n", ["motor"], ["'motor'", "twice"]),
    ("time,motor\n0,1\n", [], ["no inputs"]),
])
def test_bad_tables_name_file_column_and_row(tmp_path, text, names, expect):
    p = write(tmp_path, text)
    with pytest.raises(InputError) as info:
        read_input_table(p, names)
    msg = str(info.value)
    assert str(p) in msg
    for e in expect:
        assert e in msg, msg
    assert isinstance(info.value, ValueError)  # the CLI maps ValueError (and InputError) to exit 2


def test_missing_file_and_non_utf8_are_bad_input(tmp_path):
    with pytest.raises(InputError, match="nope.csv"):
        read_input_table(tmp_path / "nope.csv", ["motor"])
    p = tmp_path / "latin.csv"
    p.write_bytes(b"time,motor\n0,\xff\n")
    with pytest.raises(InputError, match="UTF-8"):
        read_input_table(p, ["motor"])


def test_too_many_rows_and_bytes_are_bad_input(tmp_path, monkeypatch):
    from overcon.tooling import inputs

    assert MAX_ROWS == 1_000_000  # the bound itself; lowered below so that the test stays small
    monkeypatch.setattr(inputs, "MAX_ROWS", 10)
    p = write(tmp_path, "time,u\n" + "".join(f"{i},0\n" for i in range(11)))
    with pytest.raises(InputError, match="11 rows, more than the 10"):
        read_input_table(p, ["u"])
    monkeypatch.setattr(inputs, "MAX_BYTES", 20)
    with pytest.raises(InputError, match="bytes, more than the 20"):
        read_input_table(p, ["u"])


def table(time, u):
    return InputTable(np.asarray(time, float), {"u": np.asarray(u, float)})


def test_signal_linear_between_rows_and_flat_outside():
    tab = table([1.0, 2.0, 4.0], [10.0, 20.0, 0.0])
    assert tab.at(0.0)["u"] == 10.0 and tab.at(1.0)["u"] == 10.0  # before the first row: the first value
    assert tab.at(1.5)["u"] == 15.0 and tab.at(2.0)["u"] == 20.0
    assert tab.at(3.0)["u"] == 10.0
    assert tab.at(4.0)["u"] == 0.0 and tab.at(9.0)["u"] == 0.0  # from the last row on: the last value
    # the slope at a row is the one of the segment ending there; 0 at/before the first row, after the last
    assert tab.slope(0.5)["u"] == 0.0 and tab.slope(1.0)["u"] == 0.0
    assert tab.slope(1.5)["u"] == 10.0 and tab.slope(2.0)["u"] == 10.0 and tab.slope(2.5)["u"] == -10.0
    assert tab.slope(4.0)["u"] == -10.0 and tab.slope(4.5)["u"] == 0.0
    with pytest.raises(ValueError, match="non-finite"):
        tab.at(float("nan"))


def test_hold_and_linear_over_a_step():
    tab = table([-1.0, 1.0], [-2.0, 2.0])
    assert tab.step(0.25, "hold") == ({"u": 0.5}, {"u": 0.0})
    assert tab.during(0.75, 0.25, "hold")["u"] == 0.5  # held over the step at its start value
    assert tab.during(0.75, 0.25, "linear")["u"] == pytest.approx(1.5, abs=1e-15)  # = u(0.75) on one segment
    # a bend inside or at the start of the step is seen one communication point late (fmpy's rule)
    bend = table([0.0, 0.5, 1.0], [0.0, 1.0, 1.0])
    assert bend.during(1.0, 0.0, "linear")["u"] == 0.0  # the step starting at the first row is held
    assert bend.during(1.0, 0.5, "linear")["u"] == 2.0  # the step at the bend keeps the segment before it
    with pytest.raises(InputError, match="cubic"):
        tab.step(0.0, "cubic")


def test_one_row_is_a_constant():
    tab = table([0.3], [7.0])
    assert tab.at(0.0)["u"] == 7.0 and tab.at(5.0)["u"] == 7.0 and tab.slope(0.3)["u"] == 0.0


def test_same_values_and_slopes_as_fmpy_reads_from_the_structured_array():
    """fmpy.simulation.Input.interpolate on the structured array gives the values of at() (to the
    bit) and the derivatives of slope(): the table means the same to overcon and to fmpy (before,
    at, between and after the rows)."""
    fmpy_sim = pytest.importorskip("fmpy.simulation")
    tab = table([0.2, 0.5, 1.0, 1.7], [1.0, -2.0, 4.0, 0.5])
    s = tab.structured()
    rows = np.array([s["u"]])
    for when in [0.0, 0.2, 0.3, 0.5, 0.77, 1.0, 1.1 / 3.0, 1.69, 1.7, 3.0]:
        v, d = fmpy_sim.Input.interpolate(when, s["time"], rows, discrete=False, after_event=True)
        assert float(np.ravel(v)[0]) == tab.at(when)["u"], when
        assert float(np.ravel(d)[0]) == tab.slope(when)["u"], when
