"""The built-in fittable families as :class:`~.fit_model.FitModel` implementations.

* ``coulomb`` / ``coulomb_viscous``: phi = sat(v/eps) (ABB M19-S paper A.2.1), linear ``fc`` (+ ``fv``);
* ``stribeck``: phi = [sat(v/eps), sat(v/eps) exp(-|v/vs|^delta)] (ABB M19-S paper A.2.2), theta =
  ``vs, delta, eps`` (the linear-zone width is fitted), linear ``fc, dfs = fs - fc``;
* ``dahl``, ``lugre``, ``gms<N>[d]``: the regressors of the compiled kernels (:mod:`kernels`; the
  normalised theta ``sigma_n = sigma/fc``, ``r = fc/fs``, ``sigma0_n = sigma0/fs``,
  ``attraction_n = attraction/fs``, ``x_i = alpha_i fs/k_i``, ``s_damp = sigma1 / sum k`` are
  documented there).

Bounds of the dynamic models: fc/fs in [0.5, 1] (a static level at most twice the Coulomb level)
and vs >= 1e-3 rad/s; without them the sparsely visited low-speed sliding region lets the fit grow
an unphysical Stribeck spike that costs nothing in NMSE but ruins compensation. The damped GMS
searches ``s_damp`` in log space over [1e-6, 0.1] s (1e-6 s is no damping for any practical purpose).

Export (:meth:`FitModel.library_config`): a static family fitted in the time domain with a linear
zone ``eps`` -> ``stribeck_eps`` (Coulomb as fs = fc); from plateaus -> the plain library model
(``asymmetric`` wrapper when the directions differ); ``dahl`` -> ``dahl`` (alpha = 1; the fitted
``fv`` has no place in the library's Dahl); ``lugre`` -> ``lugre``; ``gms<N>[d]`` -> ``gms``
(``fs`` held >= ``fc``, ``alpha`` summing exactly to 1).
"""

from __future__ import annotations

import numpy as np

from friction_ros.core.identification.fit import kernels
from friction_ros.core.identification.fit.fit_model import Coef, FitModel, register_fit_model, sat_sign
from friction_ros.core.identification.fit.static_fit import stribeck_map
from friction_ros.core.validation import ParameterError


def _library_coefficients(model: str, c: dict) -> dict:
    """The fitted coefficients that library ``model`` has, in the library's order, ``fs >= fc``."""
    from friction_ros.core.friction import MODEL_CLASSES

    out = {co.name: c[co.name] for co in MODEL_CLASSES[model].COEFS if co.name in c}
    out["fs"] = max(out["fs"], out["fc"])
    return out


# ------------------------------------------------------------------------------ static Stribeck family
class _StaticStribeckFamily(FitModel):
    """Shared export and steady state of the Coulomb / Coulomb+viscous / Stribeck maps."""

    nested = "stribeck"

    def _body(self, c: dict) -> dict:
        return {"fc": float(c["fc"])}

    def library_config(self, c, eps=0.0, per_direction=None):
        if per_direction:
            return {
                "model": "asymmetric",
                "base": self.plateau_shape,
                "positive": self._body(per_direction["positive"]),
                "negative": self._body(per_direction["negative"]),
            }
        eps = float(c.get("eps", eps))
        body = self._body(c)
        if eps > 0:
            fc = body["fc"]
            full = {
                "fc": fc,
                "fs": body.get("fs", fc),
                "vs": body.get("vs", 1.0),
                "delta": body.get("delta", 2.0),
            }
            return {"model": "stribeck_eps", **full, "fv": float(c.get("fv", 0.0)), "eps": eps}
        return {"model": self.plateau_shape, **body}

    def steady_state(self, c, v, eps):
        return stribeck_map(v, {**c, "fs": c.get("fs", c["fc"])}) * np.abs(sat_sign(v, c.get("eps", eps)))


@register_fit_model
class CoulombFit(_StaticStribeckFamily):
    family = help = plateau_shape = "coulomb"
    viscous = False

    def linear(self):
        return ["fc"]

    def features(self, theta, v, dt, eps):
        return sat_sign(v, eps)[:, None]

    def coefficients(self, theta, lin, fv):
        return {"fc": lin["fc"], **({} if fv is None else {"fv": fv})}


