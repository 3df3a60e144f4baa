"""A friction model defined outside the package, end to end through the fit-model plugin.

The toy model is a smooth Coulomb + viscous map (tanh instead of sgn, a common compensation form):

    F(v) = fc tanh(v / vt) + fv v

It is written here, in the test module, as two small classes: the friction library model (what the
plant and the controller evaluate) and its :class:`~friction_ros.core.identification.fit.fit_model.FitModel`
(what the fitter searches and exports), and registered with one call. Then:

* friction-fit (the CLI entry) fits it to a synthetic log of a joint whose friction *is* that map
  (J a + F(v) + noise) and recovers the coefficients;
* the parameter file it writes names the model, and the compensating controller built from that
  file drives the project's plant (which simulates the toy friction from its table) in the closed
  loop with a lower tracking error than the same loop without compensation.
"""

from __future__ import annotations

import contextlib
import inspect
import io
import json

import numpy as np
import pytest
import yaml

from friction_ros.core.config import Field
from friction_ros.core.friction import StaticModel, make_model
from friction_ros.core.identification.fit.fit_model import Coef, FitModel, register_fit_model
from friction_ros.core.identification.fit.fit_registry import fit_model
from friction_ros.core.synthetic.logs.tables import GauntletLog, scaled_sines

TRUTH = {"fc": 0.5, "vt": 0.05, "fv": 0.1}  # [N*m], [rad/s], [N*m*s/rad]
J = 0.01  # [kg*m^2]


# ---------------------------------------------------------------------------- the toy model (one file)
class TanhCoulomb(StaticModel):
    """F = fc tanh(v / vt) + fv v."""

    name = "tanh_coulomb"
    COEFS = (
        Field("fc", 0.0, "Coulomb level", lo=0.0, unit="N*m"),
        Field("vt", 0.01, "velocity of the tanh transition", lo=0.0, lo_open=True, unit="rad/s"),
        Field("fv", 0.0, "viscous coefficient", lo=0.0, unit="N*m*s/rad"),
    )

    def _steady(self, v):
        c = self._c
        return c["fc"] * np.tanh(v / c["vt"]) + c["fv"] * v


class TanhCoulombFit(FitModel):
    """Fit: theta = [vt] (log search, a velocity: scales with the log's speeds), beta = [fc] (+ fv)."""

    family = help = "tanh_coulomb"

    def nonlinear(self):
        return [Coef("vt", 1e-4, 1.0, log=True, power=1)]

    def linear(self):
        return ["fc"]

    def features(self, theta, v, dt, eps):
        return np.tanh(v / theta[0])[:, None]

    def coefficients(self, theta, lin, fv):
        return {"fc": lin["fc"], "vt": float(theta[0]), "fv": fv}

    def library_config(self, c, eps=0.0, per_direction=None):
        return {"model": "tanh_coulomb", "fc": c["fc"], "vt": c["vt"], "fv": c["fv"]}

    def steady_state(self, c, v, eps):
        return c["fc"] * np.tanh(v / c["vt"]) + c["fv"] * v


# ---------------------------------------------------------------------------- end of the toy model


@pytest.fixture(autouse=True, scope="module")
def _registered():
    """Register the toy for this module's tests (one call, as a user's plugin module does at import)
    and take it out again: the other test modules see the built-in models only."""
    from friction_ros.core.friction import catalog, registry
    from friction_ros.core.identification.fit import fit_model as fit_model_module

    register_fit_model(TanhCoulombFit, library_class=TanhCoulomb)
    yield
    fit_model_module._REGISTRY.pop(TanhCoulombFit.family, None)
    registry.MODEL_CLASSES.pop(TanhCoulomb.name, None)
    catalog.BASE_MODEL_CLASSES.pop(TanhCoulomb.name, None)


def _log(seed: int = 0, seconds: float = 20.0) -> GauntletLog:
    """Inverse dynamics of the toy joint on a multisine (|v| <= 1 rad/s, 0.1-2 Hz), 1 kHz, with
    +-2 mN*m torque noise and +-1 mrad/s velocity noise."""
    rng = np.random.default_rng(seed)
    dt = 1e-3
    t = np.arange(int(round(seconds / dt))) * dt
    q, v, a, _ = scaled_sines(rng, t, 0.1, 2.0, 1.0, 1.0, n=6)
    tau = J * a + make_model("tanh_coulomb", **TRUTH).torque(v)
    cols = {
        "time": t,
        "position": q,
        "velocity": v + 1e-3 * rng.standard_normal(t.size),
        "effort": tau + 2e-3 * rng.standard_normal(t.size),
    }
    units = {"time": "s", "position": "rad", "velocity": "rad/s", "effort": "N*m"}
    return GauntletLog("tanh_joint", "toy tanh Coulomb + viscous joint", cols, units, dict(TRUTH))


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    from friction_ros.cli.fit import main

    d = tmp_path_factory.mktemp("plugin")
    csv = _log().write_csv(d / "tanh_joint.csv")
    out = d / "fit"
    args = [str(csv), "--models", "tanh_coulomb", "coulomb_viscous", "--out", str(out)]
    args += ["--residual", "none", "--load", "none", "--no-plots", "--quiet"]
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(args)
    assert code == 0, err.getvalue()
    return out


