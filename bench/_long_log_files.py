"""Long joint logs with known truth for the long-log benchmark: MCAP bags and CSV files in /tmp.

The joint follows the realistic joint's truth (:mod:`friction_ros.core.synthetic.realistic_joint`:
gravity, spring, Stribeck friction, load-dependent friction, ripple, noise) at 1 kHz. The
trajectory is that module's band-limited multisine with its amplitude modulated by a slow sinusoid (period
``envelope_period``), so the speed varies over the log as in a real session (slow and fast stretches),
and still has exact derivatives (the modulation is a sum of sinusoids too).

    python bench/_long_log_files.py /tmp/long_logs --minutes 1 10 60 --arm
"""

from __future__ import annotations

import argparse
import math
import struct
from dataclasses import replace
from pathlib import Path

import numpy as np

from friction_ros.core.synthetic.realistic_joint import START_TIME, JointTruth, Trajectory, trajectory

RATE_PERIOD = 0.001  # 1 kHz
#: arm joints: (truth overrides, max speed) - the same truth family, different sizes
ARM = {
    "joint1": ({}, 0.3),
    "joint2": ({"J": 0.5, "gravity": 20.0}, 0.25),
    "joint3": ({"J": 0.1, "gravity": 6.0, "fc": 0.9, "fs": 1.2}, 0.35),
    "joint4": ({"J": 0.05, "gravity": 4.0, "fc": 0.8, "fs": 1.1, "fv": 1.0, "torque_noise_std": 0.03}, 0.4),
    "joint5": ({"J": 0.02, "gravity": 1.0, "fc": 0.5, "fs": 0.7, "torque_noise_std": 0.02}, 0.5),
    "joint6": ({"J": 0.01, "gravity": 0.5, "fc": 0.3, "fs": 0.4, "vs": 0.05, "fv": 0.4}, 0.6),
    "joint7": ({"J": 0.005, "gravity": 0.0, "spring": 0.0, "fc": 0.2, "fs": 0.3, "fv": 0.3}, 0.7),
}


def modulated(traj: Trajectory, period: float, depth: float = 0.7) -> Trajectory:
    """``traj`` with its fast components times (1 + depth sin(2 pi t / period)) (still a sum of sines)."""
    big = 2.0 * math.pi / period
    a, w, p = traj.amplitude, traj.omega, traj.phase
    slow, fast = slice(0, 1), slice(1, None)
    amp = np.concatenate([a, 0.5 * depth * a[fast], 0.5 * depth * a[fast]])
    om = np.concatenate([w, w[fast] - big, w[fast] + big])
    ph = np.concatenate([p, p[fast] + 0.5 * math.pi, p[fast] + 1.5 * math.pi])
    del slow
    return replace(traj, amplitude=amp, omega=om, phase=ph, max_speed=traj.max_speed * (1 + depth))


def joint_signals(
    truth: JointTruth, speed: float, duration: float, seed: int, envelope_period: float = 240.0
):
    """(stamp_ns, position, velocity, effort) of one joint over ``duration`` s at the truth's period."""
    rng = np.random.default_rng(seed)
    traj = trajectory("bandlimited", min(duration, 600.0), speed, seed=seed, f_max=1.5)
    if duration > envelope_period:
        traj = modulated(traj, envelope_period)
    n = int(math.floor(duration / truth.sample_period)) + 1
    jitter = np.clip(
        rng.normal(0.0, truth.jitter_std, n), -0.4 * truth.sample_period, 0.4 * truth.sample_period
    )
    jitter[0] = 0.0
    rel = np.round((np.arange(n) * truth.sample_period + jitter) * 1e9).astype(np.int64)
    out = {k: np.empty(n) for k in ("position", "velocity", "effort")}
    for i0 in range(0, n, 200_000):  # blocks: the multisine's (n, components) matrix stays small
        sl = slice(i0, min(i0 + 200_000, n))
        t = rel[sl] * 1e-9
        q, v, a = traj(t)
        tau = truth.J * a + truth.load_torque(q) + truth.friction(v, q, a)
        m = t.size
        out["effort"][sl] = tau + truth.sensor_offset + rng.normal(0.0, truth.torque_noise_std, m)
        out["position"][sl] = np.round(q / truth.encoder_resolution) * truth.encoder_resolution
        out["velocity"][sl] = v + rng.normal(0.0, truth.velocity_noise_std, m)
    return rel + int(START_TIME * 1e9), out["position"], out["velocity"], out["effort"]


