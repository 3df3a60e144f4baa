"""Issue "manipulator scale": one friction_estimator node for N joints (``joints``), over real DDS.

The test publishes multi-joint ``joint_states`` one message at a time (each waits for the
estimates it causes, so no reader queue can overflow and every node sees every message) and
compares the FrictionEstimates with single-joint nodes fed the same bytes and with the core
OnlineFrictionEstimator fed the same samples.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time

import pytest
from ros_graph import Graph, Listener, write_params

from friction_ros.cli.bringup import NodeSpec
from friction_ros.core.coefficient_exchange import to_fields
from friction_ros.core.estimation.estimator import OnlineFrictionEstimator
from friction_ros.core.wire import JointStateEncoder
from friction_ros.nodes.qos import RECORDED_QOS

pytestmark = pytest.mark.ros

JOINTS = ["j1", "j2", "j3"]
NODE_LEVEL = {
    "method": "torque_balance",
    "model": "coulomb_viscous",
    "inertia": 0.0012,
    "forgetting_factor": 0.995,
    "initial": {"fc": 0.3, "fv": 0.02},
    "publish_every": 1,
    "diagnostics_period": 0.1,
}
# per joint, in the multi-joint node's layout, and the same as node-level values of a one-joint node
PER_JOINT = {
    "j1": {},
    "j2": {"gains": {"forgetting_factor": 0.98, "min_velocity": 0.02}},
    "j3": {"gains": {"model": "stribeck", "inertia": 0.002}, "initial": {"fc": 0.5}},
}
SINGLE = {  # core config of each joint (j3 names its own model: only its own initial values)
    "j1": {**NODE_LEVEL},
    "j2": {**NODE_LEVEL, "forgetting_factor": 0.98, "min_velocity": 0.02},
    "j3": {**NODE_LEVEL, "model": "stribeck", "inertia": 0.002, "initial": {"fc": 0.5}},
}
PERIOD_NS = 1_000_000
TOL = 1e-9


def multi_params() -> dict:
    p = {**NODE_LEVEL, "joints": JOINTS, "gains": {}, "initial": dict(NODE_LEVEL["initial"])}
    for j, sections in PER_JOINT.items():
        for section, values in sections.items():
            if values:
                p.setdefault(section, {})[j] = dict(values)
    return p


def core_config(joint: str) -> dict:
    return {k: v for k, v in SINGLE[joint].items() if k not in ("publish_every", "diagnostics_period")}


def sample(k: int, i: int) -> tuple[float, float, float]:
    """Position, velocity, effort of joint ``i`` at step ``k`` (a sinusoid per joint, Coulomb +
    viscous friction + inertia torque)."""
    w, a, t = 6.0 + i, 0.2 + 0.1 * i, k * PERIOD_NS * 1e-9
    pos = a * math.sin(w * t + i)
    vel = a * w * math.cos(w * t + i)
    acc = -a * w * w * math.sin(w * t + i)
    eff = (0.4 + 0.2 * i) * math.copysign(1.0, vel) + (0.01 + 0.01 * i) * vel + 0.0012 * acc
    return pos, vel, eff


def packed(enc: JointStateEncoder, stamp_ns: int, k: int, joints: list[str]) -> bytes:
    values = [sample(k, JOINTS.index(j)) for j in joints]
    return enc.pack_ns(stamp_ns, *(v[0] for v in values), *(v[1] for v in values), *(v[2] for v in values))


class Replica:
    """The core estimator of one joint fed what the node's gate accepts (dt from the stamps)."""

    def __init__(self, config: dict):
        self.est = OnlineFrictionEstimator(config)
        self.last_ns: int | None = None

    def restart(self, config: dict) -> None:
        self.est = OnlineFrictionEstimator(config)  # the gate and the last stamp are kept

    def update(self, stamp_ns: int, k: int, i: int) -> tuple[list[float], float]:
        dt = (stamp_ns - self.last_ns) * 1e-9 if self.last_ns is not None else 0.001
        self.last_ns = stamp_ns
        e = self.est.update(stamp_ns * 1e-9, *sample(k, i), dt)
        return to_fields(self.est.model_config())[2], e.friction_torque


def close(a, b) -> bool:
    """Equal to TOL; NaN only where the other is NaN (the std of the fixed Stribeck shape: vs, delta)."""
    same = (abs(x - y) <= TOL or (math.isnan(x) and math.isnan(y)) for x, y in zip(a, b))
    return len(a) == len(b) and all(same)


def _by_stamp(msgs) -> dict[tuple[str, int], object]:
    return {(m.joint_name, m.header.stamp.sec * 10**9 + m.header.stamp.nanosec): m for m in msgs}


def _wait_ready(lis, pubs, topics, g) -> None:
    """Every joint_states writer matched with its node, every estimate topic with this listener."""
    ok = lis.wait_for(
        lambda: all(p.get_subscription_count() >= 1 for p in pubs) and all(lis.matched(t) for t in topics),
        90,
        g,
    )
    assert ok, "the estimator nodes did not come up"
    time.sleep(1.0)  # the nodes' estimate writers match this listener's readers too


