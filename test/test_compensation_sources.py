"""The source documents' compensation experiments (shortened runs of bench/compensation.py): orderings and thresholds.

Goals of issue 4 that the simulation does NOT reach are not asserted here; the benchmark prints
their figures (see the report / README): the 0.4 rad PTP ranking (gain scheduling does not end
within 1e-4 rad, the cascade is faster; DNPF hunts instead of stopping short) and the Tilakaratna et al. 2004
P-control limit cycle. GA friction thesis 2002 item 7 is met on the thesis's own plant model (explicit F(v),
sgn(0) = 0, no stick logic); with the preset's GKF stick logic it is not (ratio ~1, asserted as the
documented cause: the backward-difference velocity is exactly 0 while stuck, so F_hat = 0). ABB M19-S paper runs use the truth GMS with presliding micro-damping
(bench.SIGMA1, see bench/compensation.py).
"""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.append(
    str(Path(__file__).resolve().parents[1] / "bench")
)  # after site-packages: bench/can.py must not shadow python-can

import compensation as bench  # noqa: E402

OURS = bench.FF_CASES[-1][0]


@pytest.fixture(scope="module")
def table2():
    return {
        s: {r["case"]: r for r in bench.abb_m19s_feedforward_table(0.005, 10.0, s)}
        for s in ("preset", "ideal")
    }


@pytest.fixture(scope="module")
def table3():
    return {r["case"]: r for r in bench.abb_m19s_feedforward_table(np.pi, 10.0, "preset")}


def test_abb_m19s_table2_ordering(table2):
    for rows in table2.values():
        none, coul, lugre, gms = (rows[k]["rms_error"] for k in ("none", "Coulomb", "LuGre", "GMS"))
        assert abs(coul / none - 1.0) < 0.15  # Coulomb "almost identical" to no feed-forward
        assert lugre < 0.8 * none and gms < lugre  # none ~ Coulomb > LuGre > GMS
        assert 0.8e-3 < none < 1.6e-3  # the paper's 1.2 mrad scale
    # our feed-forward + feedback combination: >= 95 % with ideal sensing, >= 90 % with the encoder
    assert table2["ideal"][OURS]["reduction"] >= 0.97
    assert table2["preset"][OURS]["reduction"] >= 0.90


def test_abb_m19s_table2_goals_gms_89_and_ours_95_with_encoder(table2):
    rows = table2["preset"]  # encoder 1.05e-4 rad, 0.5 ms current lag, current noise
    assert rows["GMS"]["reduction"] >= 0.89 + 0.03  # paper 1.20 -> 0.13 mrad (-89 %); ours ~ -96 %
    assert rows[OURS]["reduction"] >= 0.95  # issue goal (ours ~ -96.5 %)
    assert rows["GMS"]["rms_error"] < 0.5 * rows["LuGre"]["rms_error"]  # paper: GMS 62 % better
    assert 0.0 < rows["Coulomb"]["reduction"] < 0.15  # paper -8.3 % ("almost identical")


def test_abb_m19s_table3_thresholds(table3):
    none = table3["none"]["rms_error"]
    assert table3["GMS"]["reduction"] >= 0.56 + 0.2  # goal -56 %, with margin
    assert table3[OURS]["reduction"] >= 0.70 + 0.2  # goal -70 %
    assert (
        table3["Coulomb"]["rms_error"] < none
        and table3["LuGre"]["rms_error"] < table3["Coulomb"]["rms_error"]
    )
    assert table3["GMS"]["rms_error"] <= table3["LuGre"]["rms_error"]


@pytest.fixture(scope="module")
def ga_thesis_results():
    return bench.ga_thesis_compensation(quick=True)


def test_ga_thesis_item7_compensated_rms_at_most_25_percent_thesis_model(ga_thesis_results):
    res = ga_thesis_results["item7"][
        "thesis model"
    ]  # 40 s of the parabola (GA friction thesis 2002 section 9.7 full 141 s: 0.797 / 0.138)
    unc = res["uncompensated"]["rms_deviation"]
    comp = res["compensated k_c=0.95"]["rms_deviation"]
    assert 0.6 < unc < 1.0  # lags T(s) by ~ the 1 rad break-away error
    assert res["ratio"] <= 0.25 - 0.05  # goal <= 25 %; ours ~14 % (40 s), ~17 % (141 s)
    assert comp < 0.15 and res["compensated k_c=0.95"]["max_deviation"] < 1.0
    assert res["compensated k_c=0.95"]["max_command"] < bench.GA_THESIS_LOOP_LIMITS["u_clamp_max"]


