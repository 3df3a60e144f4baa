"""A realistic robot-joint log with known truth: gravity, load-dependent and rippling friction, noise.

Every bag the fitter used to see came from the package's simulator (plateaus, experiment events).
A real arm joint behind a harmonic drive logs something else; this module generates such logs from
a truth written here independently of the package's friction classes (an independent check), in
the convention of :mod:`friction_ros.core.friction.joint_load` (REP-103 signs, SI):

    tau      = J a + tau_load(q) + F(v) + k_L |tau_tr| sgn_eps(v) + sgn_eps(v) R(q)
    tau_load = gravity sin(q + gravity_phase) + offset + spring q,   tau_tr = tau_load(q) + J a
    R(q)     = sum_k c_k cos(k w q) + s_k sin(k w q),                w = 2 pi / ripple_period
    F(v)     = sgn_eps(v) (fc + (fs - fc) exp(-|v / vs|^delta)) + fv v     (AI friction chapter eq. 5)
    sgn_eps(v) = clip(v / eps, -1, 1)                                      (ABB M19-S paper A.2.1)

``k_L |tau_tr|`` is the friction a gear adds in proportion to the torque it transmits (gear
efficiency; Rhoban BAM's load-dependent models); ``R(q)`` the Coulomb level rippling with the
harmonic-drive wave-generator angle. The joint follows a smooth trajectory exactly (sum of
sinusoids, :func:`trajectory`) and the torque is its inverse dynamics; the log then holds

    stamp    = k T + jitter (clipped to +-0.4 T; a few samples dropped), strictly increasing
    position = round(q / encoder_resolution) encoder_resolution
    velocity = v + N(0, velocity_noise_std)  (or the backward difference of the logged position)
    effort   = tau + sensor_offset + N(0, torque_noise_std)

with no plateaus and no experiment events, one run per speed (:func:`realistic_runs`).
``sensor_offset`` only shifts the measurement; ``offset`` is a real torque the gear transmits (so a
fitter sees ``offset + sensor_offset`` as one constant, told apart only through ``k_L``).
:func:`write_bag` stores runs as rosbag2 bags with the ``rosbags`` library (not the package's
writer), :func:`write_csv` as CSV; ``python -m friction_ros.core.synthetic.realistic_joint OUT``
writes both and a ``truth.yaml``. The truth itself is :class:`~.joint_truth.JointTruth`.
"""

from __future__ import annotations

import argparse
import math
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from friction_ros.core.synthetic.joint_truth import JointTruth

#: first stamp of run 0 [s since the epoch]; run i starts (duration + 60 s) i later
START_TIME = 1_700_000_000.0
TRAJECTORY_KINDS = ("multisine", "bandlimited")


@dataclass(frozen=True)
class Trajectory:
    """q(t) = center + sum_i A_i sin(w_i t + phi_i), with v and a its exact derivatives (t in s)."""

    kind: str
    duration: float
    max_speed: float
    center: float
    amplitude: np.ndarray  # rad
    omega: np.ndarray  # rad/s
    phase: np.ndarray  # rad

    def _arg(self, t):
        return np.multiply.outer(np.asarray(t, dtype=float), self.omega) + self.phase

    def q(self, t):
        return self.center + np.sin(self._arg(t)) @ self.amplitude

    def v(self, t):
        return np.cos(self._arg(t)) @ (self.amplitude * self.omega)

    def a(self, t):
        return -(np.sin(self._arg(t)) @ (self.amplitude * self.omega**2))

    def __call__(self, t):
        """(q, v, a) at times t [rad, rad/s, rad/s^2]."""
        return self.q(t), self.v(t), self.a(t)


