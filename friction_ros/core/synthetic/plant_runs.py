"""Known-truth identification records from the simulated plant (tests, benchmarks, demos).

``abb_m19s_excitation_experiment`` runs ABB M19-S paper's identification excitation (A.3) on a plant
preset (default ``abb_m19s``: J = 0.0012 kg m^2, GMS-4 truth, 1.05e-4 rad encoder, current noise) in
closed velocity loop at 1 kHz:

    v_ref(t) = e(t) r(t),  r = 4th-order Butterworth (4 Hz) band-limited white noise, unit RMS,
    e(t) = (H+L)/2 + (H-L)(2/pi)[sin w0 t + sin(3 w0 t)/3],  w0 = 2 pi / 10 s   (ABB M19-S paper A.3 (a)),
    floored at L (the 3-term series undershoots);

``plateau_experiment`` runs constant-velocity plateaus in both directions over a log-spaced speed
range (AI friction chapter B.3 experiment 2) with ExperimentEvent markers. ``write_bag`` stores either as a
rosbag2 MCAP directory (sensor_msgs/JointState + friction_msgs/ExperimentEvent).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import signal

from friction_ros.core.experiment.events import END, START, Event
from friction_ros.core.validation import check_choice


@dataclass
class Record:
    """Raw measured arrays of a simulated experiment plus the truth."""

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    current: np.ndarray
    true_velocity: np.ndarray
    true_friction: np.ndarray
    events: list[Event] = field(default_factory=list)
    truth: dict = field(default_factory=dict)
    inertia: float = 0.0
    torque_constant: float = 1.0


def abb_m19s_excitation_velocity(
    duration: float, dt: float, high: float, low: float, seed: int = 3
) -> np.ndarray:
    """ABB M19-S paper's excitation velocity (module docstring)."""
    n = int(round(duration / dt))
    t = np.arange(n) * dt
    rng = np.random.default_rng(seed)
    sos = signal.butter(4, 4.0, fs=1.0 / dt, output="sos")
    r = signal.sosfilt(sos, rng.standard_normal(n + 2000))[2000:]
    r /= np.sqrt(np.mean(r**2))
    w0 = 2 * math.pi / 10.0
    e = (high + low) / 2 + (high - low) * (2 / math.pi) * (np.sin(w0 * t) + np.sin(3 * w0 * t) / 3)
    return np.maximum(e, low) * r


def _make_plant(preset: str, friction=None, overrides: dict | None = None):
    """The preset's plant with plant-key ``overrides`` and ``friction`` as its motor-side model."""
    from friction_ros.core.presets import make_plant

    changes = dict(overrides or {})
    if friction is not None:
        changes["friction_motor"] = friction
    plant = make_plant(preset, **changes)
    return plant, plant.params


def run_velocity_loop(
    v_ref: np.ndarray,
    dt: float,
    *,
    preset: str = "abb_m19s",
    friction=None,
    overrides: dict | None = None,
    kp: float | None = None,
    ki: float | None = None,
    events: list[Event] | None = None,
    position_feedback: bool = False,
) -> Record:
    """Track ``v_ref`` with a PI velocity loop (K_v = 400 J, integral gain = a position gain of
    200 K_v, so plateaus break away quickly) plus inertia feed-forward; record the sensors.

    ``position_feedback``: the integral term acts on the encoder position against the integrated
    reference, ``ki (p_ref - p_meas)`` (a PD position loop on a ramp), instead of on the integral
    of the filtered velocity error: the same stiffness without the velocity filter's lag."""
    plant, params = _make_plant(preset, friction, overrides)
    J = params.reflected_inertia
    kt_out = params.torque_constant * params.ratio * params.gear_efficiency
    a_ref = np.gradient(v_ref, dt)
    kp = 400.0 * J if kp is None else kp
    ki = 200.0 * kp if ki is None else ki
    n = v_ref.size
    out = {k: np.empty(n) for k in ("t", "p", "v", "e", "i", "tv", "tf")}
    integ = 0.0
    v_meas = 0.0
    p_meas = 0.0
    p_ref = 0.0
    for k in range(n):
        err = v_ref[k] - v_meas
        if position_feedback:
            integ = p_ref - p_meas
            p_ref += v_ref[k] * dt
        else:
            integ += err * dt
        tau = kp * err + ki * integ + J * a_ref[k]
        cmd = tau / kt_out if params.actuation == "current" else tau
        m = plant.step(cmd, dt)
        v_meas = m.velocity
        p_meas = m.position
        out["t"][k] = m.time
        out["p"][k] = m.position
        out["v"][k] = m.velocity
        out["e"][k] = m.effort
        out["i"][k] = m.motor_current
        out["tv"][k] = m.true_velocity
        out["tf"][k] = m.friction_motor
    fm = params.friction_motor
    return Record(
        out["t"],
        out["p"],
        out["v"],
        out["e"],
        out["i"],
        out["tv"],
        out["tf"],
        list(events or []),
        fm.to_config(),
        float(J),
        float(kt_out),
    )


