"""Benchmark: identification on realistic and real joint data (issue 17).

1. Realistic synthetic joint (:mod:`friction_ros.core.synthetic.realistic_joint`, known truth:
   gravity 12 N*m, spring, offset + sensor offset, Stribeck map, load-dependent friction k_L = 0.03 and
   a Coulomb ripple at the motor angle of the 100:1 harmonic drive; 3 runs x 40 s at 2 ms, seed 0).
   ``fit_records`` with load="auto", residual="auto" and ``ripple_period = 2 pi / 100`` (the truth's
   ripple repeats once per wave-generator turn = 1/100 of a link turn; the fitter's default 2 pi would
   look for it at the link angle and miss it), models coulomb_viscous, stribeck, lugre, nusvr:
   validation NMSE, RMS, fit time, the static friction map against the truth's (max |F_fit - F_true| /
   max |F_true| over 0.005 <= |v| <= 0.4 rad/s, both directions), gravity and load-friction errors,
   next to the noise floors (pooled noise floor; the true model fed the logged position and velocity).
   The same fit with load="none" shows what the load terms bring; cross-validation over the runs
   (train on two, validate on the third) shows what a user deploying the model gets on a new run.
2. Real pendulum (DFKI torque-limited simple pendulum, AK80-6 motor, real logs): per run
   (pd_system_identification, energy_shaping, gravity_compensation) coulomb_viscous and stribeck with
   load="auto" and load="none" (train_seconds ~40 % of the run; residual="auto" as friction-fit): NMSE, RMS, recommended model, the
   chosen load terms, the identified gravity m g l against the authors' m cx g = 0.1022 * 9.81 = 1.003
   N*m, whether the fit was flagged (verdict explains_little). Data checks: the authors' own model
   (system_identification.txt) on every run, tau against a sin q + b, the share of torque beyond the
   kit's 4 N*m limit. Uses /work/shared/data/dfki_pendulum when present, else the sys-id run copied
   into test/data/dfki_pendulum (a user's clone): the printed notes and the JSON say which.
3. Learned residual inference time: per residual candidate the report's step() time, and for every
   exported residual the median of 10,000 single ``LearnedResidual.step`` calls (goal < 20 us).
4. Gauntlet (bench/_gauntlet.py): the fitter with friction-fit's defaults on every class of log users
   bring (friction_ros.core.synthetic.logs: ball-screw axis in m/N, hobby servo, coupled arm, LuGre
   creep, coarse encoder, jittered/missing samples, saturation, one direction only) and both joints
   of the real DFKI double pendulum: recommended model, validation NMSE, verdict and warnings per log.
5. Long logs (``bench/_long_logs.py``): friction-fit on a 60 s, 10 min and 1 h log (bag, and the 1 h
   one as CSV) and on a 7-joint 21 s arm bag with ``--jobs 2``: seconds and peak RSS, each in its own
   process.

    .venv/bin/python bench/real_data.py            # full (~100 s CPU + the gauntlet's ~4 min CPU)
    .venv/bin/python bench/real_data.py --quick    # 20 s runs, no lugre/nusvr (smoke test)
    .venv/bin/python bench/real_data.py --gauntlet # section 4 alone (bench/_gauntlet.py)
    .venv/bin/python bench/real_data.py --section long_logs   # friction-fit on 60 s .. 1 h logs, 7-joint arm
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.append(str(ROOT / "bench"))  # after site-packages: bench/can.py must not shadow python-can

from _common import print_table, write_results  # noqa: E402
from _gauntlet import gauntlet  # noqa: E402
from _real_pendulum import pendulum  # noqa: E402
from _real_synthetic import _f, _residual_entries, _time_step, synthetic  # noqa: E402

from friction_ros.core.identification.data.records import concat_records  # noqa: E402
from friction_ros.core.identification.fit.residual_learning import fit_residual  # noqa: E402

GOAL = {"map_percent": 5.0, "gravity_percent": 2.0, "load_friction_percent": 10.0, "floor_ratio": 1.5}
STEP_GOAL_US = 20.0


# ------------------------------------------------------------------------------------ residual
def residual_timing(syn_res, pend_fits: dict) -> dict:
    entries = _residual_entries("synthetic", syn_res)
    for (name, load), res in pend_fits.items():
        entries += _residual_entries(f"pendulum {name} load={load}", res)
    fallback = None
    if not entries:  # no residual chosen anywhere: one on the synthetic recommended model's residual
        base = syn_res.models[syn_res.recommended]
        tr = syn_res.train
        model, rep = fit_residual(
            [r.position for r in tr],
            [r.velocity for r in tr],
            None,
            [r.torque - base.predict(r) for r in tr],
            float(tr[0].dt),
            kind="auto",
            seed=0,
        )
        if model is None:  # nothing beat r = 0: time the MLP anyway (the run-time cost is the same)
            model = rep["models"]["mlp"]
        rec = concat_records(tr)
        fallback = {
            "chosen": rep["chosen"],
            "kind": model.kind,
            "candidates": {
                c: {k: v for k, v in i.items() if isinstance(v, (int, float, str, bool))}
                for c, i in rep["candidates"].items()
            },
            "step_us_median_10k": _time_step(model, rec.position, rec.velocity),
        }
    rows = []
    for e in entries:
        for c, info in e["candidates"].items():
            rows.append(
                [
                    e["data"],
                    e["model"] + (" *" if e["recommended"] else ""),
                    c + (" (chosen)" if c == e["chosen"] else ""),
                    info.get("n_params", "-"),
                    _f(info.get("fit_s"), 2),
                    _f(info.get("validation_nmse_percent"), 1),
                    _f(info.get("step_us"), 1),
                    _f(e["step_us_median_10k"], 1) if c == e["chosen"] else "-",
                ]
            )
    if fallback:
        for c, info in fallback["candidates"].items():
            rows.append(
                [
                    "synthetic (fit_residual, fallback)",
                    "-",
                    c + (" (timed)" if c == fallback["kind"] else ""),
                    info.get("n_params", "-"),
                    _f(info.get("fit_s"), 2),
                    _f(info.get("validation_nmse_percent"), 1),
                    _f(info.get("step_us"), 1),
                    _f(fallback["step_us_median_10k"], 1) if c == fallback["kind"] else "-",
                ]
            )
    print_table(
        f"Learned residual: candidates of every '+residual' model (residual validation NMSE % = of the physics "
        f"model's residual; step = per-sample run-time evaluation; goal < {STEP_GOAL_US:g} us; * = recommended)",
        [
            "data",
            "model",
            "candidate",
            "params",
            "fit [s]",
            "resid. NMSE %",
            "step [us] report",
            "step [us] 10k median",
        ],
        rows,
    )
    steps = [e["step_us_median_10k"] for e in entries] + (
        [fallback["step_us_median_10k"]] if fallback else []
    )
    return {"entries": entries, "fallback": fallback, "max_step_us": max(steps) if steps else None}


# ------------------------------------------------------------------------------------ goals
def goals(syn: dict, pend: dict, resid: dict) -> list[dict]:
    a = syn["load_auto"]
    rec = a["recommended"]
    m = a["models"][rec]
    floor = syn["floors"]["loader_input_nmse_percent"]
    out = [
        {
            "goal": f"synthetic: friction map of the recommended model ({rec}) within {GOAL['map_percent']:g} %",
            "measured": m["map_error_percent"],
            "met": m["map_error_percent"] <= GOAL["map_percent"],
        },
        {
            "goal": f"synthetic: gravity within {GOAL['gravity_percent']:g} % ({rec})",
            "measured": m["gravity_error_percent"],
            "met": m["gravity_error_percent"] is not None
            and m["gravity_error_percent"] <= GOAL["gravity_percent"],
        },
        {
            "goal": f"synthetic: load-friction coefficient k_L within {GOAL['load_friction_percent']:g} % ({rec})",
            "measured": m["load_friction_error_percent"],
            "met": m["load_friction_error_percent"] is not None
            and m["load_friction_error_percent"] <= GOAL["load_friction_percent"],
        },
        {
            "goal": f"synthetic: recommended validation NMSE within {GOAL['floor_ratio']:g} x the true model on "
            f"the same validation inputs ({floor:.4f} %; velocity and acceleration from the logged positions)",
            "measured": m["nmse_percent"] / floor,
            "met": m["nmse_percent"] <= GOAL["floor_ratio"] * floor,
        },
    ]
    gc = pend["runs"].get("gravity_compensation")
    if gc:
        out.append(
            {
                "goal": "pendulum: gravity term selected on the gravity_compensation run (load=auto)",
                "measured": gc["load_auto"]["load_terms"],
                "met": "gravity" in gc["load_auto"]["load_terms"].split(", "),
            }
        )
        out.append(
            {
                "goal": "pendulum: the no-gravity fit (load=none) of the gravity_compensation run flagged",
                "measured": f"flagged: {gc['load_none']['flagged']}",
                "met": gc["load_none"]["flagged"],
            }
        )
    else:
        out.append({"goal": "pendulum: gravity_compensation run", "measured": "not available", "met": None})
    out.append(
        {
            "goal": f"learned residual step() under {STEP_GOAL_US:g} us per sample (max over exported residuals)",
            "measured": resid["max_step_us"],
            "met": resid["max_step_us"] is not None and resid["max_step_us"] < STEP_GOAL_US,
        }
    )
    print_table(
        "Goals (issue 17)",
        ["goal", "measured", "met"],
        [
            [
                g["goal"],
                _f(g["measured"], 3) if isinstance(g["measured"], float) else str(g["measured"]),
                {True: "yes", False: "NO", None: "-"}[g["met"]],
            ]
            for g in out
        ],
    )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--quick", action="store_true", help="20 s synthetic runs, coulomb_viscous and stribeck only"
    )
    ap.add_argument("--gauntlet", action="store_true", help="run the gauntlet section alone")
    ap.add_argument(
        "--section",
        choices=["all", "identification", "long_logs"],
        default="all",
        help="long_logs: only the long-log rows (bench/_long_logs.py), merged into real_data.json",
    )
    args = ap.parse_args()
    if args.section == "long_logs":
        return _long_logs_only()
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    if args.gauntlet:
        figures = {
            "gauntlet": gauntlet(args.quick),
            "quick": args.quick,
            "wall_s": time.perf_counter() - t_wall,
        }
        name = "real_data_gauntlet" + ("_quick" if args.quick else "")
        write_results(
            name,
            figures,
            ".venv/bin/python bench/real_data.py --gauntlet" + (" --quick" if args.quick else ""),
        )
        return
    load_start = os.getloadavg()[0]  # other processes on the machine slow the step() timings
    syn, syn_res = synthetic(args.quick)
    pend, pend_fits = pendulum(args.quick)
    resid = residual_timing(syn_res, pend_fits)
    gaunt = gauntlet(args.quick)
    gl = goals(syn, pend, resid)
    notes = syn["notes"] + pend["findings"]
    print("\nNotes (measured on this run):")
    for n in notes:
        print(f"- {n}")
    figures = {
        "synthetic": syn,
        "pendulum": pend,
        "residual": resid,
        "gauntlet": gaunt,
        "goals": gl,
        "notes": notes,
        "load_average_1min": {"start": load_start, "end": os.getloadavg()[0]},
        "quick": args.quick,
        "wall_s": time.perf_counter() - t_wall,
        "cpu_s": time.process_time() - t_cpu,
    }
    if args.section == "all" and not args.quick:
        import _long_logs as long_logs

        figures["long_logs"] = long_logs.run(print_table)
    print(
        f"\nrun time: {figures['wall_s']:.0f} s wall, {figures['cpu_s']:.0f} s CPU (1-min load average "
        f"{load_start:.1f} at the start, {figures['load_average_1min']['end']:.1f} at the end, {os.cpu_count()} cores)"
    )
    write_results(
        "real_data" + ("_quick" if args.quick else ""),
        figures,
        ".venv/bin/python bench/real_data.py" + (" --quick" if args.quick else ""),
    )


def _long_logs_only() -> None:
    """The long-log rows alone, merged into the figures of bench/results/real_data.json."""
    import json

    import _long_logs as long_logs

    path = ROOT / "bench" / "results" / "real_data.json"
    figures = json.loads(path.read_text()).get("figures", {}) if path.is_file() else {}
    figures["long_logs"] = long_logs.run(print_table)
    write_results("real_data", figures, ".venv/bin/python bench/real_data.py --section long_logs")


if __name__ == "__main__":
    main()
