"""Benchmark: learned residual on a physics backbone (issue 17 item 4).

Per data set: a least-squares physics backbone on the first 60 % of every run, the residual
r = tau - tau_physics learned on the same 60 % (``fit_residual``: mlp, rff, and hgb for comparison)
and everything scored on the last 40 % of every run: validation NMSE of the torque (physics alone
vs physics + residual) and of the residual itself, RMS, fit time, and the per-sample inference time
of ``step()`` (median over >= 10,000 single calls) and of ``predict_batch`` (total / samples).

Data sets:

* ``pendulum``: the real DFKI pendulum logs (/work/shared/data/dfki_pendulum; 3 runs: PD sys-id,
  energy shaping, gravity compensation), resampled to a uniform 1 ms grid by linear interpolation
  (the logs' own steps are 3.3, 5 and 1 ms); backbone tau = J a + m cx g sin q + Fv v + Fc tanh(v /
  0.01) + offset, one model for the joint (all runs pooled), a = d/dt of the velocity smoothed by a
  zero-phase 20 Hz Butterworth. Data checks (the authors' model and per-run fits) are printed too;
* ``realistic``: :func:`friction_ros.core.synthetic.realistic_joint.realistic_runs` (known truth:
  gravity, spring, Stribeck, load-dependent and rippling friction, noise; 3 runs x 40 s at 2 ms),
  backbone J a + gravity (sin, cos) + spring + Coulomb-viscous + offset;
* ``hysteresis``: a joint with presliding hysteresis (Dahl) and frictional lag that the
  Coulomb-viscous backbone cannot represent (as test/test_learned_residual.py), 40 s at 1 ms.

    .venv/bin/python bench/learned_residual.py            # full
    .venv/bin/python bench/learned_residual.py --quick    # shorter synthetic records, no command variant
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.signal import butter, filtfilt

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.append(str(ROOT / "bench"))  # after site-packages: bench/can.py must not shadow python-can

from _common import print_table, write_results  # noqa: E402

from friction_ros.core.identification.fit.residual_learning import fit_residual  # noqa: E402

PENDULUM = Path("/work/shared/data/dfki_pendulum")
PENDULUM_RUNS = ("pd_system_identification", "energy_shaping", "gravity_compensation")
AUTHORS = {"J": 6.259e-02, "mcx": 1.022e-01, "Fv": 4.707e-02, "Fc": 1.839e-01, "offset": -7.586e-02}
TRAIN = 0.6


def _nmse(pred, y) -> float:
    return float(100.0 * np.mean((pred - y) ** 2) / np.var(y))


def _smoothed_acceleration(v, dt, cutoff=20.0):
    b, a = butter(2, cutoff / (0.5 / dt), btype="low")
    return np.gradient(filtfilt(b, a, v), dt)


def _backbone(runs, basis_fn):
    """Pooled least squares on the first TRAIN of every run; returns (theta, physics per run)."""
    bases = [basis_fn(r) for r in runs]
    cuts = [int(round(TRAIN * len(r["tau"]))) for r in runs]
    a = np.concatenate([b[:k] for b, k in zip(bases, cuts)])
    y = np.concatenate([r["tau"][:k] for r, k in zip(runs, cuts)])
    theta = np.linalg.lstsq(a, y, rcond=None)[0]
    for r, b in zip(runs, bases):
        r["phys"] = b @ theta
    return theta


def pendulum_data() -> tuple[list[dict], float, dict]:
    dt = 1e-3
    runs, checks = [], {}
    for name in PENDULUM_RUNS:
        d = np.loadtxt(PENDULUM / f"control_method_{name}.csv", delimiter=",", skiprows=1)
        t, q, v, tau = d.T
        tg = np.arange(0.0, t[-1], dt)
        r = {
            "name": name,
            "q": np.interp(tg, t, q),
            "v": np.interp(tg, t, v),
            "tau": np.interp(tg, t, tau),
            "raw_samples": int(t.size),
            "raw_dt_median": float(np.median(np.diff(t))),
        }
        r["a"] = _smoothed_acceleration(r["v"], dt)
        runs.append(r)

    def basis(r):
        return np.c_[r["a"], 9.81 * np.sin(r["q"]), r["v"], np.tanh(r["v"] / 0.01), np.ones_like(r["q"])]

    for r in runs:  # data checks: the authors' model and a per-run fit, whole run
        au = AUTHORS
        p = (
            au["J"] * r["a"]
            + au["mcx"] * 9.81 * np.sin(r["q"])
            + au["Fv"] * r["v"]
            + au["Fc"] * np.arctan(100 * r["v"])
            + au["offset"]
        )
        k = int(round(TRAIN * len(r["tau"])))
        th = np.linalg.lstsq(basis(r)[:k], r["tau"][:k], rcond=None)[0]
        checks[r["name"]] = {
            "authors_model_nmse_percent": _nmse(p, r["tau"]),
            "own_fit_validation_nmse_percent": _nmse(basis(r)[k:] @ th, r["tau"][k:]),
            "own_fit_theta": th.tolist(),
            "raw_samples": r["raw_samples"],
            "raw_dt_median": r["raw_dt_median"],
        }
    theta = _backbone(runs, basis)
    checks["pooled_theta [J, m*cx, Fv, Fc, offset]"] = theta.tolist()
    return runs, dt, checks


def realistic_data(duration: float) -> tuple[list[dict], float, dict]:
    from friction_ros.core.synthetic import realistic_joint

    logs = realistic_joint.realistic_runs(duration=duration, seed=0)
    dt = float(np.median(np.diff(logs[0].t)))
    runs = []
    for lg in logs:
        runs.append({"name": lg.name, "q": lg.position, "v": lg.velocity, "tau": lg.effort, "t": lg.t})
        # stamps jitter: smooth on the sample index, differentiate over the stamps
        b, a = butter(2, 20.0 / (0.5 / dt), btype="low")
        runs[-1]["a"] = np.gradient(filtfilt(b, a, lg.velocity), lg.t)

    def basis(r):
        q, v = r["q"], r["v"]
        return np.c_[r["a"], np.sin(q), np.cos(q), q, v, np.tanh(v / 0.01), np.ones_like(q)]

    _backbone(runs, basis)
    floor = realistic_joint.pooled_noise_floor_nmse_percent(logs)
    return runs, dt, {"noise_floor_nmse_percent": floor, "dt_median": dt}


def hysteresis_data(duration: float) -> tuple[list[dict], float, dict]:
    dt = 1e-3
    rng = np.random.default_rng(0)
    t = np.arange(0.0, duration, dt)
    v = sum(
        rng.uniform(0.1, 0.4) * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
        for f in (0.13, 0.31, 0.7, 1.3)
    )
    q = np.cumsum(v) * dt
    a = np.gradient(v, dt)
    z, vf = np.zeros_like(t), np.zeros_like(t)
    zk = vfk = 0.0
    alpha = 1.0 - math.exp(-dt / 0.05)
    for k in range(1, t.size):
        dq = q[k] - q[k - 1]
        zk = min(max(zk + 300.0 * dq * (1.0 - zk * np.sign(dq)), -1.0), 1.0)
        vfk += alpha * (v[k] - vfk)
        z[k], vf[k] = zk, vfk
    noise = rng.normal(0, 0.01, t.size)
    tau = 0.05 * a + 0.3 * z + 0.1 * v + 0.4 * (vf - v) + 0.5 * np.sin(q) + noise
    runs = [{"name": "hysteresis", "q": q, "v": v, "tau": tau, "a": a}]
    _backbone(runs, lambda r: np.c_[r["a"], np.tanh(r["v"] / 0.01), r["v"], np.sin(r["q"]), np.ones_like(q)])
    n = int(round(TRAIN * t.size))
    return runs, dt, {"noise_floor_nmse_percent": _nmse(tau[n:] - noise[n:], tau[n:])}


def _timings(model, runs) -> tuple[float, float]:
    """(median us per step() call over >= 10,000 calls, us per sample of predict_batch)."""
    q = np.concatenate([r["q"] for r in runs])
    v = np.concatenate([r["v"] for r in runs])
    c = np.concatenate([r["tau"] for r in runs])
    n = min(len(q), 20000)
    reps = int(np.ceil(10000 / n))
    qs, vs, cs = (np.tile(x[:n], reps).tolist() for x in (q, v, c))
    model.reset()
    step, clock = model.step, time.perf_counter
    times = np.empty(len(qs))
    for i, (a, b, d) in enumerate(zip(qs, vs, cs)):
        t0 = clock()
        step(a, b, d)
        times[i] = clock() - t0
    model.reset()
    t0 = clock()
    model.predict_batch(q[:n], v[:n], c[:n])
    batch = (clock() - t0) / n
    return float(np.median(times) * 1e6), float(batch * 1e6)


def run_dataset(name, runs, dt, settings, variants, seed=0) -> dict:
    cuts = [int(round(TRAIN * len(r["tau"]))) for r in runs]
    tau_v = np.concatenate([r["tau"][k:] for r, k in zip(runs, cuts)])
    phys_v = np.concatenate([r["phys"][k:] for r, k in zip(runs, cuts)])
    out = {
        "physics_validation_nmse_percent": _nmse(phys_v, tau_v),
        "physics_validation_rms": float(np.sqrt(np.mean((phys_v - tau_v) ** 2))),
        "samples": int(sum(len(r["tau"]) for r in runs)),
        "dt": dt,
        "candidates": {},
    }
    rows = []
    for label, extra, kind, compare in variants:
        t0 = time.perf_counter()
        model, rep = fit_residual(
            [r["q"] for r in runs],
            [r["v"] for r in runs],
            [r["tau"] for r in runs],
            [r["tau"] - r["phys"] for r in runs],
            dt,
            kind=kind,
            seed=seed,
            validation=1.0 - TRAIN,
            settings={**settings, **extra},
            compare=compare,
        )
        total_s = time.perf_counter() - t0
        for cand, info in rep["candidates"].items():
            key = cand if label == "" else f"{cand} {label}"
            entry = {
                "validation_nmse_percent": 100.0 * info["validation_mse"] / np.var(tau_v),
                "validation_rms": math.sqrt(info["validation_mse"]),
                "residual_validation_nmse_percent": info["validation_nmse_percent"],
                "fit_s": info["fit_s"],
                "exported": info["exported"],
                "n_params": info["n_params"],
                "chosen": rep["chosen"] == cand,
                **{k: info[k] for k in ("epochs", "converged", "gamma", "ridge_alpha") if k in info},
            }
            if info["exported"]:
                entry["step_us"], entry["batch_us"] = _timings(rep["models"][cand], runs)
            else:
                entry["step_us"], entry["batch_us"] = info["step_us"], float("nan")
            out["candidates"][key] = entry
            rows.append(
                [
                    key + (" *" if entry["chosen"] else ""),
                    out["physics_validation_nmse_percent"],
                    entry["validation_nmse_percent"],
                    entry["residual_validation_nmse_percent"],
                    out["physics_validation_rms"],
                    entry["validation_rms"],
                    entry["fit_s"],
                    entry["step_us"],
                    entry["batch_us"],
                ]
            )
        out.setdefault("features", rep["features"])
        out[f"fit_residual_total_s {label}".strip()] = total_s
    print_table(
        f"{name}: validation (last 40 % of each run), * = chosen by fit_residual (kind auto)",
        [
            "candidate",
            "NMSE phys %",
            "NMSE phys+res %",
            "res NMSE %",
            "RMS phys",
            "RMS phys+res",
            "fit [s]",
            "step [us]",
            "batch [us/sample]",
        ],
        rows,
    )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="15 s synthetic records, no command variant")
    args = ap.parse_args()
    duration = 15.0 if args.quick else 40.0
    auto = ("", {}, "auto", ("hgb",))
    command = ("(+command)", {"use_command": True}, "mlp", ())
    figures: dict = {"train_fraction": TRAIN, "step_budget_us": 20.0}

    runs, dt, checks = pendulum_data()
    figures["pendulum_checks"] = checks
    print_table(
        "DFKI pendulum data checks: NMSE % of the authors' model (whole run) and of a per-run least-squares fit (last 40 %)",
        ["run", "authors' model", "own per-run fit", "raw samples", "raw dt [ms]"],
        [
            [
                n,
                checks[n]["authors_model_nmse_percent"],
                checks[n]["own_fit_validation_nmse_percent"],
                checks[n]["raw_samples"],
                1e3 * checks[n]["raw_dt_median"],
            ]
            for n in PENDULUM_RUNS
        ],
    )
    pend_settings = {"reversal_velocity": 0.1}
    figures["pendulum"] = run_dataset(
        "DFKI pendulum (3 real runs, 1 ms grid)",
        runs,
        dt,
        pend_settings,
        [auto] + ([] if args.quick else [command]),
    )

    try:
        runs, dt, info = realistic_data(duration)
    except ImportError:
        runs = None
    if runs is not None:
        figures["realistic"] = {"info": info}
        figures["realistic"].update(
            run_dataset(f"realistic_joint (3 runs x {duration:g} s, 2 ms)", runs, dt, {}, [auto])
        )

    runs, dt, info = hysteresis_data(duration)
    figures["hysteresis"] = {"info": info}
    figures["hysteresis"].update(
        run_dataset(f"hysteresis joint ({duration:g} s, 1 ms)", runs, dt, {}, [auto])
    )
    write_results("learned_residual", figures)


if __name__ == "__main__":
    main()