def abb_m19s_excitation_experiment(
    duration: float = 50.0,
    dt: float = 1e-3,
    *,
    high: float = 1.0,
    low: float = 0.02,
    seed: int = 3,
    preset: str = "abb_m19s",
    friction=None,
    overrides: dict | None = None,
) -> Record:
    """ABB M19-S paper's identification run (50 s at 1 kHz by default) on a plant preset."""
    v = abb_m19s_excitation_velocity(duration, dt, high, low, seed)
    ev = [
        Event(0.0, "random", "abb_m19s_random", 0, START, math.nan),
        Event(duration, "random", "abb_m19s_random", 0, END),
    ]
    return run_velocity_loop(v, dt, preset=preset, friction=friction, overrides=overrides, events=ev)


def plateau_experiment(
    speeds=None,
    *,
    dt: float = 1e-3,
    hold: float = 1.0,
    ramp: float = 0.1,
    preset: str = "abb_m19s",
    friction=None,
    overrides: dict | None = None,
    order: str = "descending",
    kp: float | None = None,
    ki: float | None = 150.0,
    position_feedback: bool = True,
) -> Record:
    """Constant-velocity plateaus at ``speeds`` in both directions with ExperimentEvent markers.

    Experiment design for the Stribeck knee (where the steady friction falls with speed, slope
    down to -2.6 N*m*s/rad on the ABB preset; the velocity loop's damping is only K_v = 400 J =
    0.48 N*m*s/rad, and cannot be raised: 1 kHz sampling, the velocity filter and the current lag
    put its limit near 0.5):

    * ``order="descending"``: each direction starts at the fastest plateau and slows down
      plateau by plateau without stopping, so a slow plateau is entered from steady sliding, never
      through a break-away (the fs - fc torque released at break-away throws a slow plateau into
      stick-slip even where steady sliding would be stable); ``"ascending"`` = the old order.
    * ``position_feedback`` with position gain ``ki`` (PD position loop on the ramp): steady sliding
      at speed v is linearly stable when K_v + K_p s(v)/C > -F'(v), the friction's lag
      (GMS attraction C = 50 N*m/s, s ~ 0.9 N*m: 18 ms) letting the position stiffness K_p damp the
      negative slope: K_p > 125 N*m/rad here; 150 is used, since much stiffer loops hunt on the
      stuck presliding mode (element stiffness 617 N*m/rad) excited by the encoder's quantisation.

    With it the ABB preset slides steadily down to ~0.025 rad/s (the default 16 speeds put five
    plateaus in the knee); slower plateaus still stick-slip on the 1.05e-4 rad encoder (without
    quantisation all plateaus down to 0.003 rad/s are steady) and are rejected by
    :func:`~friction_ros.core.identification.data.plateau_detection.find_plateaus` from their torque oscillation.
    """
    check_choice("order", order, ["descending", "ascending"])
    if speeds is None:
        speeds = np.geomspace(0.005, 2.0, 16)
    speeds = np.sort(np.abs(np.asarray(speeds, dtype=float)))
    if order == "descending":
        speeds = speeds[::-1]
    t = 0.0
    v_parts = []
    events = []
    idx = 0
    for sgn in (1.0, -1.0):
        for s in speeds:
            target = sgn * float(s)
            nr = int(round(ramp / dt))
            nh = int(round(hold / dt))
            prev = v_parts[-1][-1] if v_parts else 0.0
            if order == "descending" and prev * target < 0:
                # through rest into the other direction: stop, then start at the fastest plateau
                v_parts.append(np.linspace(prev, 0.0, nr))
                t += nr * dt
                prev = 0.0
            v_parts.append(np.linspace(prev, target, nr))
            t += nr * dt
            events.append(Event(t, "plateaus", f"plateau{target:+.4g}", idx, START, target))
            v_parts.append(np.full(nh, target))
            t += nh * dt
            events.append(Event(t, "plateaus", f"plateau{target:+.4g}", idx, END, target))
            idx += 1
    # ramp to rest and stay there 0.5 s (closes the last plateau for automatic detection)
    stop = [np.linspace(v_parts[-1][-1], 0.0, int(round(ramp / dt))), np.zeros(int(round(0.5 / dt)))]
    v = np.concatenate(v_parts + stop)
    return run_velocity_loop(
        v,
        dt,
        preset=preset,
        friction=friction,
        overrides=overrides,
        events=events,
        kp=kp,
        ki=ki,
        position_feedback=position_feedback,
    )


