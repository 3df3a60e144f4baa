"""friction-doctor: check that this installation works end to end.

Checks, in order: the pure core imports without rclpy; rclpy and the friction_msgs interfaces
import; one message crosses from a separate publisher process to this process over DDS.
Exit code 0 when everything passes; otherwise the failing check is named.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time

_PUBLISHER = """
import sys, time, rclpy
from friction_msgs.msg import ControllerState
rclpy.init()
node = rclpy.create_node('friction_doctor_pub')
pub = node.create_publisher(ControllerState, 'friction_doctor', 10)
end = time.monotonic() + float(sys.argv[1])
try:
    while rclpy.ok() and time.monotonic() < end:
        pub.publish(ControllerState(joint_name='doctor', mode='check', command=1.25))
        time.sleep(0.05)
except KeyboardInterrupt:
    pass
finally:
    node.destroy_node()
    rclpy.try_shutdown()

"""


def _check(label: str, ok: bool, detail: str = "") -> bool:
    print(f"  [{'ok' if ok else 'FAIL'}] {label}{(': ' + detail) if detail else ''}")
    return ok


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        allow_abbrev=False, prog="friction-doctor", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--timeout", type=float, default=10.0, help="seconds to wait for DDS (default 10)")
    args = parser.parse_args(argv)
    print("friction-doctor: checking the installation")
    import friction_ros.core  # noqa: F401

    if not _check("pure core imports without rclpy", "rclpy" not in sys.modules):
        return 1
    try:
        import rclpy
        from friction_msgs.msg import ControllerState
    except ImportError as exc:
        _check("rclpy and friction_msgs import", False, f"{exc} (run ./scripts/bootstrap.sh)")
        return 1
    _check("rclpy and friction_msgs import", True)

    proc = subprocess.Popen([sys.executable, "-c", _PUBLISHER, str(args.timeout)])
    rclpy.init()
    node = rclpy.create_node("friction_doctor_sub")
    got: list[ControllerState] = []
    node.create_subscription(ControllerState, "friction_doctor", got.append, 10)
    deadline = time.monotonic() + args.timeout
    try:
        while not got and time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
    finally:
        node.destroy_node()
        rclpy.shutdown()
        proc.terminate()
        proc.wait(timeout=5)
    ok = bool(got) and got[0].joint_name == "doctor" and got[0].command == 1.25
    _check(
        "friction_msgs/ControllerState crosses processes over DDS",
        ok,
        "" if ok else f"nothing received within {args.timeout:g} s",
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