def trajectory(
    kind: str = "multisine",
    duration: float = 40.0,
    max_speed: float = 0.4,
    seed=0,
    *,
    amplitude: float = 1.5,
    f_max: float = 1.0,
    n_components: int | None = None,
    center: float = 0.0,
    slow_share: float = 0.45,
) -> Trajectory:
    """A smooth ordinary joint trajectory: no plateaus, no events, many velocity reversals.

    One slow sinusoid (one period over ``duration``, random phase) carries the angle range, at most
    ``+-amplitude`` rad and at most ``slow_share * max_speed`` of speed (so slow runs cover less
    angle); faster sinusoids with random phases between min(3/duration, f_max/4) and ``f_max`` Hz add the
    reversals: ``"multisine"`` 4 components at log-uniform random frequencies, ``"bandlimited"``
    24 on the 1/duration grid with a flat velocity spectrum. The fast part is scaled so that
    max |v| on a 5 ms grid is ``max_speed``, and the slow amplitude reduced until max |q - center|
    <= amplitude. ``seed``: anything ``numpy.random.default_rng`` takes.
    """
    if kind not in TRAJECTORY_KINDS:
        raise ValueError(f"kind must be one of {TRAJECTORY_KINDS}, not {kind!r}")
    if duration <= 0 or max_speed <= 0 or amplitude <= 0:
        raise ValueError("duration, max_speed and amplitude must be > 0")
    rng = np.random.default_rng(seed)
    w0 = 2.0 * math.pi / duration
    if f_max <= 1.0 / duration:
        raise ValueError(f"f_max must be above 1 / duration = {1.0 / duration:g} Hz")
    f_lo = min(3.0 / duration, 0.25 * f_max)
    if kind == "multisine":
        n = n_components or 4
        f = np.exp(rng.uniform(math.log(f_lo), math.log(f_max), n))
        vel_weight = rng.uniform(0.5, 1.0, n)
    else:
        n = n_components or 24
        f = np.unique(np.round(np.linspace(f_lo, f_max, n) * duration)) / duration
        vel_weight = np.ones(f.size)
    w = 2.0 * math.pi * f
    fast_amp = vel_weight / w  # position amplitudes of unit-scale velocity components
    phases = np.concatenate([[rng.uniform(0.0, 2.0 * math.pi)], rng.uniform(0.0, 2.0 * math.pi, w.size)])
    omega = np.concatenate([[w0], w])
    grid = np.arange(0.0, duration + 1e-9, 0.005)
    arg = np.multiply.outer(grid, omega) + phases
    sin_g, cos_g = np.sin(arg), np.cos(arg)
    v_fast = cos_g[:, 1:] @ (fast_amp * w)
    q_fast = sin_g[:, 1:] @ fast_amp

    a0 = min(amplitude, slow_share * max_speed / w0)
    for _ in range(20):
        v_slow = a0 * w0 * cos_g[:, 0]

        def excess(s, v_slow=v_slow):
            return float(np.max(np.abs(v_slow + s * v_fast))) - max_speed

        hi = max_speed / max(float(np.max(np.abs(v_fast))), 1e-12)
        while excess(hi) < 0:
            hi *= 2.0
        s = brentq(excess, 0.0, hi, xtol=1e-14) if excess(0.0) < 0 else 0.0
        peak = float(np.max(np.abs(a0 * sin_g[:, 0] + s * q_fast)))
        if peak <= amplitude * (1 + 1e-9):
            break
        a0 = max(a0 - (peak - amplitude), 0.05 * a0)
    amp = np.concatenate([[a0], s * fast_amp])
    return Trajectory(kind, float(duration), float(max_speed), float(center), amp, omega, phases)


@dataclass
class Run:
    """One logged run: measured arrays as a robot logs them, plus the truth behind them.

    ``stamp_ns`` [int ns since the epoch] is each sample's header stamp and log time; ``t`` [s] is
    ``(stamp_ns - start_ns) 1e-9``, the time the trajectory was evaluated at.
    ``noise_floor_nmse_percent = 100 var(torque_noise) / var(effort)``: the NMSE (ABB M19-S paper eq. 4)
    a perfect model of the effort would score on this run; ``friction_noise_floor_nmse_percent =
    100 var(noise) / var(true_friction + noise)``, the same for the friction part alone (effort minus
    the true J a, tau_load and sensor offset), much higher because gravity dominates var(effort).
    ``measured_input_nmse_percent``: the NMSE of the true model fed the logged position and velocity
    (and the true acceleration), a floor closer to what a fitted model can reach: the velocity noise
    flips sgn_eps(v) near reversals.
    """

    name: str
    speed: float
    start_ns: int
    stamp_ns: np.ndarray
    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    true_position: np.ndarray
    true_velocity: np.ndarray
    true_acceleration: np.ndarray
    true_torque: np.ndarray
    true_friction: np.ndarray
    true_load: np.ndarray
    torque_noise: np.ndarray
    sensor_offset: float
    noise_floor_nmse_percent: float
    friction_noise_floor_nmse_percent: float
    measured_input_nmse_percent: float
    trajectory: Trajectory
    truth: JointTruth

    @property
    def stamp(self) -> np.ndarray:
        """Header stamps in float s since the epoch."""
        return self.stamp_ns * 1e-9

    def summary(self) -> dict:
        return {
            "name": self.name,
            "speed": float(self.speed),
            "samples": int(self.t.size),
            "duration": float(self.t[-1]),
            "position_range": [float(self.true_position.min()), float(self.true_position.max())],
            "max_abs_velocity": float(np.max(np.abs(self.true_velocity))),
            "noise_floor_nmse_percent": float(self.noise_floor_nmse_percent),
            "friction_noise_floor_nmse_percent": float(self.friction_noise_floor_nmse_percent),
            "measured_input_nmse_percent": float(self.measured_input_nmse_percent),
        }

    def measured_input_torque(self) -> np.ndarray:
        """The true model on the logged position and velocity and the true acceleration, + sensor offset."""
        tr = self.truth
        return tr.torque(self.position, self.velocity, self.true_acceleration) + tr.sensor_offset


