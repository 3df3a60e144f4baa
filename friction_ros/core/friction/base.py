"""Common machinery of the friction model library: coefficient validation, config round-trip.

Sign convention (docs/architecture.md): a model returns the friction torque that *opposes* motion, so
in steady sliding ``steady_state(v) * v >= 0`` and the plant applies ``-friction``.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np

from friction_ros.core.config import Field, Names, names_of
from friction_ros.core.validation import ParameterError, check_keys, check_real

from . import _kernels


class FrictionModel:
    """Base class of every friction model.

    Subclasses declare ``name``, ``COEFS`` (tuple of :class:`~friction_ros.core.config.Field`), ``KIND`` (kernel id) and
    ``is_dynamic``; they implement ``_steady(v)`` (vectorised numpy) and may add cross-checks in
    ``_validate``.
    """

    name: ClassVar[str] = "base"
    COEFS: ClassVar[tuple[Field, ...]] = ()
    KIND: ClassVar[int] = _kernels.K_NONE
    is_dynamic: ClassVar[bool] = False
    #: True when the model's torque depends on the transmitted (load) torque (gearbox term)
    load_dependent: ClassVar[bool] = False
    #: the coefficient holding the presliding stiffness (a number or a list summed), which the
    #: controller's feedback bound scales down (Dahl ``sigma``, LuGre ``sigma0``, GMS ``k``); None: none
    STIFFNESS: ClassVar[str | None] = None

    def __init__(self, *, _path: str | Names = "", **coefficients: Any) -> None:
        names = names_of(_path or self.name)
        check_keys(names(""), coefficients, [c.name for c in self.COEFS])
        self._set(
            names,
            OrderedDict(
                (c.name, c.check(coefficients.get(c.name, c.default), names(c.name))) for c in self.COEFS
            ),
        )

    @classmethod
    def from_section(cls, section: Any) -> FrictionModel:
        """From a typed ``friction`` section (``model`` + the fields :attr:`COEFS`, each checked when
        the section was typed: :meth:`~friction_ros.core.config.Schema.typed`), as it is: only the
        rules across coefficients (``_validate``) run; messages name ``section.path()``."""
        self = cls.__new__(cls)
        values = ((c.name, getattr(section, c.name)) for c in cls.COEFS)
        self._set(
            section.path() or cls.name,
            OrderedDict((k, list(v) if isinstance(v, tuple) else v) for k, v in values),
        )
        return self

    def _set(self, path: str | Names, values: OrderedDict[str, Any]) -> None:
        """Take checked coefficient values; the cross-coefficient rules, kernel parameters, state.
        ``path``: the section's name, or the :data:`~friction_ros.core.config.Names` of its keys."""
        self._names = names_of(path)
        #: the parameter name of the model's section in messages (``friction`` in a ROS parameter
        #: file; the model's name by default)
        self.path = self._names("")
        self._c = values
        self._validate()
        self._p = np.ascontiguousarray(self._kernel_params(), dtype=np.float64)
        self._state = self.initial_state()

    # ---- helpers -----------------------------------------------------------------------------------
    def _validate(self) -> None:
        """Cross-coefficient checks (override)."""

    def _require_fs_ge_fc(self, fs: str = "fs", fc: str = "fc") -> None:
        if self._c[fs] < self._c[fc]:
            raise ParameterError(
                f"{self.key(fs)} = {self._c[fs]:g} is out of range: must be >= {self.key(fc)} "
                f"= {self._c[fc]:g} (static friction below Coulomb friction is not allowed) [N*m]",
                self.key(fs),
            )

    def key(self, coefficient: str) -> str:
        """The parameter name of ``coefficient`` in messages (``friction.fc``, ``friction.j2.fc``)."""
        return self._names(coefficient)

    def _kernel_params(self) -> list[float]:
        out: list[float] = []
        for v in self._c.values():
            out.extend(v if isinstance(v, list) else [v])
        return out

    # ---- public interface --------------------------------------------------------------------------
    @property
    def coefficients(self) -> OrderedDict[str, Any]:
        """Ordered mapping coefficient name -> value (float, or list of floats for element arrays)."""
        return OrderedDict((k, list(v) if isinstance(v, list) else v) for k, v in self._c.items())

    def __getitem__(self, key: str) -> Any:
        return self.coefficients[key]

    def to_config(self) -> dict:
        """Return ``{"model": name, <coefficient>: value, ...}`` (one ROS parameter YAML section)."""
        return {"model": self.name, **self.coefficients}

    def with_coefficients(self, **changes: Any) -> FrictionModel:
        """Return a new model of the same kind with some coefficients replaced (validated)."""
        c = dict(self.coefficients)
        c.update(changes)
        return type(self)(**c, _path=self._names)

    @property
    def param_names(self) -> list[str]:
        """Names of the flat parameter vector (lists expanded as ``k[0]``, ``k[1]`` ...)."""
        names = []
        for k, v in self._c.items():
            if isinstance(v, list):
                names.extend(f"{k}[{i}]" for i in range(len(v)))
            else:
                names.append(k)
        return names

    def param_vector(self) -> np.ndarray:
        """Flat float vector in ``param_names`` order (the row format of ``simulate_batch``)."""
        out: list[float] = []
        for v in self._c.values():
            out.extend(v if isinstance(v, list) else [v])
        return np.array(out, dtype=float)

    def from_param_vector(self, vec: Sequence[float]) -> FrictionModel:
        """Inverse of :meth:`param_vector` for a model of the same structure (validated)."""
        vec = [float(x) for x in vec]
        if len(vec) != len(self.param_names):
            raise ParameterError(
                f"{self.name} parameter vector has {len(vec)} entries: must have {len(self.param_names)} "
                f"({', '.join(self.param_names)})"
            )
        c: dict[str, Any] = {}
        i = 0
        for k, v in self._c.items():
            if isinstance(v, list):
                c[k] = vec[i : i + len(v)]
                i += len(v)
            else:
                c[k] = vec[i]
                i += 1
        return type(self)(**c, _path=self._names)

    def _steady(self, v: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def steady_state(self, v: Any) -> np.ndarray | float:
        """Vectorised steady-sliding friction torque at velocity ``v`` (scalar or array)."""
        arr = np.asarray(v, dtype=float)
        out = self._steady(np.atleast_1d(arr))
        return float(out[0]) if arr.ndim == 0 else out.reshape(arr.shape)

    _scalar_ok = True

    def steady_scalar(self, v: float) -> float:
        """``steady_state`` at one velocity without the array round trip (the controller's hot path:
        ~3 us instead of ~15 us); the same formula on a float, equal to rounding. A model whose
        formula needs arrays falls back to ``steady_state`` (remembered per object)."""
        if self._scalar_ok:
            try:
                return float(self._steady(float(v)))
            except (TypeError, IndexError, ValueError):
                self._scalar_ok = False
        return float(self.steady_state(v))

    def breakaway(self, direction: float = 1.0) -> float:
        """Friction magnitude just off zero velocity in ``direction`` (the plant's stick threshold)."""
        return abs(float(self.steady_state(math.copysign(1e-12, direction))))

    def max_stiffness(self) -> float:
        """Largest presliding stiffness [N*m/rad]; 0 for static models (used to choose sub-steps)."""
        return 0.0

    # kernel view (used by the plant) ---------------------------------------------------------------
    @property
    def kernel_kind(self) -> int:
        return self.KIND

    @property
    def kernel_params(self) -> np.ndarray:
        return self._p

    def initial_state(self) -> np.ndarray:
        return np.zeros(1)

    def __repr__(self) -> str:
        inner = ", ".join(f"{k}={v!r}" for k, v in self._c.items())
        return f"{type(self).__name__}({inner})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, FrictionModel) and self.to_config() == other.to_config()

    __hash__ = None  # type: ignore[assignment]


class StaticModel(FrictionModel):
    """A memoryless velocity map: ``torque(v)`` is ``steady_state(v)``.

    A subclass without a compiled kernel of its own (``KIND``; a model defined outside the package)
    is simulated by the plant from a table of ``steady_state`` at :meth:`table_speeds` (linear in
    |v| between the nodes, :func:`~._kernels.table_torque`); the controller and the fitter call
    ``steady_state`` itself.
    """

    is_dynamic = False
    KIND = _kernels.K_TABLE

    def table_speeds(self) -> np.ndarray:
        """Speeds 0 < w_1 < ... < w_n of the plant's table (override to follow the map's own
        scales): 601 nodes log-spaced over 1e-9 .. 1e4 (rad/s or m/s), 2 % apart, so a smooth map
        is tabulated within about 5e-5 of its curvature scale."""
        return np.geomspace(1e-9, 1e4, 601)

    def _kernel_params(self) -> list[float]:
        if type(self).KIND != _kernels.K_TABLE:
            return super()._kernel_params()
        w = np.asarray(self.table_speeds(), dtype=float)
        if w.ndim != 1 or w.size < 2 or not np.all(np.diff(w) > 0) or w[0] <= 0:
            raise ParameterError(f"{self.name}.table_speeds() must be >= 2 increasing speeds > 0")
        fp, fn = self._steady(w), self._steady(-w)
        f0 = self._steady(np.array([1e-300, -1e-300]))
        return [
            float(w.size),
            *w.tolist(),
            *np.asarray(fp, float).tolist(),
            *np.asarray(fn, float).tolist(),
            *f0,
        ]

    def torque(self, v: Any, load: Any = 0.0) -> np.ndarray | float:
        """Vectorised friction torque at velocity ``v`` (``load``: transmitted torque, gearbox models)."""
        return self.steady_state(v)


class DynamicModel(FrictionModel):
    """A model with internal state: ``reset/state/step/simulate/simulate_batch``."""

    is_dynamic = True
    STATE_NAMES: ClassVar[tuple[str, ...]] = ("z",)

    def reset(self, state: Any = None) -> None:
        """Reset the internal state (relaxed, zero force) or set it to ``state``."""
        if state is None:
            self._state = self.initial_state()
        else:
            st = np.array(state, dtype=float).ravel()
            if st.shape != self.initial_state().shape:
                raise ParameterError(
                    f"{self.name} state has {st.size} entries: must have {self.initial_state().size}"
                )
            self._state = st

    @property
    def state(self) -> np.ndarray:
        """Copy of the internal state vector."""
        return self._state.copy()

    def step(self, v: float, dt: float) -> float:
        """Advance the state by ``dt`` at velocity ``v`` (held constant) and return the friction torque."""
        return float(_kernels.friction_eval(self.KIND, self._p, self._state, float(v), float(dt), 0.0))

    def simulate(self, v_traj: Any, dt: float, reset: bool = True) -> np.ndarray:
        """Torque after each step of the zero-order-held velocity trajectory ``v_traj`` (from rest)."""
        v = np.ascontiguousarray(v_traj, dtype=float).ravel()
        check_real(f"{self.name}.dt", dt, 0.0, lo_open=True, unit="s")
        if reset:
            self.reset()
        out = np.empty(v.size)
        _kernels.simulate_kernel(self.KIND, self._p, self._state, v, float(dt), out)
        return out

    def _check_rows(self, pm: np.ndarray) -> None:
        """Vectorised range check of a parameter matrix (same limits as the constructor)."""
        names = self.param_names
        specs = []
        for c in self.COEFS:
            n = len(self._c[c.name]) if c.is_list else 1
            specs.extend([c] * n)
        for j, (nm, c) in enumerate(zip(names, specs)):
            col = pm[:, j]
            bad = ~np.isfinite(col)
            if c.lo is not None:
                bad |= col <= c.lo if c.lo_open else col < c.lo
            if c.hi is not None:
                bad |= col >= c.hi if c.hi_open else col > c.hi
            if bad.any():
                r = int(np.argmax(bad))
                raise ParameterError(
                    f"{self.name}.{nm} = {col[r]:g} (row {r}) is out of range: must be {c.range_text()}{f' [{c.unit}]' if c.unit else ''}"
                )
        if "fs" in names and "fc" in names:
            fs, fc = pm[:, names.index("fs")], pm[:, names.index("fc")]
            bad = fs < fc
            if bad.any():
                r = int(np.argmax(bad))
                raise ParameterError(
                    f"{self.name}.fs = {fs[r]:g} (row {r}) is out of range: must be >= {self.name}.fc = {fc[r]:g}"
                )

    def batch_kernel_params(self, param_matrix: Any) -> np.ndarray:
        """Convert rows in ``param_names`` order into kernel parameter rows (override if different)."""
        return np.ascontiguousarray(param_matrix, dtype=float)

    def simulate_batch(
        self, param_matrix: Any, v_traj: Any, dt: float, *, use_numba: bool = True
    ) -> np.ndarray:
        """Simulate many parameter sets at once from rest.

        ``param_matrix``: (n_sets, len(param_names)) in ``param_names`` order; returns (n_sets, len(v)).
        Uses the compiled kernel (numba) or, with ``use_numba=False`` / without numba, a pure-numpy
        path vectorised over the parameter axis.
        """
        pm = np.atleast_2d(np.asarray(param_matrix, dtype=float))
        if pm.shape[1] != len(self.param_names):
            raise ParameterError(
                f"{self.name} param_matrix has {pm.shape[1]} columns: must have {len(self.param_names)} "
                f"({', '.join(self.param_names)})"
            )
        self._check_rows(pm)
        check_real(f"{self.name}.dt", dt, 0.0, lo_open=True, unit="s")
        v = np.ascontiguousarray(v_traj, dtype=float).ravel()
        if use_numba and _kernels.HAVE_NUMBA:
            kp = self.batch_kernel_params(pm)
            st0 = np.ascontiguousarray(np.tile(self.initial_state(), (pm.shape[0], 1)))
            out = np.empty((pm.shape[0], v.size))
            _kernels.simulate_batch_kernel(self.KIND, kp, st0, v, float(dt), out)
            return out
        return self._simulate_batch_numpy(pm, v, float(dt))

    def _simulate_batch_numpy(
        self, pm: np.ndarray, v: np.ndarray, dt: float
    ) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError


def sign(v):
    """``np.sign`` that keeps a Python float a float (0 at +-0, NaN at NaN): the scalar path of the
    steady-state formulas (:meth:`FrictionModel.steady_scalar`) without a numpy call per term."""
    if type(v) is float:
        return 1.0 if v > 0.0 else -1.0 if v < 0.0 else (0.0 if v == 0.0 else v)
    return np.sign(v)


def exp(x):
    """``np.exp`` that keeps a Python float a float (``math.exp``); see :func:`sign`."""
    return math.exp(x) if type(x) is float else np.exp(x)


def stribeck_np(av: np.ndarray, fc: Any, fs: Any, vs: Any, delta: Any) -> np.ndarray:
    """Stribeck magnitude s(|v|) = Fc + (Fs - Fc) exp(-(|v|/vs)^delta), on arrays or a float."""
    return fc + (fs - fc) * exp(-((av / vs) ** delta))
