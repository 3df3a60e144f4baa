"""Load, gravity and position-dependent regressors, identified jointly with inertia and friction.

Real joints carry more than friction (:mod:`friction_ros.core.friction.joint_load` has the
equations). Each term enters the measured torque linearly, so it is one more column of the
output-error fit's linear part (variable projection, :mod:`~friction_ros.core.identification.fit.models`):

=================  ==========================================  ===============  ================
term               column(s)                                   coefficient(s)   sign
=================  ==========================================  ===============  ================
``gravity``        sin q, cos q                                a, b             free
``offset``         1                                           offset           free
``spring``         q                                           spring           free
``load_friction``  abs(tau_tr) sgn_eps(v)                      k_L              >= 0
``ripple`` (H)     sgn_eps(v) cos(k w q), sgn_eps(v) sin(k w q) c_k, s_k         free
=================  ==========================================  ===============  ================

with ``a sin q + b cos q = gravity sin(q + gravity_phase)``, ``gravity = hypot(a, b)``,
``gravity_phase = atan2(b, a)``, ``w = 2 pi / ripple_period`` and ``tau_tr = J a + tau_load(q)``
the torque the gear transmits, estimated from a first fit without the load-dependent term
(:func:`transmitted_torque`).

A direction-dependent load friction (a gear's forward and backward efficiencies differ:
``k_L (1 + a_L d) abs(tau_tr)`` with ``d = sgn(tau_tr v)``) adds ``k_L a_L tau_tr abs(sgn_eps(v))``, which
while the joint moves is ``k_L a_L tau_tr``: a scaling of the load torque and of J a, absorbed by the
gravity, offset, spring and inertia coefficients. Tried on the realistic joint with a_L = 0.4 it
lowered the validation MSE by 0.7 % at best and was never kept, so it is not a term here.

Which terms a log needs is decided by validation (:func:`select_terms`): greedy forward selection
on a linear backbone (inertia, viscous, Coulomb and a bank of Stribeck bumps: every candidate costs
one least-squares solve, :func:`backbone_fit`; samples slower than the sign's linear zone left out),
a term kept only when it lowers the validation MSE by at least ``min_gain`` (5 %: on the
simulator's GMS joint a spurious first ripple harmonic gained 2.8 % on the linear backbone); the
ripple grows one harmonic at a time the same way, up to :data:`MAX_RIPPLE`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, replace

import numpy as np

from friction_ros.core.friction.joint_load import JointLoad
from friction_ros.core.identification.data.data_scale import velocity_scale
from friction_ros.core.identification.data.records import quantization_velocity_noise
from friction_ros.core.validation import ParameterError

#: the load terms a user can name (``--load gravity,offset,ripple=4``)
TERMS = ("gravity", "offset", "spring", "load_friction", "ripple")
MAX_RIPPLE = 8  # harmonics tried by the automatic selection
MIN_GAIN = 0.05  # relative validation-MSE reduction a term must bring to be kept


@dataclass(frozen=True)
class LoadTerms:
    """Which load/position terms a fit identifies (see the module table)."""

    gravity: bool = False
    offset: bool = False
    spring: bool = False
    load_friction: bool = False
    ripple: int = 0
    ripple_period: float = 2.0 * math.pi
    eps: float = 1e-3

    @property
    def names(self) -> list[str]:
        out = []
        if self.gravity:
            out += ["gravity_sin", "gravity_cos"]
        if self.offset:
            out.append("offset")
        if self.spring:
            out.append("spring")
        if self.load_friction:
            out.append("load_friction")
        for k in range(1, self.ripple + 1):
            out += [f"ripple_cos{k}", f"ripple_sin{k}"]
        return out

    @property
    def free(self) -> list[bool]:
        """Per column: may the coefficient take either sign (all but the load-dependent friction)."""
        return [n != "load_friction" for n in self.names]

    @property
    def empty(self) -> bool:
        return not self.names

    def describe(self) -> str:
        parts = [t for t in TERMS[:4] if getattr(self, t)]
        if self.ripple:
            parts.append(f"ripple={self.ripple} (period {self.ripple_period:.4g} rad)")
        return ", ".join(parts) or "none"

    def columns(self, q, v, transmitted=None) -> np.ndarray:
        """The regressor columns (n x len(names)) for angle q, velocity v and transmitted torque."""
        q = np.asarray(q, dtype=float)
        cols = []
        sg = np.clip(np.asarray(v, dtype=float) / self.eps, -1.0, 1.0)
        if self.gravity:
            cols += [np.sin(q), np.cos(q)]
        if self.offset:
            cols.append(np.ones_like(q))
        if self.spring:
            cols.append(q)
        if self.load_friction:
            if transmitted is None:
                raise ParameterError("load_friction: the record has no transmitted-torque estimate")
            cols.append(np.abs(np.asarray(transmitted, dtype=float)) * sg)
        w = 2.0 * math.pi / self.ripple_period
        for k in range(1, self.ripple + 1):
            cols += [sg * np.cos(k * w * q), sg * np.sin(k * w * q)]
        return np.column_stack(cols) if cols else np.zeros((q.size, 0))

    def joint_load(self, coefficients: dict) -> JointLoad:
        """The runtime :class:`JointLoad` of fitted coefficients (keys = :attr:`names`)."""
        c = {n: float(coefficients.get(n, 0.0)) for n in self.names}
        a, b = c.get("gravity_sin", 0.0), c.get("gravity_cos", 0.0)
        return JointLoad(
            gravity=math.hypot(a, b),
            gravity_phase=math.atan2(b, a) if (a or b) else 0.0,
            offset=c.get("offset", 0.0),
            spring=c.get("spring", 0.0),
            load_friction=min(max(c.get("load_friction", 0.0), 0.0), 1.0),
            ripple_period=self.ripple_period,
            ripple_cos=[c[f"ripple_cos{k}"] for k in range(1, self.ripple + 1)],
            ripple_sin=[c[f"ripple_sin{k}"] for k in range(1, self.ripple + 1)],
            eps=self.eps,
        )


def parse_terms(text: str | None, *, ripple_period: float = 2.0 * math.pi, eps: float = 1e-3):
    """``"auto"`` -> "auto"; ``"none"``/"" -> LoadTerms(); ``"gravity,offset,ripple=4"`` -> LoadTerms.

    A bad name or count raises ParameterError naming it and the allowed values.
    """
    text = "none" if text is None else str(text).strip().lower()
    if text == "auto":
        return "auto"
    if not (ripple_period > 0 and math.isfinite(ripple_period)):
        raise ParameterError(f"ripple_period = {ripple_period!r} is out of range: must be > 0 [rad]")
    out = LoadTerms(ripple_period=float(ripple_period), eps=float(eps))
    if text in ("none", ""):
        return out
    for item in (p.strip() for p in text.split(",") if p.strip()):
        name, _, count = item.partition("=")
        name = name.strip()
        if name not in TERMS:
            raise ParameterError(
                f"load term {name!r} is not allowed: must be auto, none or a comma list of {', '.join(TERMS)} "
                "(ripple=<harmonics>)"
            )
        if name == "ripple":
            try:
                h = int(count) if count else 2
            except ValueError:
                raise ParameterError(
                    f"ripple={count!r}: the harmonic count must be an integer 1..20"
                ) from None
            if not 1 <= h <= 20:
                raise ParameterError(f"ripple={h} is out of range: must be 1..20 harmonics")
            out = replace(out, ripple=h)
        else:
            if count:
                raise ParameterError(f"load term {item!r}: only ripple takes a value (ripple=<harmonics>)")
            out = replace(out, **{name: True})
    return out


def transmitted_torque(record, inertia: float, load: JointLoad, acceleration=None) -> np.ndarray:
    """tau_tr = J a + tau_load(q): the torque the gear passes to the link (joint_load docstring)."""
    a = record.acceleration if acceleration is None else acceleration
    return inertia * np.asarray(a, dtype=float) + load.load_torque(record.position)


# ------------------------------------------------------------------------------------ selection
@dataclass
class Selection:
    """What :func:`select_terms` chose and the validation MSE of every step (for the report)."""

    terms: LoadTerms
    steps: list[tuple[str, float, float, bool]]  # (candidate, validation MSE, MSE before it, kept)
    baseline_mse: float
    inertia: float
    joint_load: JointLoad

    def table(self) -> list[str]:
        """One line per selection step: the best candidate (kept or not) and the others tried."""
        rows = [f"no load terms: validation MSE {self.baseline_mse:.4g} N^2*m^2"]
        groups: list[list[tuple[str, float, float, bool]]] = []
        for row in self.steps:  # the candidates of one step share the MSE before it
            if groups and groups[-1][0][2] == row[2]:
                groups[-1].append(row)
            else:
                groups.append([row])

        def change(mse, before):
            return f"{100.0 * (mse / before - 1.0):+.1f} %" if before > 0 else "n/a"

        for k, g in enumerate(groups, 1):
            best = min(g, key=lambda r: r[1])
            others = ", ".join(f"{n} {change(m, b)}" for n, m, b, _ in g if n != best[0])
            verdict = "kept" if best[3] else "not kept (gain below min_gain): selection ends"
            rows.append(
                f"step {k}: {best[0]} -> {best[1]:.4g} ({change(best[1], best[2])}), {verdict}"
                + (f"; also tried: {others}" if others else "")
            )
        return rows


#: Stribeck velocities of the backbone's bumps sgn(v) exp(-(v/vs_i)^2), times the log's velocity scale
BACKBONE_STRIBECK = (0.003, 0.01, 0.03, 0.1, 0.3)


@dataclass
class BackboneFit:
    """The selection backbone's linear fit: coefficients per column name."""

    terms: LoadTerms
    coefficients: dict

    @property
    def inertia(self) -> float:
        return float(self.coefficients["J"])

    @property
    def load_coefficients(self) -> dict:
        return {n: self.coefficients[n] for n in self.terms.names}

    def predict(self, r) -> np.ndarray:
        return _backbone_columns(self.terms, r) @ np.array(list(self.coefficients.values()))