def noise_floor_nmse_percent(noise, effort) -> float:
    """100 var(noise) / var(effort): the NMSE of a model that predicts the effort up to its noise."""
    return float(100.0 * np.var(np.asarray(noise, dtype=float)) / np.var(np.asarray(effort, dtype=float)))


def pooled_noise_floor_nmse_percent(runs: Sequence[Run]) -> float:
    """The noise floor of all runs pooled (noise and effort concatenated)."""
    return noise_floor_nmse_percent(
        np.concatenate([r.torque_noise for r in runs]), np.concatenate([r.effort for r in runs])
    )


def pooled_measured_input_nmse_percent(runs: Sequence[Run]) -> float:
    """:attr:`Run.measured_input_nmse_percent` of all runs pooled."""
    y = np.concatenate([r.effort for r in runs])
    e = np.concatenate([r.measured_input_torque() for r in runs]) - y
    return float(100.0 * np.mean(e**2) / np.var(y))


def _stamps(truth: JointTruth, duration: float, rng: np.random.Generator) -> np.ndarray:
    """Sample times [ns from the run start]: k T + jitter, a few dropped, strictly increasing, t[0] = 0."""
    dt = truth.sample_period
    n = int(math.floor(duration / dt)) + 1
    jitter = np.clip(rng.normal(0.0, truth.jitter_std, n), -0.4 * dt, 0.4 * dt)
    jitter[0] = 0.0
    keep = rng.random(n) >= truth.drop_rate
    keep[0] = True
    return np.round((np.arange(n) * dt + jitter)[keep] * 1e9).astype(np.int64)


def make_run(
    truth: JointTruth,
    speed: float,
    duration: float,
    seed,
    *,
    name: str = "run",
    kind: str = "multisine",
    f_max: float = 1.0,
    start_ns: int = int(START_TIME * 1e9),
) -> Run:
    """One run at ``speed`` [rad/s] max: trajectory, inverse dynamics, sampling and measurement."""
    rng = np.random.default_rng(seed)
    traj = trajectory(kind, duration, speed, seed=int(rng.integers(2**63)), f_max=f_max)
    rel = _stamps(truth, duration, rng)
    t = rel * 1e-9
    q, v, a = traj(t)
    load = truth.load_torque(q)
    fric = truth.friction(v, q, a)
    tau = truth.J * a + load + fric
    noise = rng.normal(0.0, truth.torque_noise_std, t.size)
    effort = tau + truth.sensor_offset + noise
    res = truth.encoder_resolution
    position = np.round(q / res) * res
    if truth.velocity_estimate == "noisy":
        velocity = v + rng.normal(0.0, truth.velocity_noise_std, t.size)
    else:
        velocity = np.empty_like(position)
        velocity[1:] = np.diff(position) / np.diff(t)
        velocity[0] = velocity[1] if t.size > 1 else 0.0
    y_in = truth.torque(position, velocity, a) + truth.sensor_offset
    return Run(
        name=name,
        speed=float(speed),
        start_ns=int(start_ns),
        stamp_ns=rel + int(start_ns),
        t=t,
        position=position,
        velocity=velocity,
        effort=effort,
        true_position=q,
        true_velocity=v,
        true_acceleration=a,
        true_torque=tau,
        true_friction=fric,
        true_load=load,
        torque_noise=noise,
        sensor_offset=float(truth.sensor_offset),
        noise_floor_nmse_percent=noise_floor_nmse_percent(noise, effort),
        friction_noise_floor_nmse_percent=noise_floor_nmse_percent(noise, fric + noise),
        measured_input_nmse_percent=float(100.0 * np.mean((y_in - effort) ** 2) / np.var(effort)),
        trajectory=traj,
        truth=truth,
    )


def realistic_runs(
    truth: JointTruth | None = None,
    speeds: Sequence[float] = (0.1, 0.25, 0.4),
    duration: float = 40.0,
    seed: int = 0,
    *,
    kind: str = "multisine",
    f_max: float = 1.0,
    start_time: float = START_TIME,
) -> list[Run]:
    """One run per speed (max |v| = speed), each ``duration`` s; deterministic in ``seed``.

    Run i is named ``run<i>_speed<speed>``, drawn from ``default_rng([seed, i])`` and starts at
    ``start_time + i (duration + 60)`` s since the epoch. ``kind``, ``f_max``: see :func:`trajectory`
    (the default 1 Hz keeps J a below ~0.1 N*m at 0.4 rad/s, like an ordinary slow arm motion).
    """
    truth = truth or JointTruth()
    gap = int(round((duration + 60.0) * 1e9))
    return [
        make_run(
            truth,
            sp,
            duration,
            [int(seed), i],
            name=f"run{i}_speed{sp:g}",
            kind=kind,
            f_max=f_max,
            start_ns=int(round(start_time * 1e9)) + i * gap,
        )
        for i, sp in enumerate(speeds)
    ]


