"""The middleware's own floor for bench/manipulator.py: the arm's topology with no work in it.

One process (pinned to core 0, SCHED_FIFO 80, one executor, as ``composed_fifo``) holds a stand-in
plant that publishes a 7-joint sensor_msgs/JointState at 1 kHz deadlines (the plant's deadline
loop) and a stand-in controller that answers each state with a 7-joint effort command; a second
process on core 1 subscribes to the states as the estimator does. No physics, no control law, no
estimator: what is left is rclpy, the executor and Fast DDS. Figures with the plant's definitions:

* ``missed_percent``: ticks at which the answer to the previous state had not arrived;
* ``latency_p50_ms`` / ``latency_p99_ms``: command arrival minus the stamp of the state it answers;
* ``cpu_percent``: CPU of the composed process (% of one core).

    python bench/_middleware_floor.py run SECONDS     # prints one JSON line
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

JOINTS = [f"joint{i}" for i in range(1, 8)]


def _listener(seconds: float) -> None:
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import JointState

    from friction_ros.nodes.qos import STATE_QOS
    from friction_ros.nodes.runtime import make_executor, set_cpu_affinity

    rclpy.init()
    node = Node("floor_listener")
    node.create_subscription(JointState, "joint_states", lambda data: None, STATE_QOS, raw=True)
    set_cpu_affinity(1)
    ex = make_executor()
    ex.add_node(node)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        ex.spin_once(timeout_sec=0.05)


def _composed(seconds: float, warmup: float) -> dict:
    import rclpy
    from rclpy.node import Node
    from sensor_msgs.msg import JointState

    from friction_ros.core.wire import JointStateDecoder, JointStateEncoder
    from friction_ros.nodes.loops import DeadlineLoop, LatencyHistogram
    from friction_ros.nodes.qos import COMMAND_QOS, STATE_QOS
    from friction_ros.nodes.runtime import make_executor, set_cpu_affinity, set_realtime_priority

    rclpy.init()
    plant, ctrl = Node("floor_plant"), Node("floor_controller")
    state_enc, cmd_enc = JointStateEncoder(JOINTS), JointStateEncoder(JOINTS, ("effort",))
    decoder = JointStateDecoder()
    states = plant.create_publisher(JointState, "joint_states", STATE_QOS)
    commands = ctrl.create_publisher(JointState, "joint_commands", COMMAND_QOS)
    s = {"published": 0, "answered": 0, "missed": 0, "ticks": 0, "lat": LatencyHistogram()}
    zeros = [0.0] * (3 * len(JOINTS))
    efforts = [0.0] * len(JOINTS)

    def on_state(data: bytes) -> None:
        m = decoder.decode(data)
        commands.publish(cmd_enc.pack(m.sec, m.nanosec, *efforts))

    def on_command(data: bytes) -> None:
        m = decoder.decode(data)
        s["answered"] = m.stamp_ns
        s["lat"].add((time.time_ns() - m.stamp_ns) * 1e-9)

    def tick() -> None:
        if s["published"]:
            s["ticks"] += 1
            s["missed"] += s["answered"] != s["published"]
        now = time.time_ns()
        s["published"] = now
        states.publish(state_enc.pack(*divmod(now, 1_000_000_000), *zeros))

    ctrl.create_subscription(JointState, "joint_states", on_state, STATE_QOS, raw=True)
    plant.create_subscription(JointState, "joint_commands", on_command, COMMAND_QOS, raw=True)
    set_cpu_affinity(0)
    set_realtime_priority(80)
    ex = make_executor()
    ex.add_node(plant)
    ex.add_node(ctrl)
    loop = DeadlineLoop(1e-3, tick)
    t_measure = time.monotonic() + warmup
    end = t_measure + seconds
    cpu0 = None
    while time.monotonic() < end:
        if cpu0 is None and time.monotonic() >= t_measure:
            cpu0, wall0 = time.process_time(), time.monotonic()
            s.update(missed=0, ticks=0, lat=LatencyHistogram())
        loop.run_once(ex)
    cpu = 100.0 * (time.process_time() - cpu0) / (time.monotonic() - wall0)
    return {
        "seconds": seconds,
        "cycles": s["ticks"],
        "missed_percent": 100.0 * s["missed"] / max(s["ticks"], 1),
        "latency_p50_ms": 1e3 * s["lat"].percentile(50),
        "latency_p99_ms": 1e3 * s["lat"].percentile(99),
        "cpu_percent": cpu,
    }


def measure(seconds: float, warmup: float = 4.0) -> dict:
    """Run the floor (listener process + composed process) and return its figures."""
    env = dict(os.environ)
    listener = subprocess.Popen(
        [sys.executable, __file__, "listen", str(seconds + warmup + 4.0)], env=env, stderr=subprocess.DEVNULL
    )
    try:
        res = subprocess.run(
            [sys.executable, __file__, "run", str(seconds), str(warmup)],
            env=env,
            capture_output=True,
            text=True,
            timeout=seconds + warmup + 60,
        )
    finally:
        listener.terminate()
        listener.wait(10)
    if res.returncode != 0:
        return {"error": (res.stderr.strip().splitlines() or ["failed"])[-1]}
    return json.loads(res.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    role, secs = sys.argv[1], float(sys.argv[2])
    if role == "listen":
        _listener(secs)
    else:
        print(json.dumps(_composed(secs, float(sys.argv[3]) if len(sys.argv) > 3 else 4.0)), flush=True)
