"""What the stages of one fit pass on (:func:`~friction_ros.core.identification.fit.pipeline.fit_records`).

:class:`FitContext` starts with the options and the records as given; each stage fills its part
(data stages: :mod:`~friction_ros.core.identification.fit.fit_data`; model stages:
:mod:`~friction_ros.core.identification.fit.pipeline`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from friction_ros.core.identification.data.records import JointData
from friction_ros.core.identification.fit.fit_options import FitOptions


@dataclass
class FitContext:
    """The state of one fit, stage by stage (validation = the records outside the training windows)."""

    options: FitOptions
    models: Any  # the model names as given: a refit starts from them
    records_in: list[JointData]  # the records as given (cut to max_samples): a refit starts from them
    validation_in: list[JointData] | None  # validation records as given (cross-validation over runs)
    progress: Callable[[str, float], None] | None
    t_start: float
    # prepare_data
    names: list[str] = field(default_factory=list)  # the models to fit (dynamic ones may be skipped)
    records: list[JointData] = field(default_factory=list)  # scaled, load offset removed
    validation: list[JointData] | None = None  # validation_in with the records' scales
    scale: Any = None  # DataScale: the log's velocity and torque scales
    eps: float = 0.0  # [vel] linear zone of sgn(v) (option or 1e-3 x velocity scale)
    offset: float = 0.0  # [N*m | N] load offset measured on the plateaus (0: none)
    offset_note: str = ""
    # split_train_validation
    train: list[JointData] = field(default_factory=list)
    val: list[JointData] = field(default_factory=list)
    val_from: list[tuple[JointData, np.ndarray]] = field(default_factory=list)  # (whole record, kept mask)
    windows: list[tuple[float, float]] = field(default_factory=list)  # [s] training windows
    warnings: list[str] = field(default_factory=list)
    # find_features
    plateaus: list = field(default_factory=list)
    breakaways: list = field(default_factory=list)
    excitation: Any = None
    skipped: dict[str, str] = field(default_factory=dict)  # model -> why the log cannot determine it
    # choose_load_terms
    terms: Any = None  # LoadTerms
    selection: Any = None  # Selection | None: how the terms were chosen
    vall: JointData | None = None  # the validation data in one record
    high_mask: np.ndarray | None = None
    low_mask: np.ndarray | None = None
    scored: np.ndarray | None = None  # validation samples scored (long standstills are not)
    high_threshold: float = 0.0  # [vel]
    grid: np.ndarray | None = None  # [vel] steady-state map velocities
    # model stages
    results: dict = field(default_factory=dict)  # name -> ModelResult
    baseline: Any = None  # the inverse-dynamics baseline's ModelResult
    candidates: dict = field(default_factory=dict)  # models that may be recommended
    recommendation: dict = field(default_factory=dict)
    verdict: dict = field(default_factory=dict)

    def predict_val(self, model) -> np.ndarray:
        """A model's validation prediction: dynamic states run through each whole record (one
        simulation); validation = the samples outside the training windows."""
        return np.concatenate([model.predict(full)[keep] for full, keep in self.val_from])

    def progress_of(self, name: str) -> Callable[[float], None] | None:
        """``fraction -> None`` reporting ``name``'s progress (None without a progress callback)."""
        return (lambda f: self.progress(name, f)) if self.progress else None