def write_bag(
    runs: Run | Sequence[Run],
    path,
    storage: str = "mcap",
    topic: str = "/joint_states",
    joint: str = "joint1",
    *,
    overwrite: bool = False,
) -> list[Path]:
    """Write each run as a rosbag2 directory (``sensor_msgs/msg/JointState``, one joint) with ``rosbags``.

    ``path``: a directory that gets one bag per run (``path/<run.name>``), or a sequence of bag
    paths, one per run. ``storage``: ``"mcap"`` or ``"sqlite3"``. Header stamp = log time = the
    sample's stamp. Independent of the package's :class:`~friction_ros.core.bag.BagWriter`.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    plugins = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
    if storage not in plugins:
        raise ValueError(f"storage must be 'mcap' or 'sqlite3', not {storage!r}")
    runs = [runs] if isinstance(runs, Run) else list(runs)
    if isinstance(path, str | Path):
        paths = [Path(path) / r.name for r in runs]
    else:
        paths = [Path(p) for p in path]
        if len(paths) != len(runs):
            raise ValueError(f"{len(paths)} paths for {len(runs)} runs")
    ts = get_typestore(Stores.ROS2_JAZZY)
    JointState = ts.types["sensor_msgs/msg/JointState"]
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    msgtype = "sensor_msgs/msg/JointState"
    for run, p in zip(runs, paths):
        if p.exists():
            if not overwrite:
                raise FileExistsError(f"{p} exists (overwrite=True replaces it)")
            shutil.rmtree(p)
        p.parent.mkdir(parents=True, exist_ok=True)
        with Writer(p, version=9, storage_plugin=plugins[storage]) as w:
            conn = w.add_connection(topic, msgtype, typestore=ts)
            for k in range(run.stamp_ns.size):
                ns = int(run.stamp_ns[k])
                msg = JointState(
                    header=Header(
                        stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id=""
                    ),
                    name=[joint],
                    position=np.array([run.position[k]]),
                    velocity=np.array([run.velocity[k]]),
                    effort=np.array([run.effort[k]]),
                )
                w.write(conn, ns, bytes(ts.serialize_cdr(msg, msgtype)))
    return paths


def write_csv(run: Run, path) -> Path:
    """Write ``time,position,velocity,effort`` (time = ``run.t`` [s from the run start]; floats as repr)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = ["time,position,velocity,effort"]
    lines += [
        f"{float(a)!r},{float(b)!r},{float(c)!r},{float(d)!r}"
        for a, b, c, d in zip(run.t, run.position, run.velocity, run.effort)
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m friction_ros.core.synthetic.realistic_joint OUT_DIR``: bags, CSVs and truth.yaml."""
    import yaml

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--storage", choices=("mcap", "sqlite3"), default="mcap")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--speeds", type=float, nargs="+", default=[0.1, 0.25, 0.4])
    ap.add_argument("--kind", choices=TRAJECTORY_KINDS, default="multisine")
    ap.add_argument("--overwrite", action="store_true")
    args = ap.parse_args(argv)
    truth = JointTruth()
    runs = realistic_runs(truth, args.speeds, args.duration, args.seed, kind=args.kind)
    paths = write_bag(runs, args.out_dir, storage=args.storage, overwrite=args.overwrite)
    for r in runs:
        write_csv(r, args.out_dir / f"{r.name}.csv")
    doc = {
        "truth": truth.to_dict(),
        "seed": args.seed,
        "kind": args.kind,
        "runs": [dict(r.summary(), bag=str(p)) for r, p in zip(runs, paths)],
        "pooled_noise_floor_nmse_percent": pooled_noise_floor_nmse_percent(runs),
        "pooled_measured_input_nmse_percent": pooled_measured_input_nmse_percent(runs),
    }
    (args.out_dir / "truth.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    for r, p in zip(runs, paths):
        print(
            f"{p}: {r.t.size} samples, noise floor {r.noise_floor_nmse_percent:.4f} % NMSE, true model on "
            f"measured inputs {r.measured_input_nmse_percent:.4f} %"
        )
    print(
        f"pooled noise floor {doc['pooled_noise_floor_nmse_percent']:.4f} % NMSE, true model on measured inputs {doc['pooled_measured_input_nmse_percent']:.4f} %; truth in {args.out_dir}/truth.yaml"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