@register_fit_model
class CoulombViscousFit(CoulombFit):
    family = help = plateau_shape = "coulomb_viscous"
    viscous = True

    def _body(self, c):
        return {"fc": float(c["fc"]), "fv": float(c.get("fv", 0.0))}


@register_fit_model
class StribeckFit(_StaticStribeckFamily):
    family = help = plateau_shape = "stribeck"

    def nonlinear(self):
        # ABB M19-S paper A.2.2: the linear-zone width eps is a coefficient of this model (fitted)
        return [Coef("vs", 1e-4, 2.0, True, 1), Coef("delta", 0.3, 4.0), Coef("eps", 1e-4, 0.5, True, 1)]

    def linear(self):
        return ["fc", "dfs"]

    def features(self, theta, v, dt, eps):
        vs, delta, eps = theta
        sg = sat_sign(v, eps)
        return np.column_stack([sg, sg * np.exp(-(np.abs(v / vs) ** delta))])

    def coefficients(self, theta, lin, fv):
        fc = lin["fc"]
        return {"fc": fc, "fs": fc + lin["dfs"], "vs": theta[0], "delta": theta[1], "fv": fv, "eps": theta[2]}

    def _body(self, c):
        fc = float(c["fc"])
        return {
            "fc": fc,
            "fs": max(float(c["fs"]), fc),
            "vs": float(c["vs"]),
            "delta": float(c["delta"]),
            "fv": float(c.get("fv", 0.0)),
        }


# ------------------------------------------------------------------------------ dynamic families
class _CompiledDynamic(FitModel):
    """A dynamic family whose regressors and Grams come from :mod:`kernels` (``_features``/``_gram``)."""

    dynamic = True
    nested = "stribeck"

    def features(self, theta, v, dt, eps):
        return type(self)._features(theta, v, dt)

    def grams(self, P, v, E, dt, sos):
        return type(self)._gram(P, v, E, dt, sos)

    def steady_state(self, c, v, eps):
        return stribeck_map(v, c)


@register_fit_model
class DahlFit(_CompiledDynamic):
    family = help = "dahl"
    _features = staticmethod(kernels.dahl_features)
    _gram = staticmethod(kernels.dahl_gram)

    def nonlinear(self):
        return [Coef("sigma_n", 1.0, 1e6, True, -1)]

    def linear(self):
        return ["fc"]

    def coefficients(self, theta, lin, fv):
        return {"fc": lin["fc"], "sigma": theta[0] * lin["fc"], "fv": fv}

    def library_config(self, c, eps=0.0, per_direction=None):
        return {"model": "dahl", "sigma": c["sigma"], "fc": c["fc"], "alpha": 1.0}

    def steady_state(self, c, v, eps):
        return c["fc"] * np.sign(v)


#: the Stribeck shape of LuGre and GMS: r = fc/fs, vs, delta (see the module docstring)
_SHAPE = [Coef("r", 0.5, 1.0), Coef("vs", 1e-3, 2.0, True, 1), Coef("delta", 0.3, 4.0)]


@register_fit_model
class LuGreFit(_CompiledDynamic):
    family = help = "lugre"
    two_stage = True
    _features = staticmethod(kernels.lugre_features)
    _gram = staticmethod(kernels.lugre_gram)

    def nonlinear(self):
        return [*_SHAPE, Coef("sigma0_n", 10.0, 1e6, True, -1)]

    def linear(self):
        return ["fs", "sigma1"]

    def coefficients(self, theta, lin, fv):
        r, vs, delta, s0 = theta
        fs = lin["fs"]
        return {
            "fc": r * fs,
            "fs": fs,
            "vs": vs,
            "delta": delta,
            "sigma0": s0 * fs,
            "sigma1": lin["sigma1"],
            "fv": fv,
        }

    def library_config(self, c, eps=0.0, per_direction=None):
        return {"model": "lugre", **_library_coefficients("lugre", c)}

    def steady_state_constraints(self, linear_all, fs):
        return [(np.array([1.0 if n == "fs" else 0.0 for n in linear_all]), fs)]


