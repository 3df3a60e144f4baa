"""Digital Butterworth low-pass filters in second-order sections, and zero-phase filtering.

The band-limited excitations (ABB M19-S paper A.5: white noise through a 4th-order digital
Butterworth low-pass) need only these three functions. They follow ``scipy.signal``'s ``butter``
(``output="sos"``), ``sosfilt`` and ``sosfiltfilt`` step for step (the tests compare them), and exist
because importing ``scipy.signal`` costs about 0.55 s of CPU in every process that builds an
excitation: the experiment CLI, the experiment node and each controller with a random reference.

Design (bilinear transform with pre-warping, ``fs`` = 2 internally):
    analog poles  p_k = -w_a exp(j pi m / (2N)),  m = -N+1, -N+3, ..., N-1,  w_a = 4 tan(pi W_n / 2)
    digital poles z_k = (4 + p_k) / (4 - p_k); every zero at z = -1; gain w_a^N / prod(4 - p_k)
    W_n = cutoff / (fs / 2). One section per conjugate pole pair (``[1, -2 Re z, |z|^2]``), for odd N
    one with the real pole (``[1, -z, 0]``); the zeros paired as ``scipy.signal.zpk2sos`` pairs them,
    the sections nearest the unit circle last, the gain in the first.
Filtering: each section in direct form II transposed,
    y = b0 x + s0;  s0 = b1 x - a1 y + s1;  s1 = b2 x - a2 y.
"""

from __future__ import annotations

import numpy as np


def butter_lowpass_sos(order: int, cutoff: float, fs: float) -> np.ndarray:
    """Second-order sections ``(n, 6)`` of an ``order``-pole low-pass at ``cutoff`` Hz, sampled at
    ``fs`` Hz (0 < cutoff < fs / 2)."""
    order = int(order)
    if order < 1:
        raise ValueError(f"filter order must be a whole number >= 1, not {order}")
    wn = float(cutoff) / (float(fs) / 2.0)
    if not 0.0 < wn < 1.0:
        raise ValueError(f"cutoff must be within (0, fs/2) = (0, {fs / 2:g}) Hz, not {cutoff:g}")
    warped = 2 * 2.0 * np.tan(np.pi * np.float64(wn) / 2.0)
    m = np.arange(-order + 1, order, 2, dtype=np.float64)
    p = warped * -np.exp(1j * np.pi * m / (2 * order))
    k = 1.0 * warped**order
    fs2 = 4.0
    z = (fs2 + p) / (fs2 - p)
    k = k * np.real(1.0 / np.prod(fs2 - p))
    # one section per conjugate pair (its member above the real axis) and one for the real pole of
    # an odd order (with a pole at 0); the zeros (-1, and 0 for an odd order) go to the sections in
    # turn, nearest the unit circle first, each its nearest remaining zero and then the nearest other
    poles = sorted((zk for zk in z if zk.imag >= 0), key=lambda zk: abs(1 - abs(zk)))
    zeros = [-1.0] * order + [0.0] * (order % 2)
    rows = []
    for zk in poles:
        z1 = min(zeros, key=lambda q: abs(q - zk))
        zeros.remove(z1)
        z2 = min(zeros, key=lambda q: abs(q - zk))
        zeros.remove(z2)
        b = [1.0, -(z1 + z2), z1 * z2]
        if zk.imag > 0:
            a = [1.0, -(zk.real + zk.real), zk.real * zk.real + zk.imag * zk.imag]
        else:
            a = [1.0, -zk.real, 0.0]
        rows.append(b + a)
    sos = np.array(rows[::-1], dtype=np.float64)  # nearest the unit circle last
    sos[0, :3] *= k
    return sos


def sosfilt(sos: np.ndarray, x, zi: np.ndarray | None = None) -> np.ndarray:
    """``x`` through the cascade of sections ``sos`` (states ``zi``, shape ``(n, 2)``; zero if None)."""
    y = np.asarray(x, dtype=np.float64).tolist()
    for s, (b0, b1, b2, _, a1, a2) in enumerate(np.asarray(sos, dtype=np.float64).tolist()):
        s0, s1 = (0.0, 0.0) if zi is None else (float(zi[s][0]), float(zi[s][1]))
        for i, xc in enumerate(y):
            yc = b0 * xc + s0
            s0 = b1 * xc - a1 * yc + s1
            s1 = b2 * xc - a2 * yc
            y[i] = yc
    return np.asarray(y, dtype=np.float64)


def _section_zi(b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The state of one section (a0 = 1) in its steady state for a unit step input."""
    i_minus_a = np.eye(2) - np.array([[-a[1], -a[2]], [1.0, 0.0]]).T
    return np.linalg.solve(i_minus_a, b[1:] - a[1:] * b[0])


def sosfilt_zi(sos: np.ndarray) -> np.ndarray:
    """Initial states ``(n, 2)`` of the cascade for a unit step's steady state."""
    zi = np.empty((len(sos), 2))
    scale = 1.0
    for s, row in enumerate(np.asarray(sos, dtype=np.float64)):
        b, a = row[:3], row[3:]
        zi[s] = scale * _section_zi(b, a)
        scale *= np.sum(b) / np.sum(a)
    return zi


def sosfiltfilt(sos: np.ndarray, x) -> np.ndarray:
    """Zero-phase filtering: forward then backward through ``sos``, the ends extended by odd
    reflection over ``3 (2 n + 1 - zero end taps)`` samples and the states started in steady state."""
    sos = np.asarray(sos, dtype=np.float64)
    x = np.asarray(x, dtype=np.float64)
    edge = 3 * (2 * len(sos) + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum())))
    if x.shape[0] <= edge:
        raise ValueError(f"the signal must be longer than {edge} samples (the padding), not {x.shape[0]}")
    ext = np.concatenate((2 * x[0:1] - x[edge:0:-1], x, 2 * x[-1:] - x[-2 : -(edge + 2) : -1]))
    zi = sosfilt_zi(sos)
    y = sosfilt(sos, ext, zi * ext[0])
    y = sosfilt(sos, y[::-1], zi * y[-1])[::-1]
    return y[edge:-edge]
