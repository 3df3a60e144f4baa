"""The excitations' Butterworth filters against scipy.signal (the reference implementation), and the
processes that build an excitation do not import scipy.signal (0.55 s of CPU each)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import scipy.signal as sg

from friction_ros.core.experiment.butterworth import butter_lowpass_sos, sosfilt, sosfiltfilt


@pytest.mark.parametrize("fs", [1000.0, 700.0, 4.0])
@pytest.mark.parametrize("order", range(1, 11))
def test_sections_are_scipys_at_every_order_and_cutoff_over_decades(order, fs):
    for cutoff in np.geomspace(1e-6 * fs, 0.49999 * fs, 40):
        ours, ref = butter_lowpass_sos(order, cutoff, fs), sg.butter(order, cutoff, fs=fs, output="sos")
        assert ours.shape == ref.shape == ((order + 1) // 2, 6)
        np.testing.assert_allclose(ours, ref, rtol=1e-13, atol=1e-300, err_msg=f"cutoff {cutoff:g}")


@pytest.mark.parametrize("order,cutoff", [(1, 5.0), (3, 10.0), (4, 1.0), (4, 4.0), (8, 100.0), (10, 450.0)])
def test_filtering_is_scipys(order, cutoff):
    x = np.random.default_rng(order).standard_normal(5000)
    sos = sg.butter(order, cutoff, fs=1000.0, output="sos")
    scale = np.max(np.abs(sg.sosfiltfilt(sos, x)))
    np.testing.assert_allclose(sosfiltfilt(sos, x), sg.sosfiltfilt(sos, x), rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(sosfilt(sos, x), sg.sosfilt(sos, x), rtol=0, atol=1e-12 * scale)
    zi = np.array([[0.3, -0.1]] * len(sos))
    np.testing.assert_allclose(sosfilt(sos, x, zi), sg.sosfilt(sos, x, zi=zi)[0], rtol=0, atol=1e-12 * scale)


def test_a_low_pass_passes_a_slow_sine_and_stops_a_fast_one():
    t = np.arange(20000) / 1000.0
    sos = butter_lowpass_sos(4, 4.0, 1000.0)
    slow, fast = np.sin(2 * np.pi * 0.5 * t), np.sin(2 * np.pi * 40.0 * t)
    assert np.max(np.abs(sosfiltfilt(sos, slow) - slow)[2000:-2000]) < 1e-3  # zero phase, unit gain
    assert np.max(np.abs(sosfiltfilt(sos, fast))[2000:-2000]) < 1e-7  # 2 x 80 dB down a decade up


def test_bad_designs_are_refused_with_the_allowed_range():
    with pytest.raises(ValueError, match=r"within \(0, fs/2\)"):
        butter_lowpass_sos(4, 500.0, 1000.0)
    with pytest.raises(ValueError, match="order must be"):
        butter_lowpass_sos(0, 1.0, 1000.0)
    with pytest.raises(ValueError, match="longer than 15 samples"):
        sosfiltfilt(butter_lowpass_sos(4, 1.0, 1000.0), np.ones(15))


def test_building_the_excitations_does_not_import_scipy_signal():
    code = (
        "import sys\n"
        "import friction_ros.nodes.identification_experiment, friction_ros.nodes.compensating_controller\n"
        "import friction_ros.cli.experiment\n"
        "from friction_ros.core.experiment.excitation import ExcitationProgram\n"
        "from friction_ros.core.experiment.references import reference_from_config\n"
        "p = ExcitationProgram({'profile': 'quick'})\n"
        "assert any(type(s).__name__ == 'VelocityProfile' for s in p.segments)\n"
        "reference_from_config({'type': 'band_limited_random', 'amplitude': 0.1, 'cutoff': 1.0, 'duration': 4.0})\n"
        "print('scipy.signal' in sys.modules)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "False"