def test_three_joints_in_one_node_equal_three_single_joint_nodes(tmp_path):
    from friction_msgs.msg import FrictionEstimate
    from sensor_msgs.msg import JointState

    multi = write_params(
        tmp_path / "multi.yaml", {"/**/friction_estimator": {"ros__parameters": multi_params()}}
    )
    specs = [NodeSpec("friction_estimator", "multi", [multi])]
    for n, j in enumerate(JOINTS, 1):
        f = write_params(
            tmp_path / f"{j}.yaml",
            {"/**/friction_estimator": {"ros__parameters": {**SINGLE[j], "joint_name": j}}},
        )
        specs.append(NodeSpec("friction_estimator", f"s{n}", [f]))
    ns = ["multi", "s1", "s2", "s3"]
    enc = JointStateEncoder(JOINTS)
    n_msgs = 150
    stamp0 = time.time_ns() - 2 * 10**9  # in the past: no future_stamp before the first sample
    with Listener() as lis:
        out = {n: lis.subscribe(FrictionEstimate, f"/{n}/friction_estimate", RECORDED_QOS) for n in ns}
        pubs = [lis.publisher(JointState, f"/{n}/joint_states") for n in ns]
        with Graph(specs) as g:
            _wait_ready(lis, pubs, [f"/{n}/friction_estimate" for n in ns], g)
            for k in range(n_msgs):
                s = stamp0 + k * PERIOD_NS
                data = packed(enc, s, k, JOINTS)
                for p in pubs:
                    p.publish(data)
                ok = lis.wait_for(
                    lambda n=k + 1: len(out["multi"]) >= 3 * n and all(len(out[x]) >= n for x in ns[1:]),
                    30,
                    g,
                )  # the multi node answers with one estimate per joint
                assert ok, f"message {k}: estimates {[len(out[n]) for n in ns]}"
            g.assert_alive()
    assert len(out["multi"]) == 3 * n_msgs and all(len(out[n]) == n_msgs for n in ns[1:])
    got = _by_stamp(out["multi"])
    replicas = {j: Replica(core_config(j)) for j in JOINTS}
    moved = 0
    for i, j in enumerate(JOINTS):
        single = out[f"s{i + 1}"]
        assert {m.joint_name for m in single} == {j}
        for k, ref in enumerate(single):
            s = stamp0 + k * PERIOD_NS
            assert ref.header.stamp.sec * 10**9 + ref.header.stamp.nanosec == s
            m = got[(j, s)]
            assert m.model == ref.model and list(m.coefficient_names) == list(ref.coefficient_names)
            assert close(m.coefficients, ref.coefficients), (
                j,
                k,
                list(m.coefficients),
                list(ref.coefficients),
            )
            assert close(m.coefficient_std, ref.coefficient_std), (j, k)
            assert close(
                [m.friction_torque, m.model_torque, m.velocity],
                [ref.friction_torque, ref.model_torque, ref.velocity],
            )
            assert m.excitation_ok == ref.excitation_ok and m.converged == ref.converged
            coefs, friction = replicas[j].update(s, k, i)
            assert close(m.coefficients, coefs), (j, k, list(m.coefficients), coefs)
            assert abs(m.friction_torque - friction) <= TOL
        start = OnlineFrictionEstimator(core_config(j))
        moved += (
            max(abs(a - b) for a, b in zip(single[-1].coefficients, to_fields(start.model_config())[2]))
            > 0.05
        )
    assert moved == 3, "the coefficients did not adapt: the comparison would be trivial"
    assert got[("j3", stamp0)].model == "stribeck" and got[("j1", stamp0)].model == "coulomb_viscous"


