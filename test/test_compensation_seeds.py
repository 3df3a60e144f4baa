"""Seed compensation experiments (shortened runs of bench/compensation.py): orderings and thresholds.

Goals of issue 4 that the simulation does NOT reach are not asserted here; the benchmark prints
their figures (see the report / README): seed 003 Table 2 GMS -89 %, the 0.4 rad PTP ranking,
seed 001 item 7 and the seed 002 P-control limit cycle.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

import compensation as bench  # noqa: E402


@pytest.fixture(scope="module")
def table2():
    return {s: {r["case"]: r for r in bench.seed003_ff_table(0.005, 10.0, s)} for s in ("preset", "ideal")}


@pytest.fixture(scope="module")
def table3():
    return {r["case"]: r for r in bench.seed003_ff_table(np.pi, 10.0, "preset")}


def test_seed003_table2_ordering(table2):
    for rows in table2.values():
        none, coul, lugre, gms = (rows[k]["rms_error"] for k in ("none", "Coulomb", "LuGre", "GMS"))
        assert abs(coul / none - 1.0) < 0.15  # Coulomb "almost identical" to no feed-forward
        assert lugre < 0.8 * none and gms < lugre  # none ~ Coulomb > LuGre > GMS
        assert 0.8e-3 < none < 1.6e-3  # the paper's 1.2 mrad scale
    # our feed-forward + feedback combination: >= 95 % with ideal sensing, >= 90 % with the encoder
    assert table2["ideal"]["ours: GMS FF 70% + FB 30%"]["reduction"] >= 0.97
    assert table2["preset"]["ours: GMS FF 70% + FB 30%"]["reduction"] >= 0.90


def test_seed003_table3_thresholds(table3):
    none = table3["none"]["rms_error"]
    assert table3["GMS"]["reduction"] >= 0.56 + 0.2  # goal -56 %, with margin
    assert table3["ours: GMS FF 70% + FB 30%"]["reduction"] >= 0.70 + 0.2  # goal -70 %
    assert (
        table3["Coulomb"]["rms_error"] < none
        and table3["LuGre"]["rms_error"] < table3["Coulomb"]["rms_error"]
    )
    assert table3["GMS"]["rms_error"] <= table3["LuGre"]["rms_error"]


def test_seed001_item9_over_compensation_self_motion():
    out = bench.seed001(quick=True)["self_motion"]
    assert out["F_hat = 1.1 F, k_c = 1"] > 0.5  # runs away on its own (negative friction)
    assert out["accurate, k_c = 0.95"] < 0.005  # the nudge dies out


def test_seed004_sinusoids_model_compensation_halves_rmse():
    rows = bench.seed004(2.0, amplitudes=(0.1, 0.5))
    for r in rows:
        assert r["reduction_FF"] >= 0.5 + 0.2, r


def test_seed003_ptp_schemes_run_and_dnpf_beats_pd_coulomb_inside_presliding():
    rows = {r["case"]: r for r in bench.seed003_ptp(1.0, "ideal")}
    assert rows["DNPF"]["error_0.5s"] < 0.7 * rows["PD + Coulomb (mode 1 only)"]["error_0.5s"]
    for r in rows.values():
        assert np.isfinite(r["final_error"]) and r["final_error"] < 0.02
