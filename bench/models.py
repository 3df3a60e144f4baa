"""Benchmark: plant with GMS-4 friction at a 10 kHz internal step (real-time factor) and batch LuGre.

Run: .venv/bin/python bench/models.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _common import print_table, write_results  # noqa: E402

from friction_ros.core.friction import make_model  # noqa: E402
from friction_ros.core.presets import load_preset  # noqa: E402


def best_of(fn, repeat=3):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    rows, figures = [], {}
    pr = load_preset("abb_m19s")  # GMS-4 truth friction, internal_dt = 1e-4 (10 kHz)
    plant = pr.make_plant()
    dt, sim_s = 1e-3, 10.0
    n = int(sim_s / dt)
    cmd = 1.5 * np.sin(2 * np.pi * 1.0 * np.arange(n) * dt) + 0.5 * np.sin(
        2 * np.pi * 7.3 * np.arange(n) * dt
    )
    n_sub, h = plant.substeps(dt)
    assert abs(1.0 / h - 10_000) < 1e-6, (n_sub, h)
    plant.step(0.0, dt)  # compile / warm up

    def run_step():
        plant.reset()
        for c in cmd:
            plant.step(c, dt)

    def run_open():
        plant.reset()
        plant.run_open_loop(cmd, dt)

    t_step = best_of(run_step)
    t_open = best_of(run_open)
    rows.append(["plant GMS-4, step() at 1 kHz, 10 kHz internal", f"{sim_s:g} s sim", t_step, sim_s / t_step])
    rows.append(["plant GMS-4, run_open_loop, 10 kHz internal", f"{sim_s:g} s sim", t_open, sim_s / t_open])
    figures["plant_gms4_step_api_wall_s"] = t_step
    figures["plant_gms4_step_api_realtime_factor"] = sim_s / t_step
    figures["plant_gms4_open_loop_wall_s"] = t_open
    figures["plant_gms4_open_loop_realtime_factor"] = sim_s / t_open

    lug = make_model("lugre", sigma0=1e5, sigma1=50.0, fv=0.01, fc=0.8, fs=0.95, vs=0.05)
    rng = np.random.default_rng(0)
    pm = np.tile(lug.param_vector(), (64, 1))
    pm[:, 0] *= rng.uniform(0.5, 2.0, 64)
    pm[:, 3] *= rng.uniform(0.8, 1.0, 64)
    v = np.cumsum(rng.normal(0, 0.01, 60_000))
    lug.simulate_batch(pm[:2], v[:10], 1e-3)  # warm up
    t_b = best_of(lambda: lug.simulate_batch(pm, v, 1e-3))
    t_np = best_of(lambda: lug.simulate_batch(pm, v, 1e-3, use_numba=False), repeat=1)
    rows.append(["batch LuGre 60,000 samples x 64 sets (numba)", "3.84e6 steps", t_b, ""])
    rows.append(["batch LuGre 60,000 samples x 64 sets (numpy fallback)", "3.84e6 steps", t_np, ""])
    figures["batch_lugre_60000x64_wall_s"] = t_b
    figures["batch_lugre_60000x64_numpy_wall_s"] = t_np

    gms = make_model("gms", **pr.friction.coefficients)
    pg = np.tile(gms.param_vector(), (64, 1))
    t_g = best_of(lambda: gms.simulate_batch(pg, v, 1e-3), repeat=2)
    rows.append(["batch GMS-4 60,000 samples x 64 sets (numba)", "3.84e6 steps", t_g, ""])
    figures["batch_gms4_60000x64_wall_s"] = t_g

    print_table(
        "friction models / plant benchmark", ["case", "size", "wall time [s]", "real-time factor"], rows
    )
    write_results("models", figures, command=".venv/bin/python bench/models.py")


if __name__ == "__main__":
    main()
