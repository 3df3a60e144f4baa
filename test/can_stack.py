"""Test helper process: drive emulator thread + drive_interface node on one python-can virtual bus.

Usage: python test/can_stack.py --channel CH --log FILE [--emulator JSON] [--silent-after S]
       [--error-after S] -- <ROS args for drive_interface>

SIGUSR1 makes the drive go quiet; SIGUSR2 starts a spoofer (:func:`spoof`, ODrive) on a fourth bus.

python-can's virtual bus only connects buses of one process, so the emulator and the node share
this process; the test talks to the node over DDS (joint_commands / joint_states) and reads the bus
log written by a third bus (sniffer) on the same channel.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import struct
import sys
import threading
import time

import can
from can_support import make_plant

from friction_ros.core.can import odrive as od
from friction_ros.core.can.emulator import DriveEmulator, EmulatorConfig
from friction_ros.core.can.joint import JointConversion
from friction_ros.core.can.mit import MitRanges
from friction_ros.nodes import drive_interface


class Sniffer(can.Listener):
    def __init__(self, path):
        self.fh = open(path, "w")  # noqa: SIM115

    def on_message_received(self, msg):
        self.fh.write(
            f"{msg.timestamp:.6f},{msg.arbitration_id:x},{int(msg.is_remote_frame)},{bytes(msg.data).hex()}\n"
        )

    def stop(self):
        self.fh.close()


def spoof(bus, emu, node_id, log, isolated=20, burst=12):
    """Absurd encoder frames of drive ``node_id``: ``isolated`` single frames 20 ms apart among the
    drive's own, then (the drive drowned out) ``burst`` in a row; NaN, 3.2e33 rad and a 30 rad jump
    from the drive's position, in turn. Each frame sent is written to ``log`` (time, position)."""
    enc_id = (node_id << 5) | od.Cmd.GET_ENCODER_ESTIMATES

    def send(k):
        pos = (math.nan, 3.2e33, emu.motor_position + 30.0)[k % 3]
        data = struct.pack("<ff", pos / od.TWO_PI, 0.0)
        bus.send(can.Message(arbitration_id=enc_id, data=data, is_extended_id=False))
        log.write(f"{time.time():.6f},{pos}\n")
        log.flush()

    for k in range(isolated):
        send(k)
        time.sleep(0.02)
    emu.set_silent()
    time.sleep(0.01)  # the drive's frames in flight are through
    for k in range(burst):
        send(k)
    time.sleep(0.005)
    emu.set_silent(False)  # sane frames return
    log.write("done\n")
    log.flush()


def main():
    argv = sys.argv[1:]
    ros = argv[argv.index("--") + 1 :] if "--" in argv else []
    own = argv[: argv.index("--")] if "--" in argv else argv
    ap = argparse.ArgumentParser()
    ap.add_argument("--channel", required=True)
    ap.add_argument("--log", required=True)
    ap.add_argument("--emulator", default="{}")
    ap.add_argument("--silent-after", type=float, default=None)
    ap.add_argument("--error-after", type=float, default=None)
    a = ap.parse_args(own)
    emu_kw = json.loads(a.emulator)
    plant, conv = make_plant(emu_kw.pop("preset", "abb_m19s"))
    emu_kw["conversion"] = JointConversion(**{**conv.__dict__, **emu_kw.get("conversion", {})})
    if "mit_ranges" in emu_kw:
        emu_kw["mit_ranges"] = MitRanges(**emu_kw["mit_ranges"])
    cfg = EmulatorConfig(**emu_kw)
    emu_bus = can.Bus(interface="virtual", channel=a.channel)
    sniff_bus = can.Bus(interface="virtual", channel=a.channel)
    sniffer = Sniffer(a.log)
    notifier = can.Notifier(sniff_bus, [sniffer], timeout=0.05)
    emu = DriveEmulator(emu_bus, plant, cfg)
    emu.start()
    timers = []
    if a.silent_after is not None:
        timers.append(threading.Timer(a.silent_after, emu.set_silent))
    if a.error_after is not None:
        timers.append(threading.Timer(a.error_after, emu.inject_axis_error))
    signal.signal(signal.SIGUSR1, lambda *_: emu.set_silent())  # the test makes the drive go quiet
    spoof_bus = can.Bus(interface="virtual", channel=a.channel)
    spoof_log = open(a.log + ".spoof", "w")  # noqa: SIM115
    node_id = emu_kw.get("node_id", 0)
    signal.signal(
        signal.SIGUSR2,
        lambda *_: threading.Thread(
            target=spoof, args=(spoof_bus, emu, node_id, spoof_log), daemon=True
        ).start(),
    )
    for t in timers:
        t.daemon = True
        t.start()
    try:
        rc = drive_interface.main(["drive_interface", "--ros-args", *ros])
    finally:
        time.sleep(0.05)
        emu.stop()
        notifier.stop()
        sniffer.stop()
        emu_bus.shutdown()
        sniff_bus.shutdown()
        spoof_bus.shutdown()
        spoof_log.close()
    sys.exit(rc)


if __name__ == "__main__":
    main()
