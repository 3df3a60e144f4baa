"""The controller's terms file: what friction-demo's figures are computed from."""

from __future__ import annotations

from friction_ros.core.control.controller import CompensatingController
from friction_ros.nodes.terms_file import COLUMNS, TermsFile, read_terms_file


def test_rows_round_trip_exactly_and_a_cut_row_is_skipped(tmp_path):
    ctrl = CompensatingController({"pid": {"p": 20.0, "d": 0.5}, "effort_limit": 3.0})
    path = tmp_path / "terms.csv"
    f = TermsFile(str(path))
    written = []
    for k in range(5):
        terms = ctrl.compute(k * 1e-3, (0.1, 0.2, 0.0), (1e-4 * k, 0.0), 1e-3)
        f.add(k * 1_000_000, "joint1", terms)
        written.append(terms.command)
    f.close()
    with open(path, "a", encoding="utf-8") as fh:
        fh.write("5000000,joint1,0.1,0.2")  # a row cut by an abrupt end
    cols = read_terms_file(str(path))
    assert list(cols) == list(COLUMNS)
    assert cols["stamp_ns"] == [0, 1_000_000, 2_000_000, 3_000_000, 4_000_000]
    assert cols["command"] == written  # repr() round-trips floats bit for bit
    assert cols["joint"] == ["joint1"] * 5 and cols["compensation_fallback"] == [0.0] * 5
