"""Stiction handling: Karnopp zero-velocity band and AI friction chapter's GKF switching rule.

Both carry a Stribeck sliding map (AI friction chapter eq. (5)) and add ``torque_stick(v, applied)``, the friction
torque given the net non-friction torque ``applied`` acting on the body. The plant uses these rules
(and the GKF rule for every static model at exact rest).
"""

from __future__ import annotations

import numpy as np

from friction_ros.core.config import Field

from . import _kernels
from .static import _DELTA, _FC, _FS, _FV, _VS, Stribeck


class GKF(Stribeck):
    """General kinetic friction switching rule (AI friction chapter eq. (4), standard reading; GA friction thesis 2002 eq. (5)):

    F = F(v) (Stribeck map) if v != 0; F = F_e if v = 0 and |F_e| < Fs; F = Fs sgn(F_e) otherwise.
    """

    name = "gkf"
    KIND = _kernels.K_GKF
    COEFS = (_FC, _FS, _VS, _DELTA, _FV)
    band = 0.0

    def torque_stick(self, v, applied):
        """Friction torque given velocity ``v`` and the applied (non-friction) torque ``applied``."""
        v = np.asarray(v, dtype=float)
        applied = np.asarray(applied, dtype=float)
        fs = self._c["fs"]
        inband = np.abs(v) <= self.band if self.band > 0 else v == 0
        out = np.where(inband, np.clip(applied, -fs, fs), self.steady_state(v))
        return float(out) if out.ndim == 0 else out

    def sticks(self, v, applied):
        """True where the body is held at rest (inside the band and |applied| < Fs)."""
        v = np.asarray(v, dtype=float)
        inband = np.abs(v) <= self.band if self.band > 0 else v == 0
        return inband & (np.abs(applied) < self._c["fs"])

    def breakaway(self, direction: float = 1.0) -> float:
        return self._c["fs"]


class Karnopp(GKF):
    """Karnopp model (Karnopp 1985): inside the zero-velocity band |v| < dv

    F = max(-Fs, min(Fs, F_e)) (the body sticks while |F_e| < Fs and is released above), outside the
    band the Stribeck sliding map of AI friction chapter eq. (5).
    """

    name = "karnopp"
    KIND = _kernels.K_KARNOPP
    COEFS = (
        *Stribeck.COEFS,
        Field(
            "dv",
            lo=0.0,
            lo_open=True,
            unit="rad/s",
            doc="half width of the zero-velocity band |v| < dv where the body sticks (Karnopp 1985)",
        ),
    )

    @property
    def band(self) -> float:  # type: ignore[override]
        return self._c["dv"]

    def _kernel_params(self):
        c = self._c
        return [c["fc"], c["fs"], c["vs"], c["delta"], c["fv"], c["dv"]]
