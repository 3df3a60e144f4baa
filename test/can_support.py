"""Shared helpers of the CAN tests: a plant for the emulator, bus-log parsing (not collected by pytest)."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class Meas:
    position: float
    velocity: float
    effort: float
    motor_current: float
    time: float


class StandInPlant:
    """Minimal stand-in: rigid inertia with viscous + smoothed Coulomb friction (torque input)."""

    def __init__(self, inertia=0.01, viscous=0.05, coulomb=0.05, position=0.0):
        self.J, self.b, self.fc = inertia, viscous, coulomb
        self.q, self.v, self.t = position, 0.0, 0.0

    def reset(self, position=0.0):
        self.q, self.v, self.t = position, 0.0, 0.0

    def step(self, command, dt):
        friction = self.b * self.v + self.fc * math.tanh(self.v / 1e-3)
        self.v += (command - friction) / self.J * dt
        self.q += self.v * dt
        self.t += dt
        return Meas(self.q, self.v, command, 0.0, self.t)


def make_plant(preset: str = "abb_m19s"):
    """The project's plant (GearheadServoPlant preset in torque actuation) + its JointConversion."""
    from friction_ros.core.can.emulator import plant_from_preset

    return plant_from_preset(preset)


def read_bus_log(path):
    """Rows of the sniffer log: (time.time() stamp, arbitration id, is_remote, data bytes)."""
    rows = []
    with open(path) as fh:
        for line in fh:
            t, arb, rtr, data = line.rstrip("\n").split(",")
            rows.append((float(t), int(arb, 16), rtr == "1", bytes.fromhex(data)))
    return rows
