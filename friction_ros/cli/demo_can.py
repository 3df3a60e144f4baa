"""``friction-demo --can PROTOCOL``: the demo's joint behind an emulated drive on a CAN bus.

The preset's plant runs inside ``drive_emulator`` (a drive speaking PROTOCOL on the ``friction_local``
bus, its own process) and ``drive_interface`` turns the bus into ``joint_states`` /
``joint_commands``, as on a robot; the experiment, the recorder and the controller are the lockstep
demo's, on ROS topics. A CAN bus has no lockstep: everything runs in real time on the wall clock
(1 kHz), so a run is honest only if the drive stayed enabled and its telemetry fresh for the whole
run: :class:`CanStack` watches ``drive_state`` and turns a fault into an error naming it, and checks
that the drive reports itself disabled when its node has stopped.
"""

from __future__ import annotations

import sys
import threading
import time
import uuid
from dataclasses import dataclass, field

from friction_ros.cli.bringup import Bringup, NodeSpec
from friction_ros.core.can.mit import MitRanges

MIT = MitRanges()  # the MIT ranges the emulated drive and drive_interface use by default

#: drive_state fault flags that make a run worthless (friction_msgs/DriveState): stale telemetry,
#: a drive error, a bus fault, implausible telemetry (a watchdog or a clamped command is not one)
FATAL_FLAGS = {1: "telemetry stale", 2: "drive error", 32: "CAN bus fault", 64: "telemetry implausible"}
#: the node id of the emulated drive (valid for every built-in protocol: ODrive 0..63, MIT, CiA 402 1..127)
NODE_ID = 1
#: the CAN path's delay beyond the preset's, in control periods: the telemetry the drive node reads
#: is up to a period old, and it sends the controller's command at its next period
EXTRA_DELAY_PERIODS = 2
#: longest wait for the drive to come up enabled (NMT + SDO configuration + state machine for CiA 402)
ENABLE_TIMEOUT = 30.0
#: poll period of the start-up waits (the emulator's first line, the drive enabled): a step waits
#: on average half of it per wait beyond the event itself
POLL = 0.01


@dataclass
class CanJoint:
    """The drive of one demo preset: protocol, bus channel and ``drive_interface`` parameters."""

    protocol: str
    preset: str
    joint: str
    channel: str
    drive_params: dict
    #: one entry per drive stack the demo ran: (step, the drive reported disabled after its node stopped)
    disabled_after: list = field(default_factory=list)


def drive_parameters(preset_obj, protocol: str, joint: str, channel: str) -> dict:
    """``drive_interface`` parameters for the preset's plant behind ``protocol``: the conversion of the
    emulated drive (gear ratio, torque constant: :func:`~friction_ros.core.can.emulator.plant_from_preset`)
    and limits from the joint's scale: torque limit = what the preset's actuator delivers at the joint,
    current limit 10 % above the current of that torque, velocity limit = the preset's speed limit.
    MIT frames carry torque and velocity within the motor's ``mit.t_*``/``mit.v_*`` ranges (the
    defaults of drive_interface and the emulated drive): the limits stay inside them."""
    from friction_ros.core.experiment.joint_scale import JointScale

    p = preset_obj.params
    scale = JointScale.from_preset(preset_obj)
    gain = p.torque_constant * p.ratio  # joint N*m per motor A
    out = {
        "interface": "friction_local",
        "channel": channel,
        "protocol": protocol,
        "node_id": NODE_ID,
        "joint_name": joint,
        "control_period": 0.001,
        "enable_on_start": True,
        "gear_ratio": float(p.ratio),
        "torque_constant": float(p.torque_constant),
        "torque_limit": float(scale.torque_limit),
        "current_limit": float(1.1 * scale.torque_limit / gain),
        "velocity_limit": float(scale.speed_limit),
    }
    if protocol == "mit":  # the motor's MIT ranges (the emulated drive's defaults) bound the limits
        out["torque_limit"] = min(out["torque_limit"], 0.9 * min(-MIT.t_min, MIT.t_max) * p.ratio)
        out["velocity_limit"] = min(out["velocity_limit"], min(-MIT.v_min, MIT.v_max) / p.ratio)
    return out


def can_joint(preset_obj, preset: str, protocol: str, joint: str) -> CanJoint:
    channel = f"demo_{uuid.uuid4().hex[:8]}"
    return CanJoint(protocol, preset, joint, channel, drive_parameters(preset_obj, protocol, joint, channel))


def experiment_limits(cj: CanJoint) -> dict[str, float]:
    """``friction-experiment --set`` limits the wire imposes: MIT frames carry the motor position
    and velocity within ``mit.p_*`` (+-12.5 rad) and ``mit.v_*`` (+-65 rad/s) (the motor's, kept
    at their defaults): the program stays within 80 % of the position range and 90 % of the
    velocity range; none for the other protocols."""
    if cj.protocol != "mit":
        return {}
    ratio = float(cj.drive_params["gear_ratio"])
    return {
        "limits.max_travel": 0.8 * min(-MIT.p_min, MIT.p_max) / ratio,
        "limits.max_velocity": 0.9 * float(cj.drive_params["velocity_limit"]),
    }


