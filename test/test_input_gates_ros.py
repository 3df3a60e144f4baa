"""Input plausibility gates over DDS: controller, estimator and plant simulator as separate processes
fed bad messages by this test (future/zero/old stamps, absurd finite values, NaN/inf, wrong names and
lengths, 10k bursts): they stay up, keep working on the valid samples, log every rejection
(rate-limited) and count it in their diagnostics."""

from __future__ import annotations

import math
import re
import time

import pytest
from ros_graph import Graph, Listener, write_params

from friction_ros.cli.bringup import NodeSpec
from friction_ros.core.control.controller import CompensatingController
from friction_ros.core.wire import JointStateEncoder
from friction_ros.nodes.qos import RECORDED_QOS

pytestmark = pytest.mark.ros

PID = {"p": 200.0, "i": 50.0, "d": 0.15}
OFFSET = 0.1  # constant reference [rad]
TORQUE = 5.0  # a valid plant command [N*m]
PACE = 5  # valid samples sent before waiting for the controller (its reader keeps 10)


def _status(diags, name: str) -> dict[str, str]:
    """Key/values of the newest diagnostics status whose name ends with ``name``."""
    for m in reversed(diags):
        for s in m.status:
            if s.name.endswith(name):
                return {kv.key: kv.value for kv in s.values}
    return {}


def _lines(log: str, text: str) -> list[str]:
    return [ln for ln in log.splitlines() if text in ln]