def write_bag(
    path: str | Path,
    rec: Record,
    *,
    joint: str = "joint1",
    topic: str = "/joint_states",
    events_topic: str | None = "/experiment_events",
    with_effort: bool = True,
    extra_joint: str | None = "other_joint",
    t0: float = 1_700_000_000.0,
) -> Path:
    """Write ``rec`` as a rosbag2 MCAP directory (JointState with 1-2 joints + ExperimentEvent)."""
    from friction_ros.core.bag import BagWriter, encode, load_installed, make_qos

    js_defs = load_installed("sensor_msgs/msg/JointState")
    ev_defs = load_installed("friction_msgs/msg/ExperimentEvent") if events_topic else None
    path = Path(path)
    names = [joint] + ([extra_joint] if extra_joint else [])
    with BagWriter(path, overwrite=True) as w:
        w.add_topic(topic, "sensor_msgs/msg/JointState", qos_profiles=[make_qos()])
        if events_topic:
            w.add_topic(events_topic, "friction_msgs/msg/ExperimentEvent", qos_profiles=[make_qos()])
        evs = sorted(rec.events, key=lambda e: e.time)
        ei = 0
        for k in range(rec.t.size):
            ts = t0 + rec.t[k]
            while events_topic and ei < len(evs) and evs[ei].time <= rec.t[k]:
                e = evs[ei]
                te = t0 + e.time
                msg = {
                    "header": {
                        "stamp": {"sec": int(te), "nanosec": int(round((te % 1) * 1e9)) % 1_000_000_000}
                    },
                    "program": e.program,
                    "segment": e.segment,
                    "index": e.index,
                    "event": e.event,
                    "target": e.target,
                    "note": e.note,
                }
                w.write(
                    events_topic, encode(ev_defs, "friction_msgs/msg/ExperimentEvent", msg), int(te * 1e9)
                )
                ei += 1
            sec = int(ts)
            msg = {
                "header": {"stamp": {"sec": sec, "nanosec": int(round((ts - sec) * 1e9)) % 1_000_000_000}},
                "name": names,
                "position": [rec.position[k]] + [0.0] * (len(names) - 1),
                "velocity": [rec.velocity[k]] + [0.0] * (len(names) - 1),
                "effort": ([rec.effort[k]] + [0.0] * (len(names) - 1)) if with_effort else [],
            }
            w.write(topic, encode(js_defs, "sensor_msgs/msg/JointState", msg), int(ts * 1e9))
    return path