def test_the_registry_finds_the_outside_model_by_name():
    from friction_ros.core.identification.fit.models import check_model_names, spec_for

    assert check_model_names(["TANH_COULOMB", "gms4"]) == ["tanh_coulomb", "gms4"]
    spec = spec_for("tanh_coulomb", velocity_scale=10.0)  # a log 10x faster: vt searched 10x higher
    assert spec.nonlinear == ["vt"] and spec.linear_all == ["fc", "fv", "J"]
    assert spec.lower[0] == pytest.approx(1e-3) and spec.upper[0] == pytest.approx(10.0)
    assert isinstance(fit_model("tanh_coulomb"), TanhCoulombFit)
    # everything the model needed lives in this one file, outside the package
    files = {inspect.getsourcefile(c) for c in (TanhCoulomb, TanhCoulombFit)}
    assert files == {__file__} and "friction_ros" not in __file__


def test_the_plant_simulates_the_outside_model_from_its_table():
    """The plant has no compiled kernel for the toy: it tabulates steady_state (2 % node spacing)."""
    from friction_ros.core.friction._kernels import static_torque

    m = make_model("tanh_coulomb", **TRUTH)
    v = np.concatenate([-np.geomspace(1e-4, 20, 200), [0.0], np.geomspace(1e-4, 20, 200)])
    kernel = np.array([static_torque(m.kernel_kind, m.kernel_params, 0, x, 0.0) for x in v])
    assert np.max(np.abs(kernel - m.steady_state(v))) < 5e-4 * TRUTH["fc"]  # h^2 f"/8, h = 2 %


def test_fit_recovers_the_toy_coefficients(fitted):
    summary = json.loads((fitted / "summary.json").read_text())
    models = summary["models"]
    c = models["tanh_coulomb"]["coefficients"]
    assert c["fc"] == pytest.approx(TRUTH["fc"], rel=0.03)
    assert c["vt"] == pytest.approx(TRUTH["vt"], rel=0.10)
    assert c["fv"] == pytest.approx(TRUTH["fv"], rel=0.05)
    assert c["J"] == pytest.approx(J, rel=0.05)
    # the true structure explains the log better than the built-in Coulomb + viscous map
    nmse = {n: models[n]["metrics"]["nmse_percent"] for n in ("tanh_coulomb", "coulomb_viscous")}
    assert nmse["tanh_coulomb"] < nmse["coulomb_viscous"], nmse
    assert summary["recommended"] == "tanh_coulomb"


def test_parameter_file_compensates_in_the_closed_loop(fitted):
    """The parameter file's controller section (the toy model) on the plant whose friction is the
    true toy map: PD with the fitted feed-forward against the same PD without friction compensation."""
    from friction_ros.core.control.controller_config import config_from_ros_parameters
    from friction_ros.core.harness import run_closed_loop

    doc = yaml.safe_load((fitted / "friction_params.yaml").read_text())
    section = doc["compensating_controller"]["ros__parameters"]
    assert section["friction"]["model"] == "tanh_coulomb"
    ctrl, _ = config_from_ros_parameters(section)
    assert ctrl["friction"]["source"] != "none"  # the fitter's safety gate enabled a compensation
    plant = {
        "plant": {"actuation": "torque", "motor_inertia": J, "torque_constant": 1.0},
        "friction_motor": {"model": "tanh_coulomb", **TRUTH},
    }
    pd = {"p": 20.0, "d": 0.5}
    ref = {"type": "band_limited_random", "amplitude": 0.2, "duration": 4.0, "seed": 1}
    truth = {"mode": "pid", "pid": pd, "inertia": J, "friction": {"model": plant["friction_motor"]}}
    rms = {}
    for label, c in (
        ("fitted", {**ctrl, "pid": pd}),
        ("truth", truth),
        ("none", {"mode": "pid", "pid": pd, "inertia": J}),
    ):
        rms[label] = run_closed_loop(plant, c, ref, 4.0).metrics["rms_error"]
    # measured: fitted 3.4e-5, truth 2.8e-5, none 2.3e-2 rad
    assert rms["fitted"] < 0.01 * rms["none"], rms
    assert rms["fitted"] < 1.5 * rms["truth"], rms