def test_controller_and_estimator_reject_bad_states_and_keep_working(tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from friction_msgs.msg import ControllerState, FrictionEstimate
    from sensor_msgs.msg import JointState

    ctrl = {
        "mode": "pid",
        "effort_limit": 100.0,
        "pid": PID,
        "reference": {"type": "constant", "offset": OFFSET},
        "state_timeout": 0.2,
        "diagnostics_period": 0.1,
        "input_gate": {"max_velocity": 100.0},
    }
    est = {
        "method": "torque_balance",
        "model": "coulomb_viscous",
        "inertia": 0.0012,
        "publish_every": 1,
        "diagnostics_period": 0.1,
        "input_gate": {"max_velocity": 100.0},
    }
    params = write_params(
        tmp_path / "p.yaml",
        {
            "compensating_controller": {"ros__parameters": ctrl},
            "friction_estimator": {"ros__parameters": est},
        },
    )
    specs = [NodeSpec("compensating_controller", "", [params]), NodeSpec("friction_estimator", "", [params])]
    enc = JointStateEncoder(["joint1"])
    valid: set[float] = set()  # positions of the valid (stamped or unstamped) samples
    bad: set[float] = set()  # positions of samples that must be rejected
    paced_valid: set[float] = set()  # valid samples sent once the controller answered (none may be lost)
    warmup: set[float] = set()  # valid samples sent before every reader matched (may be unseen)
    k = [0]

    def pos() -> float:
        k[0] += 1
        return 1e-5 * k[0]  # unique, slow (0.5 mrad/s at 500 Hz): every valid sample is plausible

    def send(stamp_ns=None, p=None, v=0.0, e=0.1, *, good=True):
        p = pos() if p is None else p
        s = time.time_ns() if stamp_ns is None else stamp_ns
        pub.publish(enc.pack_ns(s, p, v, e))
        (valid if good else bad).add(p)

    def run_valid(n, dt=0.002, *, paced=True):
        """``n`` valid samples at 500 Hz. Paced: after every ``PACE`` samples wait until the controller
        answered the last one, so its keep-last-10 reader (a controller drops a stale backlog by
        design) never overflows however slow this machine is: every valid sample must be used."""
        for i in range(n):
            send()
            (paced_valid if paced else warmup).add(1e-5 * k[0])
            time.sleep(dt)
            if paced and ((i + 1) % PACE == 0 or i == n - 1):
                p = 1e-5 * k[0]
                assert lis.wait_for(lambda p=p: bool(states) and states[-1].position == p, 20, g), (
                    "the controller did not answer a valid sample"
                )

    with Listener() as lis:
        states = lis.subscribe(ControllerState, "controller_state", RECORDED_QOS)
        estimates = lis.subscribe(FrictionEstimate, "friction_estimate", RECORDED_QOS)
        commands = lis.subscribe(JointState, "joint_commands", RECORDED_QOS)
        diags = lis.subscribe(DiagnosticArray, "diagnostics")
        pub = lis.publisher(JointState, "joint_states")
        msg_pub = pub
        with Graph(specs) as g:
            assert lis.wait_for(
                lambda: pub.get_subscription_count() >= 2 and lis.matched("controller_state"), 60, g
            )
            t_end = time.monotonic() + 30
            while not (states and estimates) and time.monotonic() < t_end:  # writers matched too
                run_valid(10, paced=False)
            assert states and estimates, "controller/estimator did not answer valid joint states"
            run_valid(100)

            def counted(reason: str, n: int) -> None:
                """Nothing else is sent until both nodes counted the bad sample: it cannot be pushed
                out of their keep-last readers by later samples, so the counts below are exact."""
                ok = lis.wait_for(
                    lambda: all(
                        int(_status(diags, node).get(f"rejected.{reason}", -1)) >= n
                        for node in ("compensating_controller", "friction_estimator")
                    ),
                    20,
                    g,
                )
                assert ok, f"{reason} not counted"
                run_valid(20)

            # one of each bad kind, each followed by valid samples
            t_first = time.monotonic()
            send(time.time_ns() + 1000 * 10**9, good=False)  # future stamp (+1000 s)
            counted("future_stamp", 1)
            send(time.time_ns() - 10 * 10**9, good=False)  # old stamp (-10 s)
            counted("old_stamp", 1)
            for _ in range(20):  # unstamped: each one is a new sample at its receive time
                send(0)
                p = 1e-5 * k[0]
                assert lis.wait_for(lambda p=p: states[-1].position == p, 20, g)
            run_valid(20)
            send(p=1e300, good=False)  # absurd finite position
            counted("out_of_range", 1)
            send(p=math.nan, good=False)
            counted("not_finite", 1)
            send(v=math.inf, good=False)
            counted("not_finite", 2)
            send(p=5.0, good=False)  # 5 rad jump in 2 ms (allowed: 100 rad/s x 2 ms)
            counted("jump", 1)
            wrong = JointState(name=["other"], position=[0.0], velocity=[0.0], effort=[0.0])
            wrong.header.stamp.sec = int(time.time())
            msg_pub.publish(wrong)
            counted("wrong_joint", 1)
            for n in (0, 2):  # wrong lengths
                m = JointState(name=["joint1"], position=[0.0] * n, velocity=[], effort=[])
                m.header.stamp.sec = int(time.time())
                msg_pub.publish(m)
                counted("wrong_length", 1 if n == 0 else 2)
            # only bad samples for 0.8 s: zero torque after state_timeout, logged once, and once cleared
            n_cmd = len(commands)
            t_end = time.monotonic() + 0.8
            while time.monotonic() < t_end:
                send(p=math.nan, good=False)
                time.sleep(0.002)
            zero_seen = any(c.effort[0] == 0.0 for c in commands[n_cmd:])
            run_valid(50)
            # a 10k burst of absurd samples as fast as this process can publish
            for _ in range(10_000):
                send(p=1e300, good=False)
            span = time.monotonic() - t_first  # first to last rejection of each kind
            n_cmd = len(commands)
            run_valid(100)
            assert lis.wait_for(lambda: len(commands) > n_cmd + 50, 10, g), "no commands after the burst"
            time.sleep(0.5)  # last diagnostics
            g.assert_alive()
            log_c = g.output("compensating_controller")
            log_e = g.output("friction_estimator")

    # -- the controller: only valid samples entered it, and its commands are those of a clean run --
    used = [m.position for m in states]
    assert not set(used) & bad, "a rejected sample reached the controller"
    stamped_valid = len(valid - warmup)
    n_used = len(set(used) - warmup)
    assert n_used >= 0.9 * stamped_valid, f"{n_used} of {stamped_valid} valid samples after the warm-up used"
    lost = paced_valid - set(used)
    assert not lost, f"{len(lost)} of {len(paced_valid)} paced valid samples not used by the controller"
    replica = CompensatingController({"mode": "pid", "pid": PID})
    replica.pid.integral = states[0].i_term  # the warm-up samples before the first received state
    for m in states:
        out = replica.compute(0.0, (OFFSET, 0.0, 0.0), (m.position, m.velocity), 0.001)
        assert out.command == m.command, "the node's controller state differs from a clean run"
    assert all(math.isfinite(c.effort[0]) and abs(c.effort[0]) < 25.0 for c in commands)
    assert zero_seen, "no zero-torque command once only bad samples came for longer than state_timeout"
    # every rejection counted (exact for the single ones; the burst is thinned by the keep-last reader)
    for log, values in (
        (log_c, _status(diags, "compensating_controller")),
        (log_e, _status(diags, "friction_estimator")),
    ):
        counts = {k: int(v) for k, v in values.items() if k.startswith("rejected.")}
        assert counts["rejected.future_stamp"] == 1, values
        assert counts["rejected.old_stamp"] == 1
        assert counts["rejected.jump"] == 1
        assert counts["rejected.wrong_joint"] == 1
        assert counts["rejected.wrong_length"] == 2
        assert counts["rejected.out_of_range"] >= 2  # 1e300 once + at least one of the burst
        assert counts["rejected.not_finite"] >= 2 + 10  # NaN, inf, and the 0.8 s of NaN
        assert int(values["rejected_states"]) == sum(counts.values())
        assert int(values["unstamped_states"]) == 20 and int(values["resyncs"]) == 0
        for reason in counts:
            assert _lines(log, f"[{reason[9:]}]"), f"no log line for {reason}:\n{log}"
        # rate-limited: at most one line per reason per second (log_period 1 s)
        for reason in ("out_of_range", "not_finite"):
            assert len(_lines(log, f"[{reason}]")) <= 1 + span, log
    # zero torque logged once when it starts (the NaN phase; the burst if it lasted > 0.2 s, the end
    # of the test, a stall of this process) and once when it clears
    timeouts = _lines(log_c, "no valid joint state for 0.2 s (")
    assert any("last reason not_finite" in ln for ln in timeouts), log_c
    assert len(timeouts) - len(_lines(log_c, "joint states valid again")) in (0, 1), log_c
    assert all(math.isfinite(e.friction_torque) for e in estimates)


@pytest.mark.realtime  # wall-clock timing: a CPU of its own, after the other tests
def test_plant_simulator_rejects_absurd_commands_and_keeps_running(tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState

    from friction_ros.nodes.qos import COMMAND_QOS

    specs = [
        NodeSpec(
            "plant_simulator",
            "",
            [],
            {"preset": "seed001_harmonic_drive", "mode": "realtime", "diagnostics_period": 0.2},
        )
    ]
    with Listener() as lis:
        joints = lis.subscribe(JointState, "joint_states", RECORDED_QOS)
        diags = lis.subscribe(DiagnosticArray, "diagnostics")
        pub = lis.publisher(JointState, "joint_commands", COMMAND_QOS)

        def cmd(effort, name=("joint1",)):
            pub.publish(JointState(name=list(name), effort=list(effort)))
            time.sleep(0.05)  # keep-last 1: let the plant take each one

        with Graph(specs) as g:
            assert lis.wait_for(lambda: pub.get_subscription_count() >= 1 and len(joints) > 10, 60, g)
            for e in (1e308, -8.9e307, math.nan, math.inf, 1e7):
                cmd([e])
            cmd([0.5], name=("other",))
            cmd([], name=("joint1",))
            cmd([0.5, 0.5], name=())
            for _ in range(10_000):  # burst
                pub.publish(JointState(name=["joint1"], effort=[1e308]))
            n = len(joints)
            for _ in range(20):  # a valid command, refreshed within command_timeout
                cmd([TORQUE])
            assert len(joints) > n + 200
            g.assert_alive()
            log = g.output("plant_simulator")
    assert all(math.isfinite(m.position[0]) and math.isfinite(m.velocity[0]) for m in joints)
    assert joints[-1].velocity[0] > 0.1  # the valid command drives the joint
    v = _status(diags, "plant_simulator")
    assert int(v["rejected.not_finite"]) == 2
    assert int(v["rejected.out_of_range"]) >= 3 + 1  # 1e308, -8.9e307, 1e7 and the burst (thinned)
    assert int(v["rejected.wrong_joint"]) == 1 and int(v["rejected.wrong_length"]) == 2
    assert int(v["commands_ignored"]) == 3
    assert int(v["commands_rejected"]) == int(v["rejected.not_finite"]) + int(v["rejected.out_of_range"])
    for reason in ("not_finite", "out_of_range", "wrong_joint", "wrong_length"):
        assert _lines(log, f"[{reason}]"), log
    assert len(_lines(log, "[out_of_range]")) <= 4, log
    assert "Traceback" not in log and not re.search(r"ValueError|OverflowError", log)