def test_ga_thesis_stick_logic_plant_disables_measured_velocity_compensation(ga_thesis_results):
    # the cause of the 0.90 ratio: exact sticking -> omega_hat == 0 -> F_hat(0) = 0 (sgn(0) = 0)
    assert ga_thesis_results["item7"]["GKF stick logic (preset)"]["ratio"] > 0.8
    rs = ga_thesis_results["item8"]["GKF stick logic (preset)"]  # |u| <= 1 rad < F_ST: never breaks away
    assert rs["compensated k_c=0.95"]["rms_deviation"] == rs["uncompensated"]["rms_deviation"]
    # on the thesis model the random steps move the compensated shaft (thesis Fig. 5.8)
    assert ga_thesis_results["item8"]["thesis model"]["ratio"] < 0.95


def test_ga_thesis_item9_thesis_model_over_compensation_runs_away(ga_thesis_results):
    m = ga_thesis_results["item9"]["thesis model"]
    assert m["F_hat = 1.1 F, k_c = 1"] > 0.5  # negative friction: self-motion
    assert m["accurate, k_c = 0.95"] < 0.02  # stops (friction-free coast would be 0.05 rad)


def test_ga_thesis_item9_over_compensation_self_motion():
    out = bench.ga_thesis_compensation(quick=True)["self_motion"]
    assert out["F_hat = 1.1 F, k_c = 1"] > 0.5  # runs away on its own (negative friction)
    assert out["accurate, k_c = 0.95"] < 0.005  # the nudge dies out


def test_ai_chapter_sinusoids_model_compensation_halves_rmse():
    rows = bench.ai_chapter_sinusoids(2.0, amplitudes=(0.1, 0.5))
    for r in rows:
        assert r["reduction_FF"] >= 0.5 + 0.2, r


def test_abb_m19s_point_to_point_single_step_qualitative_results():
    """0.4 rad step (Fig. 11): gain scheduling ends within 1e-4 rad faster than the integrating
    cascade; DNPF is first inside 1e-4 rad but without a dead zone it hunts, with one it stops short."""
    for sensing in ("preset", "ideal"):
        rows = {r["case"]: r for r in bench.abb_m19s_point_to_point(1.0, sensing)}
        gs, cas = rows["gain scheduling"], rows["cascade (PI velocity loop)"]
        assert gs["final_error"] < 1e-4 and cas["final_error"] < 1e-4, sensing
        assert gs["settle_1e-4"] < 0.6 * cas["settle_1e-4"], (sensing, gs, cas)
        if sensing == "preset":  # the integrator hunts by one encoder count; gain scheduling rests
            assert gs["hunting_reversals"] < 0.2 * cas["hunting_reversals"], (gs, cas)
        pd = rows["PD (paper gains)"]
        assert 3e-4 < pd["final_error"] < 4e-3 and pd["error_0.5s"] == pytest.approx(pd["final_error"])
        dnpf, short = rows["DNPF"], rows["DNPF, dead zone Q_h/4"]
        assert dnpf["first_1e-4"] <= gs["first_1e-4"] and dnpf["enter_q_h"] <= gs["enter_q_h"]
        assert dnpf["hunting_reversals"] >= 100 and dnpf["final_error"] > 1e-4
        assert short["error_0.5s"] == pytest.approx(short["final_error"], abs=1e-6)  # at rest
        assert 1e-4 < short["final_error"] <= 1e-3


@pytest.fixture(scope="module")
def ptp_sweep():
    cases = (
        "PD + Coulomb (mode 1 only)",
        "gain scheduling",
        "DNPF, dead zone Q_h/4",
        "cascade (PI velocity loop)",
    )
    return {
        r["case"]: r
        for r in bench.abb_m19s_point_to_point_sweep(amplitudes=(0.05, 0.2, 0.4, 0.8), cases=cases)
    }