class _Program(NodeSpec):
    """``drive_emulator``: a process that is not a ROS node (no ``--ros-args``)."""

    def command(self) -> list[str]:
        return [sys.executable, "-m", f"friction_ros.nodes.{self.node}", *self.args]


class DriveWatch:
    """``drive_state`` of the joint in this process: enabled seen, fatal faults (first time, names)."""

    def __init__(self, joint: str):
        import rclpy
        from friction_msgs.msg import DriveState

        from friction_ros.nodes.qos import SENSOR_QOS
        from friction_ros.nodes.runtime import make_executor

        if not rclpy.ok():
            rclpy.init()
        self.joint = joint
        self.enabled = False
        self.faults: dict[str, float] = {}
        self.disabled_while_running: float | None = None
        self.t0 = time.monotonic()
        self.node = rclpy.create_node(f"friction_demo_drive_watch_{uuid.uuid4().hex[:6]}")
        self.sub = self.node.create_subscription(DriveState, "drive_state", self._on_state, SENSOR_QOS)
        # the EventsExecutor: drive_state comes once per control period (1 kHz), every message is
        # read (a one-period fault flag counts), and the demo's processes share the CPU with this one
        self.ex = make_executor()
        self.ex.add_node(self.node)
        self._stop = threading.Event()
        self._th = threading.Thread(target=self._spin, daemon=True)
        self._th.start()

    def _spin(self) -> None:
        while not self._stop.is_set():
            self.ex.spin_once(timeout_sec=0.05)

    def _on_state(self, msg) -> None:
        if msg.joint_name != self.joint:
            return
        t = time.monotonic() - self.t0
        for bit, name in FATAL_FLAGS.items():
            if msg.fault_flags & bit:
                self.faults.setdefault(name, t)
        if msg.enabled:
            self.enabled = True
        elif self.enabled and self.disabled_while_running is None:
            self.disabled_while_running = t

    def problem(self) -> str | None:
        """What spoils the run so far (fatal faults, the drive disabling itself), or None."""
        if self.faults:
            return ", ".join(f"{n} at {t:.1f} s" for n, t in sorted(self.faults.items(), key=lambda x: x[1]))
        if self.disabled_while_running is not None:
            return f"the drive disabled itself at {self.disabled_while_running:.1f} s"
        return None

    def close(self) -> None:
        self._stop.set()
        self._th.join(timeout=2)
        self.node.destroy_subscription(self.sub)
        self.node.destroy_node()


class CanStack:
    """``drive_emulator`` + ``drive_interface`` for one demo step (a fresh plant at rest at 0).

    ``with CanStack(cj, "tracking run none") as stack: ... stack.check()``: entering waits until the
    drive reports itself enabled; :meth:`check` raises RuntimeError when a node failed or the drive
    faulted; leaving stops ``drive_interface`` (zero torque, drive disabled), then the emulator, which
    reports the drive's final state: ``cj.disabled_after`` records it."""

    def __init__(self, cj: CanJoint, step: str):
        self.cj, self.step = cj, step
        emulator = _Program(
            "drive_emulator",
            args=[
                "--protocol", cj.protocol, "--interface", "friction_local", "--channel", cj.channel,
                "--node-id", str(NODE_ID), "--preset", cj.preset, "--status-period", "3600",
            ],
        )  # fmt: skip
        # the drive is powered before its node starts (else the node's stale-telemetry timeout runs
        # while the emulator is still loading): two bring-ups, emulator first
        self.emulator = Bringup([emulator], quiet=True)
        self.bring = Bringup([NodeSpec("drive_interface", "", [], dict(cj.drive_params))], quiet=True)
        self.watch: DriveWatch | None = None

    def _failure(self) -> str | None:
        for bring in (self.emulator, self.bring):
            first = bring.first_failure()
            if first:
                return f"{first[0]}: {first[2]}"
        if self.emulator.procs and self.emulator.procs[0][1].poll() is not None:
            return "drive_emulator: exited"
        return None

    def _output(self) -> list[str]:
        return sum(self.emulator.output.values(), []) + sum(self.bring.output.values(), [])

    def __enter__(self) -> CanStack:
        self.watch = DriveWatch(self.cj.joint)
        self.emulator.start()
        end = time.monotonic() + ENABLE_TIMEOUT
        try:
            while not any("drive_emulator:" in ln for ln in self._output()):  # its plant is built
                if self._failure() or time.monotonic() > end:
                    raise RuntimeError(f"{self.step}: drive_emulator did not start: {self._failure()}")
                time.sleep(POLL)
            self.bring.start()
            while not self.watch.enabled:
                failure = self._failure()
                if failure or time.monotonic() > end:
                    lines = self._output()[-10:]
                    why = failure or f"the drive did not report itself enabled within {ENABLE_TIMEOUT:g} s"
                    raise RuntimeError(f"{self.step}: {self.cj.protocol} drive: {why}\n" + "\n".join(lines))
                time.sleep(POLL)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def check(self) -> None:
        """RuntimeError if a node of the stack failed or the drive faulted so far (the run is void);
        the message has the drive node's WARN/ERROR lines (what the fault was)."""
        failure = self._failure()
        problem = self.watch.problem() if self.watch else None
        if failure or problem:
            what = f"node failed: {failure}" if failure else f"faulted: {problem}"
            logged = [ln for ln in self._output() if "[WARN]" in ln or "[ERROR]" in ln][-6:]
            raise RuntimeError(
                f"{self.step}: the {self.cj.protocol} drive {what}; the run is not a result"
                + "".join(f"\n  {ln}" for ln in logged)
            )

    def __exit__(self, *exc) -> None:
        self.bring.stop()  # drive_interface first: zero torque, drive disabled
        self.emulator.stop()
        if self.watch is not None:
            self.watch.close()
            self.watch = None
        final = [ln for ln in self.emulator.output.get("drive_emulator", []) if "stopped, drive" in ln]
        self.cj.disabled_after.append((self.step, bool(final) and "drive disabled" in final[-1]))


