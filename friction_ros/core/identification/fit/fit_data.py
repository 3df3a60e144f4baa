"""The data stages of a fit: prepare and scale -> split train/validation -> features -> load terms.

Each stage fills its part of a :class:`~friction_ros.core.identification.fit.fit_context.FitContext`
(the model stages follow in :mod:`~friction_ros.core.identification.fit.pipeline`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from friction_ros.core.identification.data.breakaway_detection import find_breakaways
from friction_ros.core.identification.data.data_scale import data_scale, with_scale
from friction_ros.core.identification.data.excitation_checks import (
    check_motion,
    excitation,
    one_direction_note,
)
from friction_ros.core.identification.data.plateau_detection import (
    chattering_plateaus,
    find_plateaus,
    load_offset,
)
from friction_ros.core.identification.data.records import concat_records
from friction_ros.core.identification.data.training_split import split, training_segments, training_window
from friction_ros.core.identification.data.velocity_regimes import (
    high_velocity_mask,
    mask_runs,
    moving_mask,
    standstill_mask,
)
from friction_ros.core.identification.fit.fit_context import FitContext
from friction_ros.core.identification.fit.load_terms import terms_for_fit, with_transmitted
from friction_ros.core.identification.fit.model_fits import imprecise_breakaways
from friction_ros.core.identification.fit.models import DEFAULT_EPS, LEARNED, check_model_names, spec_for
from friction_ros.core.identification.fit.search_space import velocity_grid
from friction_ros.core.validation import ParameterError


def prepare_data(ctx: FitContext) -> None:
    """Model names checked; records scaled to the log's own speed and torque scales
    (:mod:`~friction_ros.core.identification.data.data_scale`: every speed threshold and bound follows
    them); ``eps = 1e-3 x velocity scale`` unless given; motion checked; the load offset measured on
    the plateaus (:func:`~friction_ros.core.identification.data.plateau_detection.load_offset`) removed."""
    opts = ctx.options
    ctx.names = check_model_names(ctx.models)
    if not ctx.records_in:
        raise ParameterError("records = []: need at least one record")
    ctx.scale = data_scale(ctx.records_in)
    records = with_scale(ctx.records_in, ctx.scale)
    ctx.validation = ctx.validation_in
    if ctx.validation_in:
        ctx.validation = with_scale(ctx.validation_in, ctx.scale)
    ctx.eps = DEFAULT_EPS * ctx.scale.velocity if opts.eps is None else opts.eps
    for r in records:
        check_motion(r, r.meta.get("source", opts.label))
    ctx.offset, ctx.offset_note = load_offset([p for r in records for p in find_plateaus(r)])
    if ctx.offset:
        records = [dataclasses.replace(r, torque=r.torque - ctx.offset) for r in records]
    ctx.records = records


def split_train_validation(ctx: FitContext) -> None:
    """Training and validation data (``train_window``, see ``fit_records``); with validation records
    given, train on all the records and validate on those. Records too short to split validate on
    their training data (with a warning); what reading the data found is passed on as warnings."""
    opts = ctx.options
    if ctx.validation:
        ctx.train = list(ctx.records)
        ctx.val = list(ctx.validation)
        ctx.val_from = [(r, np.ones(r.n, bool)) for r in ctx.val]
    for r in [] if ctx.validation else ctx.records:
        if r.duration > opts.train_seconds + 1.0:
            if opts.train_window == "first":
                segs = [(0, split(r, opts.train_seconds)[0].n)]
            elif opts.train_window == "window":
                segs = [training_window(r, opts.train_seconds)]
            else:
                segs = training_segments(r, opts.train_seconds)
            keep = np.ones(r.n, bool)
            for i0, i1 in segs:
                keep[i0:i1] = False
                ctx.train.append(r.slice(i0, i1))
                ctx.windows.append((float(r.t[i0]), float(r.t[i1 - 1])))
            ctx.val.append(concat_records([r.slice(a, b) for a, b in mask_runs(keep)]))
            ctx.val_from.append((r, keep))
    if not ctx.val and not ctx.validation:  # records too short to split: validate on the training data
        ctx.train = list(ctx.records)
        ctx.val = list(ctx.records)
        ctx.val_from = [(r, np.ones(r.n, bool)) for r in ctx.records]
        ctx.warnings.append(
            f"records shorter than train_seconds + 1 s ({opts.train_seconds:g} s): validated on training data"
        )
    for r in ctx.records:  # what reading the data found: a truncated bag, missing positions ...
        ctx.warnings += [f"{r.meta.get('source', opts.label)}: {w}" for w in r.meta.get("warnings", [])]
    if ctx.offset:
        ctx.warnings.append(ctx.offset_note)


def find_features(ctx: FitContext) -> None:
    """Plateaus (every one left out named with the reason), chattering plateaus, breakaways and the
    excitation; dynamic models are skipped (listed as not fitted) when the training data hold fewer
    than 4 velocity reversals."""
    dropped: list[str] = []
    ctx.plateaus = plateaus = [p for r in ctx.records for p in find_plateaus(r, dropped=dropped)]
    if dropped:
        shown = "; ".join(dropped[:8]) + (f"; and {len(dropped) - 8} more" if len(dropped) > 8 else "")
        ctx.warnings.append(f"{len(dropped)} of {len(dropped) + len(plateaus)} plateaus left out: {shown}")
    chatter = chattering_plateaus(plateaus)
    if chatter:
        worst = max(p.torque_std / max(abs(p.torque), 1e-300) for p in chatter)
        r0 = ctx.records[0]
        res_note = f" ({r0.resolution:.3g} per count)" if r0.resolution > 0 else ""
        ctx.warnings.append(
            f"the velocity loop chattered on {len(chatter)} of {len(plateaus)} plateaus (torque scatter up to "
            f"{worst:.1f} times the mean): their mean torque is not the friction at that speed, so every map "
            f"fitted to them is suspect; a coarse encoder{res_note} or loop gains too high for it"
        )
    ctx.breakaways = [b for r in ctx.records for b in find_breakaways(r)]
    if note := imprecise_breakaways(ctx.breakaways):
        ctx.warnings.append(note)
    records = ctx.records
    ctx.excitation = excitation(records[0] if len(records) == 1 else concat_records(records), plateaus)
    if note := one_direction_note(ctx.excitation):
        ctx.warnings.append(note)
    if any(spec_for(n).dynamic for n in ctx.names if n not in LEARNED):
        ex_train = excitation(concat_records(ctx.train), [])
        if ex_train.reversals < 4:
            why = (
                f"too little excitation in the {ctx.options.train_seconds:g} s training window: "
                f"{ex_train.reversals} velocity reversals, need >= 4 for presliding dynamics (run ABB M19-S paper's "
                "'random' excitation, or lower/raise --train-seconds)"
            )
            dynamic = [n for n in ctx.names if n not in LEARNED and spec_for(n).dynamic]
            ctx.skipped.update(dict.fromkeys(dynamic, why))
            ctx.names = [n for n in ctx.names if n not in dynamic]
            ctx.warnings.append(f"dynamic models not fitted ({', '.join(dynamic)}): {why}")


def choose_load_terms(ctx: FitContext) -> None:
    """The load terms (``load`` option, :func:`~friction_ros.core.identification.fit.load_terms.terms_for_fit`);
    with load friction, the torque the gear transmits. Then the validation data in one record, its
    high/low velocity masks, the scored samples (long standstills are not: at rest the friction is
    whatever torque holds the joint) and the steady-state velocity grid."""
    o = ctx.options
    ctx.terms, ctx.selection = terms_for_fit(
        o.load, ctx.plateaus, ctx.train, ctx.val, o.ripple_period, o.load_eps, ctx.eps, o.joint_type
    )
    if ctx.terms.load_friction:  # the torque the gear transmits, from the selection backbone
        tr = (ctx.selection.inertia, ctx.selection.joint_load)
        ctx.train, ctx.val = with_transmitted(ctx.train, *tr), with_transmitted(ctx.val, *tr)
        ctx.val_from = [
            (r, keep)
            for r, keep in zip(
                with_transmitted([f for f, _ in ctx.val_from], *tr), [k for _, k in ctx.val_from]
            )
        ]
    vall = ctx.vall = concat_records(ctx.val)
    mv = moving_mask(vall.velocity, vall.resolution, vall.dt)
    hm, ctx.high_threshold = high_velocity_mask(vall.velocity, vall.dt, o.high_threshold, moving=mv)
    ctx.high_mask, ctx.low_mask = hm, mv & ~hm
    ctx.scored = ~np.concatenate(
        [standstill_mask(full.velocity, full.resolution, full.dt)[keep] for full, keep in ctx.val_from]
    )
    ctx.grid = velocity_grid(ctx.records)