def _backbone_columns(terms: LoadTerms, r) -> np.ndarray:
    sg = np.clip(r.velocity / terms.eps, -1.0, 1.0)
    av = np.abs(r.velocity)
    cols = [r.acceleration, r.velocity, sg] + [
        sg * np.exp(-((av / (vs * velocity_scale(r))) ** 2)) for vs in BACKBONE_STRIBECK
    ]
    return np.column_stack([*cols, terms.columns(r.position, r.velocity, r.transmitted)])


def backbone_fit(terms: LoadTerms, train, val, eps: float | None = None):
    """(validation MSE, :class:`BackboneFit`) of the selection backbone with ``terms``.

    The backbone is linear, so every candidate costs one least-squares solve: inertia, viscous,
    Coulomb and a bank of Stribeck bumps (:data:`BACKBONE_STRIBECK`, any sign) for the friction
    map, plus the load columns. It only ranks the load terms; the models are fitted afterwards.
    """
    names = ["J", "fv", "fc", *[f"stribeck{vs:g}" for vs in BACKBONE_STRIBECK], *terms.names]
    # samples whose direction the velocity estimate cannot tell (|v| < eps, eps >= 3 sigma of its
    # noise) carry a sign error of up to 2 fs: left out, they would hide every smaller term
    X = np.vstack([_backbone_columns(terms, r)[np.abs(r.velocity) >= terms.eps] for r in train])
    y = np.concatenate([r.torque[np.abs(r.velocity) >= terms.eps] for r in train])
    scale = np.sqrt(np.maximum(np.sum(X**2, axis=0), 1e-300))
    coef, *_ = np.linalg.lstsq(X / scale, y, rcond=None)
    fit = BackboneFit(terms, dict(zip(names, (coef / scale).tolist())))
    e = np.concatenate([(fit.predict(r) - r.torque)[np.abs(r.velocity) >= terms.eps] for r in val])
    return float(np.mean(e**2)), fit


