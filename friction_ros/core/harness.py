"""Deterministic lockstep closed loop: plant + controller + (optional) estimator at the control period.

Per period k (t_k = k dt)::

    r_k        = reference(t_k)                        (pos, vel, acc)
    tau_k      = controller.update(t_k, r_k, (pos_k, vel_k), dt)        joint torque [N*m]
    command_k  = tau_k * command_scale                  plant command unit (A, N*m or V)
    meas_{k+1} = plant.step(command_k, dt)              sensors at the end of the period
    estimator.update(t_{k+1}, pos, vel, effort, dt)     (optional; coefficients can be adopted
                                                          by the controller every ``adopt_period``)

``command_scale`` is the plant's (:attr:`GearheadServoPlant.command_scale`): it converts the
controller's joint torque to the plant's command unit.

N joints (:func:`run_closed_loop_group`): one plant per joint, one
:class:`~friction_ros.core.joint_group.JointGroup` (the compensating_controller node's per-sample
path: gate, reference, time base, timeout, fallback) fed one joint-state sample per period.

Everything is seeded and stepped in one thread, so the same inputs give bit-identical outputs
(tests, benchmarks and the ROS lockstep comparison rely on it).

Metrics (:func:`tracking_metrics`) use the *true* joint position (the encoder is a sensor):
``rms_error``, ``max_error``, ``final_error`` (|e| at the end), ``rms_error_measured``;
stick-slip: ``stick_fraction`` (share of the time the joint is stuck, |v| < v_stick, while the
reference moves, |v_ref| > 2 v_stick) and ``stick_events`` (entries into such sticking);
hunting (over the last ``window`` seconds): ``hunting_amplitude`` (peak-to-peak position),
``hunting_reversals`` (velocity sign changes with |v| > v_stick) and ``hunting`` (reversals >= 4
and amplitude above ``resolution``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from friction_ros.core.control.controller import CompensatingController, ControllerTerms
from friction_ros.core.control_period import DEFAULT_CONTROL_PERIOD
from friction_ros.core.estimation.estimator import OnlineFrictionEstimator
from friction_ros.core.experiment.references import Reference, reference_from_config
from friction_ros.core.input_gate import JointInputGate
from friction_ros.core.joint_group import JointGroup
from friction_ros.core.joint_group_inputs import control_channel
from friction_ros.core.plant.servo import GearheadServoPlant
from friction_ros.core.presets import Preset, make_plant
from friction_ros.core.validation import check_real
from friction_ros.core.wire import DecodedJointState


@dataclass
class LoopResult:
    """Time series of one closed-loop run plus its metrics."""

    t: np.ndarray
    reference: np.ndarray  # (n, 3) pos, vel, acc
    position: np.ndarray  # measured
    velocity: np.ndarray  # measured
    true_position: np.ndarray
    true_velocity: np.ndarray
    torque: np.ndarray  # controller output [N*m]
    command: np.ndarray  # plant command unit
    effort: np.ndarray  # measured joint torque
    friction: np.ndarray  # true friction (motor + load side, plant's report)
    terms: dict[str, np.ndarray] = field(default_factory=dict)
    estimate: dict[str, np.ndarray] = field(default_factory=dict)
    metrics: dict[str, float] = field(default_factory=dict)

    @property
    def error(self) -> np.ndarray:
        return self.reference[:, 0] - self.true_position


#: The control law's terms (ControllerTerms fields): p/i/d terms, feed-forwards and friction feedback.
_TERM_KEYS = tuple(
    f.name for f in fields(ControllerTerms) if f.name.endswith(("_term", "_feedforward", "_feedback"))
)


def tracking_metrics(
    t: np.ndarray,
    ref: np.ndarray,
    pos: np.ndarray,
    vel: np.ndarray,
    ref_vel: np.ndarray | None = None,
    pos_measured: np.ndarray | None = None,
    *,
    window: float = 1.0,
    v_stick: float = 1e-4,
    resolution: float = 0.0,
    skip: float = 0.0,
) -> dict[str, float]:
    """Tracking, stick-slip and hunting metrics (see the module docstring)."""
    t = np.asarray(t)
    sel = t >= skip
    e = (np.asarray(ref) - np.asarray(pos))[sel]
    out = {
        "rms_error": float(np.sqrt(np.mean(e * e))),
        "max_error": float(np.max(np.abs(e))),
        "final_error": float(abs(e[-1])),
    }
    if pos_measured is not None:
        em = (np.asarray(ref) - np.asarray(pos_measured))[sel]
        out["rms_error_measured"] = float(np.sqrt(np.mean(em * em)))
    vel = np.asarray(vel)
    if ref_vel is not None:
        rv = np.asarray(ref_vel)
        moving = np.abs(rv) > 2.0 * v_stick
        stuck = moving & (np.abs(vel) < v_stick)
        out["stick_fraction"] = float(np.sum(stuck & sel) / max(np.sum(moving & sel), 1))
        out["stick_events"] = int(np.sum(stuck[1:] & ~stuck[:-1] & sel[1:]))
    win = t >= t[-1] - window
    pw, vw = np.asarray(pos)[win], vel[win]
    amp = float(np.max(pw) - np.min(pw)) if pw.size else 0.0
    s = np.sign(np.where(np.abs(vw) > v_stick, vw, 0.0))
    s = s[s != 0]
    rev = int(np.sum(s[1:] != s[:-1])) if s.size > 1 else 0
    out["hunting_amplitude"] = amp
    out["hunting_reversals"] = rev
    out["hunting"] = float(rev >= 4 and amp > resolution)
    return out


def run_closed_loop(
    plant: str | Preset | Mapping[str, Any] | GearheadServoPlant,
    controller: CompensatingController | Mapping[str, Any],
    reference: Reference | Mapping[str, Any],
    duration: float,
    dt: float = DEFAULT_CONTROL_PERIOD,
    *,
    estimator: OnlineFrictionEstimator | Mapping[str, Any] | None = None,
    adopt_period: float = 0.0,
    scale: float | None = None,
    initial_position: float | None = None,
    initial_velocity: float = 0.0,
    record_terms: bool = False,
    metrics: Mapping[str, Any] | None = None,
) -> LoopResult:
    """Run the lockstep loop for ``duration`` seconds at period ``dt``; see the module docstring.

    ``plant``: preset (name or object), plant config (:func:`~friction_ros.core.presets.make_plant`)
    or GearheadServoPlant (reset here to the reference's initial position unless
    ``initial_position`` is given). ``adopt_period > 0`` with an estimator:
    every ``adopt_period`` seconds the controller adopts ``estimator.model_config()`` once the
    estimator has converged. ``metrics``: keyword arguments of :func:`tracking_metrics`.
    """
    duration = check_real("harness.duration", duration, 0.0, lo_open=True, unit="s")
    dt = check_real("harness.dt", dt, 0.0, 1.0, lo_open=True, unit="s")
    adopt_period = check_real("harness.adopt_period", adopt_period, 0.0, unit="s")
    if not isinstance(plant, GearheadServoPlant):
        plant = make_plant(plant)
    ctrl = (
        controller if isinstance(controller, CompensatingController) else CompensatingController(controller)
    )
    ref = reference_from_config(reference)
    est = None
    if estimator is not None:
        est = (
            estimator
            if isinstance(estimator, OnlineFrictionEstimator)
            else OnlineFrictionEstimator(estimator)
        )
    k_scale = plant.command_scale if scale is None else float(scale)
    n = int(round(duration / dt))
    t = np.arange(n) * dt
    R = np.column_stack(ref.arrays(t))
    x0 = R[0, 0] if initial_position is None else float(initial_position)
    plant.reset(position=x0, velocity=float(initial_velocity))
    ctrl.reset()
    if est is not None:
        est.reset()
    pos_m, vel_m = x0, float(initial_velocity)
    cols = {k: np.empty(n) for k in ("pos", "vel", "tpos", "tvel", "tau", "cmd", "eff", "fric")}
    terms = {k: np.empty(n) for k in _TERM_KEYS} if record_terms else {}
    est_cols = {k: np.empty(n) for k in ("friction_torque", "model_torque", "excitation_ok")} if est else {}
    adopt_every = int(round(adopt_period / dt)) if adopt_period > 0 else 0
    update = ctrl.compute
    step = plant.step
    for k in range(n):
        r = (R[k, 0], R[k, 1], R[k, 2])
        tm = update(t[k], r, (pos_m, vel_m), dt)
        tau = tm.command
        m = step(tau * k_scale, dt)
        pos_m, vel_m = m.position, m.velocity
        cols["pos"][k] = m.position
        cols["vel"][k] = m.velocity
        cols["tpos"][k] = m.true_position
        cols["tvel"][k] = m.true_velocity
        cols["tau"][k] = tau
        cols["cmd"][k] = tau * k_scale
        cols["eff"][k] = m.effort
        cols["fric"][k] = m.friction_motor + m.friction_load
        if record_terms:
            for key in _TERM_KEYS:
                terms[key][k] = getattr(tm, key)
        if est is not None:
            e = est.update(t[k] + dt, m.position, m.velocity, m.effort, dt)
            est_cols["friction_torque"][k] = e.friction_torque
            est_cols["model_torque"][k] = e.model_torque
            est_cols["excitation_ok"][k] = e.excitation_ok
            if adopt_every and (k + 1) % adopt_every == 0 and e.converged:
                ctrl.set_coefficients(est.model_config())
    # position recorded at the end of each period belongs to t + dt: compare with r(t + dt)
    t_end = t + dt
    R_end = np.column_stack(ref.arrays(t_end))
    res = LoopResult(
        t=t_end,
        reference=R_end,
        position=cols["pos"],
        velocity=cols["vel"],
        true_position=cols["tpos"],
        true_velocity=cols["tvel"],
        torque=cols["tau"],
        command=cols["cmd"],
        effort=cols["eff"],
        friction=cols["fric"],
        terms=terms,
        estimate=est_cols,
    )
    res.metrics = tracking_metrics(
        t_end, R_end[:, 0], cols["tpos"], cols["tvel"], R_end[:, 1], cols["pos"], **dict(metrics or {})
    )
    return res


@dataclass
class GroupResult:
    """Time series of one N-joint run (columns in ``joints`` order) plus per-joint metrics."""

    joints: list[str]
    t: np.ndarray  # end of each period [s]
    reference: np.ndarray  # (n, N) reference position at t (the built-in generators)
    position: np.ndarray  # (n, N) measured
    true_position: np.ndarray  # (n, N)
    torque: np.ndarray  # (n, N) the group's command [N*m or N]
    received: np.ndarray  # (n, N) bool: the joint was in that period's sample
    fallback: np.ndarray  # (n, N) bool: compensation switched off by the run-time watch
    timed_out: np.ndarray  # (n, N) bool: no valid state for state_timeout: zero torque
    events: list[tuple[float, int, str]]  # (t, level, text): what the node would log
    metrics: dict[str, dict[str, float]]
    group: JointGroup

    def column(self, joint: str) -> int:
        return self.joints.index(joint)


def run_closed_loop_group(
    joints: Mapping[str, tuple],
    duration: float,
    dt: float = DEFAULT_CONTROL_PERIOD,
    *,
    missing: Mapping[str, tuple[float, float]] | None = None,
    position_offset: Mapping[str, tuple[float, float]] | None = None,
    stamp_jump: tuple[float, float] | None = None,
    state_timeout: float = 0.05,
    input_gate: Mapping[str, Any] | None = None,
    metrics: Mapping[str, Any] | None = None,
) -> GroupResult:
    """Lockstep loop of N joints through one :class:`~friction_ros.core.joint_group.JointGroup`
    (the compensating_controller node's per-sample path), one plant per joint.

    ``joints``: name -> (plant, controller, reference) as :func:`run_closed_loop` takes them. Per
    period k the group gets one sample (node clock ``c_k = 1 s + k dt``, stamp ``c_k`` plus any
    ``stamp_jump``) and ``check_timeout(t_k, state_timeout)``; plant j steps with the group's
    command of j. Faults: ``missing``: joint -> (t0, t1), the joint is not in the samples then;
    ``position_offset``: joint -> (t0, offset), from t0 on its reported position is offset (a
    re-homing); ``stamp_jump``: (t0, seconds), from t0 on every stamp jumps ahead (a clock jump).
    ``input_gate``: the gate's config of every joint.
    """
    duration = check_real("harness.duration", duration, 0.0, lo_open=True, unit="s")
    dt = check_real("harness.dt", dt, 0.0, 1.0, lo_open=True, unit="s")
    names = list(joints)
    plants, channels, refs, scales = [], [], [], []
    for j in names:
        plant, controller, reference = joints[j]
        plant = plant if isinstance(plant, GearheadServoPlant) else make_plant(plant)
        ctrl = (
            controller
            if isinstance(controller, CompensatingController)
            else CompensatingController(controller)
        )
        ref = reference_from_config(reference)
        gate = JointInputGate(j, dict(input_gate or {}), period=dt)
        channels.append(control_channel(j, ctrl, ref, gate))
        plants.append(plant)
        refs.append(ref)
        scales.append(plant.command_scale)
    group = JointGroup(channels, dt)
    n, N = int(round(duration / dt)), len(names)
    t = np.arange(n) * dt
    R = np.column_stack([ref.arrays(t + dt)[0] for ref in refs])
    cols = {k: np.zeros((n, N)) for k in ("pos", "tpos", "tau")}
    flags = {k: np.zeros((n, N), dtype=bool) for k in ("rx", "fb", "to")}
    meas = []
    for ref, plant in zip(refs, plants):
        x0 = float(ref.arrays(np.zeros(1))[0][0])
        plant.reset(position=x0, velocity=0.0)
        meas.append((x0, 0.0, 0.0))
    missing, offsets = dict(missing or {}), dict(position_offset or {})
    events: list[tuple[float, int, str]] = []
    for k in range(n):
        tk = t[k]
        clock_ns = 1_000_000_000 + int(round(tk * 1e9))
        stamp_ns = clock_ns + (int(round(stamp_jump[1] * 1e9)) if stamp_jump and tk >= stamp_jump[0] else 0)
        present = [
            i for i, j in enumerate(names) if not (j in missing and missing[j][0] <= tk < missing[j][1])
        ]
        pos = [
            meas[i][0] + (offsets[names[i]][1] if names[i] in offsets and tk >= offsets[names[i]][0] else 0.0)
            for i in present
        ]
        msg = DecodedJointState(
            stamp_ns // 1_000_000_000,
            stamp_ns % 1_000_000_000,
            "",
            tuple(names[i] for i in present),
            tuple(pos),
            tuple(meas[i][1] for i in present),
            tuple(meas[i][2] for i in present),
        )
        group.step(msg, clock_ns, tk)
        group.check_timeout(tk, state_timeout)
        if group.events:
            events.extend((tk, level, text) for level, text in group.take_events())
        for i in present:
            flags["rx"][k, i] = True
        for i, (ch, plant) in enumerate(zip(group.channels, plants)):
            m = plant.step(ch.command * scales[i], dt)
            meas[i] = (m.position, m.velocity, m.effort)
            cols["pos"][k, i] = m.position
            cols["tpos"][k, i] = m.true_position
            cols["tau"][k, i] = ch.command
            flags["fb"][k, i] = ch.controller.compensation_fallback
            flags["to"][k, i] = ch.timed_out
    t_end = t + dt
    return GroupResult(
        joints=names,
        t=t_end,
        reference=R,
        position=cols["pos"],
        true_position=cols["tpos"],
        torque=cols["tau"],
        received=flags["rx"],
        fallback=flags["fb"],
        timed_out=flags["to"],
        events=events,
        metrics={
            j: tracking_metrics(t_end, R[:, i], cols["tpos"][:, i], cols["tpos"][:, i], **dict(metrics or {}))
            for i, j in enumerate(names)
        },
        group=group,
    )