def _template(names: list[str]) -> tuple[bytes, dict[str, int]]:
    """A JointState CDR payload for ``names`` and the byte offset of each patched field."""
    from friction_ros.core.bag import encode, load_installed

    defs = load_installed("sensor_msgs/msg/JointState")
    k = len(names)
    marks = {
        f: [1.0e300 / (i + 1 + 10 * j) for i in range(k)]
        for j, f in enumerate(("position", "velocity", "effort"))
    }
    msg = {"header": {"stamp": {"sec": 0x7A6B5C4D, "nanosec": 0x1E2D3C4B}}, "name": names, **marks}
    data = encode(defs, "sensor_msgs/msg/JointState", msg)
    offs = {
        "sec": data.index(struct.pack("<i", 0x7A6B5C4D)),
        "nanosec": data.index(struct.pack("<I", 0x1E2D3C4B)),
    }
    for f, vals in marks.items():
        offs[f] = data.index(struct.pack("<d", vals[0]))
    return data, offs


def write_bag(
    path: Path, stamps: np.ndarray, joints: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]
) -> Path:
    """A JointState bag (all ``joints`` in each message) with the package's BagWriter."""
    from friction_ros.core.bag import BagWriter, make_qos

    names = list(joints)
    data, offs = _template(names)
    n, width = stamps.size, len(data)
    block = 100_000
    with BagWriter(path, overwrite=True) as w:
        w.add_topic("/joint_states", "sensor_msgs/msg/JointState", qos_profiles=[make_qos()])
        for i0 in range(0, n, block):
            sl = slice(i0, min(i0 + block, n))
            m = sl.stop - sl.start
            mat = np.tile(np.frombuffer(data, np.uint8), (m, 1))
            ns = stamps[sl]
            mat[:, offs["sec"] : offs["sec"] + 4] = (
                (ns // 1_000_000_000).astype("<i4").view(np.uint8).reshape(m, 4)
            )
            mat[:, offs["nanosec"] : offs["nanosec"] + 4] = (
                (ns % 1_000_000_000).astype("<u4").view(np.uint8).reshape(m, 4)
            )
            for fi, f in enumerate(("position", "velocity", "effort")):
                vals = np.stack([joints[j][fi][sl] for j in names], axis=1).astype("<f8")
                mat[:, offs[f] : offs[f] + 8 * len(names)] = vals.view(np.uint8).reshape(m, 8 * len(names))
            raw = mat.tobytes()
            for k in range(m):
                w.write("/joint_states", raw[k * width : (k + 1) * width], int(ns[k]))
    return path


def write_csv(path: Path, stamps: np.ndarray, position, velocity, effort) -> Path:
    """``time,position,velocity,effort`` (time in s from the first sample), written in blocks."""
    with open(path, "w") as f:
        f.write("time,position,velocity,effort\n")
        t = (stamps - stamps[0]) * 1e-9
        for i0 in range(0, t.size, 200_000):
            sl = slice(i0, i0 + 200_000)
            np.savetxt(
                f, np.column_stack([t[sl], position[sl], velocity[sl], effort[sl]]), fmt="%.9g", delimiter=","
            )
    return path


def single_joint(out: Path, minutes: float, csv: bool = False, seed: int = 0) -> dict[str, Path]:
    """``out/joint_<minutes>min`` (bag) and, with ``csv``, ``out/joint_<minutes>min.csv``."""
    truth = JointTruth(sample_period=RATE_PERIOD, drop_rate=0.0)
    stamps, q, v, e = joint_signals(truth, 0.4, minutes * 60.0, seed)
    name = f"joint_{minutes:g}min"
    files = {"bag": write_bag(out / name, stamps, {"joint1": (q, v, e)})}
    if csv:
        files["csv"] = write_csv(out / f"{name}.csv", stamps, q, v, e)
    return files


def arm(out: Path, seconds: float = 21.0, seed: int = 0) -> Path:
    """A 7-joint arm bag, ``seconds`` long at 1 kHz, every joint moving (realistic truths)."""
    joints, stamps = {}, None
    for i, (j, (over, speed)) in enumerate(ARM.items()):
        truth = JointTruth(sample_period=RATE_PERIOD, drop_rate=0.0, **over)
        st, q, v, e = joint_signals(truth, speed, seconds, seed + i)
        stamps = st if stamps is None else stamps
        joints[j] = (q, v, e)
    return write_bag(out / f"arm7_{seconds:g}s", stamps, joints)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--minutes", type=float, nargs="*", default=[1.0, 10.0, 60.0])
    ap.add_argument("--csv", action="store_true", help="also write CSV logs")
    ap.add_argument("--arm", action="store_true", help="also the 7-joint 21 s arm bag")
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    for m in a.minutes:
        print(single_joint(a.out, m, a.csv))
    if a.arm:
        print(arm(a.out))


if __name__ == "__main__":
    main()