def with_transmitted(records, inertia: float, load: JointLoad):
    """The records with ``transmitted`` set from ``inertia`` and ``load`` (:func:`transmitted_torque`);
    a record that carries a measured transmitted torque (``meta["transmitted_source"]``: a CSV
    ``load`` column) keeps it."""
    return [
        r
        if r.meta.get("transmitted_source")
        else dataclasses.replace(r, transmitted=transmitted_torque(r, inertia, load))
        for r in records
    ]


def select_terms(
    train,
    val,
    *,
    eps: float = 1e-3,
    ripple_period: float = 2.0 * math.pi,
    max_ripple: int = MAX_RIPPLE,
    min_gain: float = MIN_GAIN,
    candidates=("gravity", "offset", "spring", "load_friction", "ripple"),
) -> Selection:
    """Choose the load terms by validation (module docstring); returns a :class:`Selection`.

    Greedy forward selection over ``candidates``: at each step every unused candidate is tried
    (``ripple`` adds one harmonic, up to ``max_ripple``), the one with the lowest validation MSE is
    kept if it lowers it by ``min_gain``. ``load_friction`` uses the transmitted torque of the
    current backbone (its inertia and load terms). ``train``/``val``: lists of JointData. The
    returned ``joint_load``/``inertia`` are the backbone's, for the transmitted torque.
    """
    terms = LoadTerms(ripple_period=ripple_period, eps=eps)
    best, fit = backbone_fit(terms, train, val)
    base = best
    steps: list[tuple[str, float, float, bool]] = []
    remaining = list(candidates)
    while remaining:
        jl = terms.joint_load(fit.load_coefficients)
        tr_train = with_transmitted(train, max(fit.inertia, 0.0), jl)
        tr_val = with_transmitted(val, max(fit.inertia, 0.0), jl)
        trials = []
        for c in remaining:
            t = replace(terms, ripple=terms.ripple + 1) if c == "ripple" else replace(terms, **{c: True})
            mse, f = backbone_fit(t, tr_train, tr_val)
            label = f"+ripple={t.ripple}" if c == "ripple" else f"+{c}"
            trials.append((mse, c, t, f, label))
        mse, c, t, f, label = min(trials, key=lambda x: x[0])
        keep = mse < (1.0 - min_gain) * best
        steps += [(lb, m2, best, keep and c2 == c) for m2, c2, _, _, lb in trials]
        if not keep:
            break
        terms, best, fit = t, mse, f
        if c != "ripple" or terms.ripple >= max_ripple:
            remaining.remove(c)
    return Selection(terms, steps, base, max(fit.inertia, 0.0), terms.joint_load(fit.load_coefficients))


