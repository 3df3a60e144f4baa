"""Spoofed encoder frames on a real python-can virtual bus never reach joint_states.

test/can_stack.py runs the drive emulator, the drive_interface node and (on SIGUSR2) a spoofer on
one virtual bus; this process is a PD controller over DDS. The spoofer sends NaN, 3.2e33 rad and a
30 rad jump as the drive's encoder frames: first single frames among the drive's own (each dropped
and counted, the drive keeps running), then a burst while the drive is drowned out (the run latches
the telemetry_implausible fault: zero torque, idle), then the drive's sane frames return (the
condition clears, the fault stays latched) and ``~/enable`` resets it.
"""

from __future__ import annotations

import math
import signal
import time

import pytest
from can_support import read_bus_log
from diagnostic_msgs.msg import DiagnosticArray
from std_srvs.srv import SetBool
from test_can_e2e import PdController, start_stack, stop, torque_frames

from friction_ros.core.can import odrive as od
from friction_ros.core.can.faults import FAULT_TELEMETRY_IMPLAUSIBLE
from friction_ros.nodes.qos import STATE_QOS

pytestmark = [pytest.mark.ros, pytest.mark.realtime, pytest.mark.flaky(reruns=2)]

REJECT_RUN = 5


def wait_for(cond, timeout, step=0.02):
    end = time.time() + timeout
    while time.time() < end:
        if cond():
            return True
        time.sleep(step)
    return cond()


def test_spoofed_encoder_frames_are_dropped_counted_and_a_run_latches_until_enable(tmp_path):
    proc, log = start_stack(tmp_path, params=[f"telemetry_gate.reject_run:={REJECT_RUN}"])
    pd = PdController()
    diags: list[dict] = []
    pd.node.create_subscription(
        DiagnosticArray,
        "diagnostics",
        lambda m: diags.extend({kv.key: kv.value for kv in s.values} for s in m.status),
        STATE_QOS,
    )
    enable = pd.node.create_client(SetBool, "/drive_interface/enable")
    try:
        pd.ref = lambda t: (0.3, 0.0)
        pd.wait_started()
        time.sleep(0.6)
        assert diags and diags[-1]["telemetry_rejected"] == "0"
        t_spoof = time.time()
        proc.send_signal(signal.SIGUSR2)
        spoof_log = tmp_path / "bus.csv.spoof"
        assert wait_for(lambda: spoof_log.exists() and "done" in spoof_log.read_text(), 10.0)

        def latched():
            recent = pd.drive_states[-20:]
            return any(s.fault_flags & FAULT_TELEMETRY_IMPLAUSIBLE and not s.enabled for s in recent)

        assert wait_for(latched, 2.0), "the run of spoofed frames did not latch the fault"
        n_js = len(pd.samples)
        assert wait_for(lambda: len(pd.samples) > n_js + 100, 3.0), "joint_states did not resume"
        t_before_enable = time.time()
        fut = enable.call_async(SetBool.Request(data=True))
        assert wait_for(fut.done, 5.0) and fut.result().success

        def enabled():
            recent = pd.drive_states[-5:]
            return any(s.enabled and not s.fault_flags & FAULT_TELEMETRY_IMPLAUSIBLE for s in recent)

        assert wait_for(enabled, 3.0), "~/enable did not reset the fault"
        time.sleep(0.6)  # a diagnostics period (0.5 s) after
        _, out = stop(proc)
    finally:
        pd.close()
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, out
    spoofed = [ln.split(",") for ln in (tmp_path / "bus.csv.spoof").read_text().splitlines() if "," in ln]
    assert len(spoofed) == 32
    # the bus carried them (the sniffer saw every spoofed frame) ...
    enc_id = (1 << 5) | od.Cmd.GET_ENCODER_ESTIMATES
    on_bus = [d for t, arb, _, d in read_bus_log(log) if arb == enc_id and t >= t_spoof]
    turns = [od._F2.unpack_from(d)[0] for d in on_bus]
    assert sum(math.isnan(x) for x in turns) == 11 and sum(x > 1e32 for x in turns) == 11
    # ... but joint_states never: every position finite and near the held 0.3 rad
    qs = [q for ts, _, q in pd.samples if ts >= t_spoof]
    assert qs and all(math.isfinite(q) and abs(q - 0.3) < 0.2 for q in qs), (min(qs), max(qs))
    # counted: every spoofed frame rejected (NaN: undecodable, 3.2e33: out_of_range, +30 rad: jump)
    last = diags[-1]
    assert int(last["telemetry_rejected"]) == 32, last
    assert (last["telemetry_rejected.undecodable"], last["telemetry_rejected.out_of_range"]) == ("11", "11")
    assert last["telemetry_rejected.jump"] == "10"
    # the drive ran on through the single frames (torque sent), was idled by the run, and runs again
    torques = torque_frames(read_bus_log(log))
    assert any(v != 0.0 for t, v in torques if t > t_before_enable + 0.5), "no torque after ~/enable"
    assert "telemetry_implausible: " in out and "drive disabled (zero torque, idle) until ~/enable" in out
    assert (
        "telemetry_implausible cleared after" in out
        and "telemetry_implausible fault reset by ~/enable" in out
    )
    assert "rejected telemetry of drive id 1 [" in out