def test_a_joint_missing_from_a_message_does_not_advance_and_per_joint_changes(tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray
    from friction_msgs.msg import FrictionEstimate
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from sensor_msgs.msg import JointState

    f = write_params(tmp_path / "m.yaml", {"/**/friction_estimator": {"ros__parameters": multi_params()}})
    specs = [NodeSpec("friction_estimator", "m", [f])]
    full, partial = JointStateEncoder(JOINTS), JointStateEncoder(["j1", "j3"])
    stamp0 = time.time_ns() - 2 * 10**9
    replicas = {j: Replica(core_config(j)) for j in JOINTS}
    expected: dict[tuple[str, int], tuple[list[float], float]] = {}
    hole = 30  # message 30 has no j2

    with Listener() as lis:
        est = lis.subscribe(FrictionEstimate, "/m/friction_estimate", RECORDED_QOS)
        diags = lis.subscribe(DiagnosticArray, "/m/diagnostics")
        pub = lis.publisher(JointState, "/m/joint_states")
        client = lis.node.create_client(SetParameters, "/m/friction_estimator/set_parameters")

        def send(k: int) -> None:
            s = stamp0 + k * PERIOD_NS
            joints = [j for j in JOINTS if not (k == hole and j == "j2")]
            pub.publish(packed(partial if len(joints) == 2 else full, s, k, joints))
            for j in joints:
                expected[(j, s)] = replicas[j].update(s, k, JOINTS.index(j))
            n = len(expected)
            assert lis.wait_for(lambda: len(est) >= n, 30, g), f"message {k}: {len(est)} of {n} estimates"

        def set_param(name: str, value: float):
            req = SetParameters.Request(
                parameters=[
                    Parameter(
                        name=name,
                        value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value),
                    )
                ]
            )
            fut = client.call_async(req)
            assert lis.wait_for(fut.done, 20, g)
            return fut.result().results[0]

        with Graph(specs) as g:
            _wait_ready(lis, [pub], ["/m/friction_estimate"], g)
            for k in range(2 * hole + 1):
                send(k)

            def status() -> dict[str, dict[str, str]]:
                """The newest diagnostics: {joint: {key: value}} (one status per joint)."""
                if not diags:
                    return {}
                st = diags[-1].status
                return {x.name.rsplit("/", 1)[-1]: {kv.key: kv.value for kv in x.values} for x in st}

            n = 2 * hole + 1  # messages sent so far; j2 was missing from one
            want = {
                "j1": {"samples": str(n), "rejected_states": "0"},
                "j2": {"samples": str(n - 1), "rejected_states": "1", "rejected.wrong_joint": "1"},
                "j3": {"samples": str(n), "rejected_states": "0"},
            }
            ok = lis.wait_for(
                lambda: (
                    (st := status()).keys() == want.keys()
                    and all(st[j][k] == v for j in want for k, v in want[j].items())
                ),
                10,
                g,
            )
            assert ok, status()
            assert diags[-1].status[1].name == "/m/friction_estimator/j2"

            # run time: a bad per-joint value is refused naming the joint's parameter
            assert client.wait_for_service(timeout_sec=20)
            bad = set_param("gains.j2.forgetting_factor", 2.0)
            assert not bad.successful
            assert bad.reason.startswith("gains.j2.forgetting_factor = 2 is out of range"), bad.reason
            # a node-level change: every joint without its own value (j1, j3), not j2
            good = set_param("forgetting_factor", 0.97)
            assert good.successful, good.reason
            for j in ("j1", "j3"):
                replicas[j].restart({**core_config(j), "forgetting_factor": 0.97})
            for k in range(2 * hole + 1, 2 * hole + 21):
                send(k)
            # a per-joint change: that joint only
            good = set_param("gains.j2.forgetting_factor", 0.99)
            assert good.successful, good.reason
            replicas["j2"].restart({**core_config("j2"), "forgetting_factor": 0.99})
            for k in range(2 * hole + 21, 2 * hole + 41):
                send(k)
            g.assert_alive()
            log = g.output("m/friction_estimator")

    got = _by_stamp(est)
    assert len(got) == len(est) == len(expected) == 3 * (2 * hole + 40) + 2
    s_hole = stamp0 + hole * PERIOD_NS
    assert ("j2", s_hole) not in got and ("j1", s_hole) in got and ("j3", s_hole) in got
    for key, (coefs, friction) in expected.items():
        m = got[key]
        assert close(m.coefficients, coefs), (key, list(m.coefficients), coefs)
        assert abs(m.friction_torque - friction) <= TOL, key
    assert "rejected joint state of j2 [wrong_joint]" in log
    assert "parameters changed: forgetting_factor (estimator of j1, j3 restarted)" in log
    assert "parameters changed: gains.j2.forgetting_factor (estimator of j2 restarted)" in log


def _start(tmp_path, name: str, params: dict) -> subprocess.CompletedProcess:
    f = write_params(tmp_path / f"{name}.yaml", {"friction_estimator": {"ros__parameters": params}})
    return subprocess.run(
        [sys.executable, "-m", "friction_ros.nodes.friction_estimator", "--ros-args", "--params-file", f],
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_a_bad_per_joint_value_at_start_up_is_refused_naming_the_joint_parameter(tmp_path):
    cases = {
        # checked by the core estimator (the field has no range of its own)
        "core": (
            {"gains": {"j2": {"forgetting_factor": 2.0}}},
            "error: gains.j2.forgetting_factor = 2 is out of range: must be in (0.5, 1]",
        ),
        # checked by the field (ROS descriptor range) of the node-level parameter it stands for
        "field": (
            {"input_gate": {"j3": {"max_velocity": -1.0}}},
            "error: input_gate.j3.max_velocity = -1 is out of range: must be >= 0",
        ),
        # a key that has no per-joint value
        "node_only": (
            {"gains": {"j1": {"publish_every": 5}}},
            "error: gains.j1.publish_every: 'publish_every' is not a per-joint gain; allowed keys: ",
        ),
    }
    for name, (extra, line) in cases.items():
        out = _start(tmp_path, name, {"joints": JOINTS, "inertia": 0.0012, **extra})
        assert out.returncode == 2, (name, out.returncode, out.stderr)
        assert "Traceback" not in out.stderr
        errors = [ln for ln in out.stderr.splitlines() if ln.startswith("error:")]
        assert len(errors) == 1 and errors[0].startswith(line), (name, out.stderr)