def terms_for_fit(load, plateaus, train, val, ripple_period, load_eps, eps, joint_type="revolute"):
    """(LoadTerms, Selection | None) for the ``load`` option of :func:`~friction_ros.core.identification.fit.pipeline.fit_records`."""
    if load_eps is None:  # sgn(v) must not flip on velocity noise: at least 3 sigma of it
        r = train[0]
        noise = (
            float(np.median(np.abs(np.diff(r.velocity, 2)))) / (0.6745 * math.sqrt(6.0)) if r.n > 3 else 0.0
        )
        load_eps = max(eps, 3.0 * noise, 3.0 * quantization_velocity_noise(r))
    terms = load
    if isinstance(load, str):
        if load == "auto" and len(plateaus) >= 3:
            terms = "none"  # an experiment with plateaus: its load offset is measured on them
        terms = parse_terms(terms, ripple_period=ripple_period, eps=load_eps)
    angle_terms = ("gravity", "ripple")  # functions of an angle: a revolute joint's only
    if terms == "auto":
        cands = ("gravity", "offset", "spring", "load_friction", "ripple")
        if joint_type == "prismatic":
            cands = tuple(c for c in cands if c not in angle_terms)
        sel = select_terms(train, val, eps=load_eps, ripple_period=ripple_period, candidates=cands)
        return sel.terms, sel
    if joint_type == "prismatic" and isinstance(terms, LoadTerms) and (terms.gravity or terms.ripple):
        raise ParameterError(
            f"load = {load!r}: gravity and ripple terms are functions of an angle; a prismatic joint allows "
            "offset, spring and load_friction"
        )
    if not isinstance(terms, LoadTerms):
        raise ParameterError(f"load = {load!r} is not allowed: must be auto, none, a term list or LoadTerms")
    if terms.load_friction:  # the transmitted torque needs a first fit of the other terms
        base = dataclasses.replace(terms, load_friction=False)
        _, fit = backbone_fit(base, train, val)
        return terms, Selection(
            terms, [], math.nan, max(fit.inertia, 0.0), base.joint_load(fit.load_coefficients)
        )
    return terms, None
