"""The known truth of the realistic synthetic joint (:mod:`.realistic_joint`): its coefficients and
the equations, written independently of the package's friction classes (an independent check), in
the convention of :mod:`friction_ros.core.friction.joint_load` (REP-103 signs, SI):

    tau      = J a + tau_load(q) + F(v) + k_L |tau_tr| sgn_eps(v) + sgn_eps(v) R(q)
    tau_load = gravity sin(q + gravity_phase) + offset + spring q,   tau_tr = tau_load(q) + J a
    R(q)     = sum_k c_k cos(k w q) + s_k sin(k w q),                w = 2 pi / ripple_period
    F(v)     = sgn_eps(v) (fc + (fs - fc) exp(-|v / vs|^delta)) + fv v     (AI friction chapter eq. 5)
    sgn_eps(v) = clip(v / eps, -1, 1)                                      (ABB M19-S paper A.2.1)
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from friction_ros.core.friction.joint_load import JOINT_LOAD_SCHEMA, JointLoad


@dataclass
class JointTruth:
    """Known truth of a mid-size arm joint behind a 100:1 harmonic drive (module docstring equations).

    Units: J [kg*m^2], gravity = m g l [N*m], gravity_phase [rad], spring [N*m/rad], offset and
    sensor_offset [N*m], fc/fs [N*m], vs [rad/s], delta [-], fv [N*m*s/rad], eps [rad/s],
    load_friction k_L [-], ripple_period [rad] (2 pi / 100: one ripple per wave-generator turn),
    ripple_cos/ripple_sin [N*m] (first harmonic ~6.7 % of fc), torque_noise_std [N*m] (3 % of fc),
    encoder_resolution [rad] (17 bit on the link), velocity_noise_std [rad/s] (the drive's estimate
    from its motor encoder through the 100:1 gear: 2 pi / 2^17 / 100 per count, ~2.4e-4 rad/s per
    count over 2 ms, filtered; as large as eps, so the sign is unsure near reversals), sample_period and
    jitter_std [s], drop_rate [-] (fraction of samples lost), delay [s] (always 0 here).
    ``velocity_estimate``: ``"noisy"`` (true v + white noise) or ``"differentiated"`` (backward
    difference of the logged position over the logged stamps, half a sample late).
    """

    J: float = 0.2
    gravity: float = 12.0
    gravity_phase: float = 0.3
    spring: float = 0.5
    offset: float = 0.4
    sensor_offset: float = 0.2
    fc: float = 2.0
    fs: float = 2.6
    vs: float = 0.03
    delta: float = 2.0
    fv: float = 3.0
    eps: float = 1e-3
    load_friction: float = 0.03
    ripple_period: float = 2.0 * math.pi / 100.0
    ripple_cos: list[float] = field(default_factory=lambda: [0.12, 0.03])
    ripple_sin: list[float] = field(default_factory=lambda: [0.06, -0.02])
    torque_noise_std: float = 0.06
    encoder_resolution: float = 2.0 * math.pi / 2**17
    velocity_noise_std: float = 0.001
    velocity_estimate: str = "noisy"
    sample_period: float = 0.002
    jitter_std: float = 0.00015
    drop_rate: float = 0.001
    delay: float = 0.0

    def __post_init__(self) -> None:
        if len(self.ripple_cos) != len(self.ripple_sin):
            raise ValueError("ripple_cos and ripple_sin must have the same length")
        if self.velocity_estimate not in ("noisy", "differentiated"):
            raise ValueError(
                f"velocity_estimate must be 'noisy' or 'differentiated', not {self.velocity_estimate!r}"
            )
        if self.delay != 0.0:
            raise ValueError("delay must be 0 (the generator logs every quantity at its true instant)")

    def sgn(self, v):
        """sgn_eps(v) = clip(v / eps, -1, 1)."""
        return np.clip(np.asarray(v, dtype=float) / self.eps, -1.0, 1.0)

    def friction_map(self, v):
        """Static Stribeck map F(v) = sgn_eps(v) (fc + (fs - fc) exp(-|v/vs|^delta)) + fv v [N*m]."""
        v = np.asarray(v, dtype=float)
        return self.sgn(v) * (
            self.fc + (self.fs - self.fc) * np.exp(-(np.abs(v / self.vs) ** self.delta))
        ) + (self.fv * v)

    def load_torque(self, q):
        """tau_load(q) = gravity sin(q + gravity_phase) + offset + spring q [N*m]."""
        q = np.asarray(q, dtype=float)
        return self.gravity * np.sin(q + self.gravity_phase) + self.offset + self.spring * q

    def ripple(self, q):
        """R(q) = sum_k c_k cos(k w q) + s_k sin(k w q), w = 2 pi / ripple_period [N*m]."""
        q = np.asarray(q, dtype=float)
        w = 2.0 * math.pi / self.ripple_period
        out = np.zeros_like(q)
        for k, (c, s) in enumerate(zip(self.ripple_cos, self.ripple_sin), start=1):
            out = out + c * np.cos(k * w * q) + s * np.sin(k * w * q)
        return out

    def friction(self, v, q, a):
        """All friction: F(v) + sgn_eps(v) (k_L |tau_load(q) + J a| + R(q)) [N*m]."""
        tr = self.load_torque(q) + self.J * np.asarray(a, dtype=float)
        return self.friction_map(v) + self.sgn(v) * (self.load_friction * np.abs(tr) + self.ripple(q))

    def torque(self, q, v, a):
        """True joint torque J a + tau_load(q) + friction (no sensor offset, no noise) [N*m]."""
        return self.J * np.asarray(a, dtype=float) + self.load_torque(q) + self.friction(v, q, a)

    def load_config(self) -> dict:
        """The ``load`` section of :class:`~friction_ros.core.friction.joint_load.JointLoad` this truth holds."""
        return JointLoad(**{k: getattr(self, k) for k in JOINT_LOAD_SCHEMA.items}).to_config()

    def to_dict(self) -> dict:
        """Plain dict (floats, lists, str) for reports and YAML, with the equations as text."""
        d = {k: (list(map(float, v)) if isinstance(v, list) else v) for k, v in asdict(self).items()}
        d = {k: (float(v) if isinstance(v, int | float) else v) for k, v in d.items()}
        d["equations"] = (
            "tau = J a + tau_load(q) + F(v) + k_L |tau_load(q) + J a| sgn_eps(v) + sgn_eps(v) R(q); "
            "tau_load = gravity sin(q + gravity_phase) + offset + spring q; "
            "R(q) = sum_k c_k cos(k w q) + s_k sin(k w q), w = 2 pi / ripple_period; "
            "F(v) = sgn_eps(v) (fc + (fs - fc) exp(-|v/vs|^delta)) + fv v (AI friction chapter eq. 5); "
            "sgn_eps(v) = clip(v / eps, -1, 1); effort = tau + sensor_offset + noise"
        )
        return d