def test_abb_m19s_point_to_point_sweep_gain_scheduling_settles_faster_than_cascade(ptp_sweep):
    gs, cas = ptp_sweep["gain scheduling"], ptp_sweep["cascade (PI velocity loop)"]
    assert gs["settled_fraction"] >= 0.85 and cas["settled_fraction"] >= 0.85, (gs, cas)
    assert gs["settle_median"] < 0.6 * cas["settle_median"], (gs, cas)
    assert gs["final_error_max"] < 2e-4  # at worst one encoder count (1.05e-4 rad) off


def test_abb_m19s_point_to_point_sweep_pd_coulomb_stalls_and_dnpf_stops_short(ptp_sweep):
    for name in ("PD + Coulomb (mode 1 only)", "DNPF, dead zone Q_h/4"):
        r = ptp_sweep[name]
        assert r["settled_fraction"] <= 0.25, r  # most steps end outside 1e-4 rad ...
        assert 1.5e-4 < r["final_error_median"] < 4e-3, r  # ... at rest inside Q_h = 4e-3 rad
    assert ptp_sweep["DNPF, dead zone Q_h/4"]["final_error_max"] <= 1e-3 + 1e-4  # inside its dead zone


@pytest.fixture(scope="module")
def tilakaratna_rows():
    return {r["case"]: r for r in bench.tilakaratna_step_hunting(10.0)}


def test_tilakaratna_p_control_dead_band_25_counts_and_compensation_few_counts(tilakaratna_rows):
    coul = tilakaratna_rows[
        "P, Coulomb, Kp_eff 0.25"
    ]  # paper x axis: SSE 25 counts (Tilakaratna et al. 2004 B-T6/B-T7)
    assert abs(coul["final_error_counts"]) == pytest.approx(25.0, abs=3.0)
    assert coul["stick_slip_starts"] == 0
    p, comp = tilakaratna_rows["P, stiction, Kp 2e6"], tilakaratna_rows["P + comp. (blended)"]
    assert abs(comp["final_error_counts"]) <= 3.5  # "within a few counts" (ours ~3)
    assert abs(comp["final_error_counts"]) < 0.6 * abs(p["final_error_counts"])  # P alone ~6
    assert comp["stick_slip_starts"] == 0


def test_tilakaratna_p_only_does_not_hunt_documented_gap(tilakaratna_rows):
    # NOT the paper's result: under P-only the x axis sticks in the dead band |e| <= F_s / Kp
    # (preset C_r = 0.15, with stiction and the 3 ms delay), or, with C_r = 0.01 and Kp = 2e6,
    # delay + current lag destabilise the loop into a current-limited ~1300-count oscillation.
    for case in ("P, stiction 16 N", "P, stiction, Kp 2e6"):
        assert (
            tilakaratna_rows[case]["stick_slip_starts"] == 0
            and tilakaratna_rows[case]["hunting_amplitude_counts"] < 1.0
        )
    assert tilakaratna_rows["P, stiction, Kp 2e6, C_r 0.01"]["hunting_amplitude_counts"] > 500.0
    # PI + stiction hunts (Tilakaratna et al. 2004 B-T8); stiction compensation on the delayed encoder velocity does not remove it
    assert tilakaratna_rows["PI, stiction"]["stick_slip_starts"] >= 1
    assert (
        tilakaratna_rows["PI + comp. (blended)"]["stick_slip_starts"]
        >= tilakaratna_rows["PI, stiction"]["stick_slip_starts"]
    )


def test_tilakaratna_smc_relay_compensation_reaches_a_few_counts_without_hunting(tilakaratna_rows):
    """Chatterjee et al. 2017's sliding-mode relay (M = the stiction estimate) on the paper's P stiffness: the
    36-count dead band of P + stiction and the PI hunting are both gone (ends within ~1 count)."""
    smc, p, pi = (
        tilakaratna_rows["P + Chatterjee et al. 2017 SMC relay (F_s estimate)"],
        tilakaratna_rows["P, stiction 16 N"],
        tilakaratna_rows["PI, stiction"],
    )
    assert abs(p["final_error_counts"]) > 30.0
    assert pi["hunting_amplitude_counts"] > 2.0
    assert abs(smc["final_error_counts"]) <= 2.0
    assert smc["stick_slip_starts"] == 0 and smc["hunting_amplitude_counts"] < 0.5
    assert smc["settle_2counts"] < 4.0
