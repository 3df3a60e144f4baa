"""The subscription guard of every node (friction_ros.nodes.safe_subscription) on a real rclpy node,
its callback driven directly with payloads DDS may not deliver (empty) and with callbacks that
raise: nothing leaves the guard, everything is counted, logs are limited to one a second per kind
and name the topic, the reason and the count (a programming error keeps its text and location)."""

from __future__ import annotations

import struct

import pytest

pytestmark = pytest.mark.ros


@pytest.fixture(scope="module")
def node():
    import rclpy

    ctx = rclpy.context.Context()
    rclpy.init(context=ctx)
    n = rclpy.create_node("guard_test", context=ctx)
    yield n
    n.destroy_node()
    rclpy.try_shutdown(context=ctx)


def test_undecodable_payloads_are_counted_and_logged_once_a_second(node, capfd):
    from sensor_msgs.msg import JointState

    from friction_ros.core.wire import JointStateDecoder, JointStateEncoder
    from friction_ros.nodes.safe_subscription import BYTES, MESSAGE, safe_subscription

    got = []
    typed = safe_subscription(node, JointState, "typed_states", got.append, 10, decode=MESSAGE)
    dec = JointStateDecoder()
    raw = safe_subscription(
        node, JointState, "raw_states", lambda d: got.append(dec.decode(d)), 10, decode=BYTES
    )
    good = JointStateEncoder(["j"]).pack_ns(5, 1.0, 2.0, 3.0)
    for guard in (typed, raw):
        for data in (
            b"",
            b"\x00",
            b"\x00\x01\x00\x00" + b"\xff" * 40,
            good[: len(good) // 2],
            b"\x00\x01\x00\x00" + b"\x7f" * (1 << 20),
        ):
            guard.subscription.callback(data)  # never raises
        guard.subscription.callback(good)
    assert typed.undecodable == raw.undecodable == 5
    assert typed.failed == raw.failed == 0
    assert [list(m.position) for m in got] == [[1.0], [1.0]]  # the valid message still goes through
    err = capfd.readouterr().err
    for topic in ("/typed_states", "/raw_states"):
        lines = [ln for ln in err.splitlines() if f"{topic}: ignored a message that does not decode" in ln]
        assert len(lines) == 1 and "[WARN]" in lines[0], err  # once a second
        assert "1 undecodable message(s) so far" in lines[0]
    assert "shorter than the 4-byte CDR header" in err  # the project codec's reason
    assert "failed to deserialize ROS message" in err  # rclpy's reason


def test_a_failing_callback_is_counted_and_logged_with_its_text_and_location(node, capfd, monkeypatch):
    from sensor_msgs.msg import JointState

    from friction_ros.core.wire import JointStateEncoder
    from friction_ros.nodes import safe_subscription as ss

    calls = []

    def broken(msg, info):  # a two-parameter callback also gets the message info
        calls.append(info)
        return 1 / len(calls[5:])

    guard = ss.safe_subscription(node, JointState, "broken", broken, 10)
    good = JointStateEncoder(["j"]).pack_ns(5, 1.0, 2.0, 3.0)
    info = {"source_timestamp": 1}
    for _ in range(3):
        guard.subscription.callback(good, info)
    assert guard.failed == 3 and guard.undecodable == 0 and calls == [info] * 3
    monkeypatch.setattr(ss.time, "monotonic", lambda: 1e9)  # a second later: the next one is logged
    guard.subscription.callback(good, info)
    err = [ln for ln in capfd.readouterr().err.splitlines() if "/broken:" in ln]
    assert len(err) == 2 and all("[ERROR]" in ln for ln in err), err
    assert "ZeroDivisionError: division by zero at test_safe_subscription.py:" in err[0]
    assert "in broken" in err[0] and "1 message(s) failed so far" in err[0]
    assert "4 message(s) failed so far, 2 more since the last report" in err[1]


def test_stop_requests_and_struct_errors(node):
    from sensor_msgs.msg import JointState

    from friction_ros.nodes.safe_subscription import BYTES, safe_subscription
    from friction_ros.nodes.stopping import StopRequested

    def stop(_data):
        raise StopRequested

    def bad_struct(_data):
        struct.unpack("<d", b"")

    guard = safe_subscription(node, JointState, "stop", stop, 10, decode=BYTES)
    with pytest.raises(StopRequested):  # SIGINT/SIGTERM's interruption passes through the guard
        guard.subscription.callback(b"x")
    guard = safe_subscription(node, JointState, "structs", bad_struct, 10, decode=BYTES)
    guard.subscription.callback(b"x")
    assert guard.undecodable == 1 and guard.failed == 0