def run_experiment_can(cj: CanJoint, argv: list[str]) -> int:
    """``friction-experiment`` on the emulated drive: ``argv`` (profile, bag, joint, seed) with
    ``--no-sim --drive-preset``; raises RuntimeError when the drive faulted during it."""
    from friction_ros.cli import experiment

    argv = [*argv, "--no-sim", "--drive-preset", cj.preset]
    for key, value in experiment_limits(cj).items():
        argv += ["--set", f"{key}={value:.6g}"]
    with CanStack(cj, "identification experiment") as stack:
        code = experiment.main(argv)
        stack.check()
    return code


def track_realtime(cj: CanJoint, params_file, duration: float, label: str, period: float):
    """One tracking run on the emulated drive in real time: ``compensating_controller`` for
    ``duration`` wall seconds from its first computed period.

    The figures come from the controller's terms file, as in lockstep; a period the controller did
    not compute (the drive node's telemetry came late, a busy machine) is missing, not invented:
    the run keeps the periods computed, ``missing_periods`` counts the others. A drive fault
    (stale telemetry, a drive or bus error) makes the run an error, never a result."""
    from pathlib import Path

    import numpy as np
    from friction_msgs.msg import ControllerState

    from friction_ros.cli.demo_results import TrackingRun
    from friction_ros.nodes.qos import STATE_QOS
    from friction_ros.nodes.terms_file import read_terms_file

    terms_path = Path(params_file).with_name(f"terms_{label}.csv")
    terms_path.unlink(missing_ok=True)
    spec = NodeSpec(
        "compensating_controller",
        "",
        [str(params_file)],
        {"joint_name": cj.joint, "terms_file": str(terms_path)},
    )
    with CanStack(cj, f"tracking run {label}") as stack:
        first: list[float] = []
        node = stack.watch.node
        sub = node.create_subscription(
            ControllerState,
            "controller_state",
            lambda _m: first or first.append(time.monotonic()),
            STATE_QOS,
            raw=True,  # only its arrival counts: no message object per period
        )
        bring = Bringup([spec], quiet=True)
        t0 = time.monotonic()
        bring.start()
        try:
            while not first or time.monotonic() < first[0] + duration + 0.1:
                stack.check()
                if bring.failed():
                    out = "\n".join(sum(bring.output.values(), [])[-20:])
                    raise RuntimeError(f"tracking run {label}: the controller failed\n{out}")
                if not first and time.monotonic() - t0 > 60:
                    raise RuntimeError(f"tracking run {label}: the controller computed nothing in 60 s")
                time.sleep(0.02)
        finally:
            bring.stop()  # the controller first (zero torque), then the drive stack on leaving
            node.destroy_subscription(sub)
        wall = time.monotonic() - t0
        stack.check()
    rows = read_terms_file(str(terms_path)) if terms_path.exists() else {"stamp_ns": []}
    if not rows["stamp_ns"]:
        raise RuntimeError(f"tracking run {label}: the controller wrote no terms")
    stamps = np.asarray(rows["stamp_ns"], dtype=np.int64)
    t_all = (stamps - stamps[0]) * 1e-9
    n_periods = int(round(duration / period))
    # every row within the run's duration (wall-clock stamps jitter: not rounded to a period grid)
    keep = np.nonzero((t_all <= duration + 0.5 * period) & np.concatenate(([True], np.diff(stamps) > 0)))[0]
    if t_all[keep][-1] < duration - 0.1:
        raise RuntimeError(
            f"tracking run {label}: the controller's terms end at {t_all[keep][-1]:.2f} s of {duration:g} s"
        )
    col = lambda name: np.asarray(rows[name], dtype=float)[keep]  # noqa: E731
    print(
        f"[demo]   {label:<12} {duration:g} s real time ({wall:.1f} s wall with the drive start)", flush=True
    )
    return TrackingRun.from_terms(label, t_all[keep], col, wall, max(0, n_periods + 1 - keep.size))