@register_fit_model
class GMSFit(_CompiledDynamic):
    """Generalized Maxwell-slip with N elements (1..20); ``gms<N>d`` adds presliding damping
    (the library GMS's ``sigma1 = s_damp sum_j k_j``, stiffness-proportional), one more theta
    (last); each element regressor becomes ``G_i + s dG_i/dt`` (see :mod:`kernels`)."""

    family = "gms"
    help = "gms<N> (e.g. gms4), gms<N>d (with presliding damping, e.g. gms4d)"
    two_stage = True
    narrow_signals = True

    def __init__(self, n_elements: int = 4, damped: bool = False) -> None:
        super().__init__(f"gms{n_elements}{'d' if damped else ''}")
        self.n_elements, self.damped = n_elements, damped

    @classmethod
    def parse(cls, name):
        if not name.startswith("gms"):
            return None
        body = name[3:].lstrip("_-")
        damped = body.endswith("d")
        body = body[:-1].rstrip("_-") if damped else body
        try:
            ne = int(body or "4")
        except ValueError:
            return None
        if not 1 <= ne <= 20:
            raise ParameterError(f"model = {name!r}: GMS element count {ne} is out of range: must be 1..20")
        return cls(ne, damped)

    def nonlinear(self):
        ne = self.n_elements
        xs = [Coef(f"x{i + 1}", 1e-6, 0.1, True, 1) for i in range(ne)]
        return [*_SHAPE, Coef("attraction_n", 1.0, 1e5, True), *xs] + [
            Coef("s_damp", 1e-6, 0.1, True)
        ] * self.damped

    def linear(self):
        return [f"beta{i + 1}" for i in range(self.n_elements)]

    def features(self, theta, v, dt, eps):
        return kernels.gms_features(theta, v, dt, self.damped)

    def grams(self, P, v, E, dt, sos):
        return kernels.gms_gram(P, v, E, dt, sos, self.damped)

    def coefficients(self, theta, lin, fv):
        ne = self.n_elements
        r, vs, delta, attraction_n = theta[:4]
        xs = theta[4 : 4 + ne]
        betas = np.array([lin[f"beta{i + 1}"] for i in range(ne)])
        fs = float(betas.sum())
        alpha = betas / fs if fs > 0 else np.full(ne, 1.0 / ne)
        k = betas / xs  # k_i = alpha_i fs / x_i
        order = np.argsort(xs)
        c = {
            "fc": r * fs,
            "fs": fs,
            "vs": vs,
            "delta": delta,
            "attraction": attraction_n * fs,
            "fv": fv,
            "k": k[order].tolist(),
            "alpha": alpha[order].tolist(),
        }
        if self.damped:  # sigma1 = s sum_j k_j (stiffness-proportional presliding damping)
            c["sigma1"] = float(theta[4 + ne] * k.sum())
        return c

    def library_config(self, c, eps=0.0, per_direction=None):
        out = {"model": "gms", **_library_coefficients("gms", c)}
        alpha = [float(a) for a in c["alpha"]]
        alpha[-1] = 1.0 - sum(alpha[:-1])  # exact sum 1 after rounding
        out.update(k=[float(k) for k in c["k"]], alpha=alpha)
        return out

    def steady_state_constraints(self, linear_all, fs):
        return [(np.array([1.0 if n.startswith("beta") else 0.0 for n in linear_all]), fs)]

    def warm_start(self, spec, fitted):
        """The last GMS fitted before: its shape and element distances (repeated to N elements)."""
        smaller = [(n, th) for n, th in fitted if n.startswith("gms")]
        if not smaller:
            return None
        prev, th = smaller[-1]
        th = np.asarray(th)
        pm = GMSFit.parse(prev)
        xs = np.resize(th[4 : 4 + pm.n_elements], self.n_elements)
        x0 = np.concatenate([th[:4], xs])
        if self.damped:  # the smaller fit's damping, else the middle of its range
            sd = th[-1] if pm.damped else np.sqrt(spec.lower[-1] * spec.upper[-1])
            x0 = np.append(x0, sd)
        return x0
