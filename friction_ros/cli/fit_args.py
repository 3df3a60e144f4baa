"""friction-fit's command line -> the fit's arguments: the fit's options
(:class:`~friction_ros.core.identification.fit.fit_options.FitOptions`), fit_bag's own keyword
arguments (reading the logs, the outputs) and the safety gate's lags."""

from __future__ import annotations


def gate_options(args) -> dict:
    """The safety gate's lags: given, else the plant preset's (as the demo uses), else 0 with a warning
    (the gate's verdicts depend on them)."""
    lags = {"current_lag": args.current_lag, "delay": args.delay}
    if args.plant_preset:
        from friction_ros.core.identification.fit.gating import preset_lags
        from friction_ros.core.presets import load_preset

        known = preset_lags(load_preset(args.plant_preset))
        lags = {k: known[k] if v is None else v for k, v in lags.items()}
        if args.current_lag is None and args.delay is None:
            lags["velocity_filter_hz"] = known["velocity_filter_hz"]
    missing = [f"--{k.replace('_', '-')}" for k, v in lags.items() if v is None]
    lags = {k: 0.0 if v is None else v for k, v in lags.items()}
    if missing:
        lags["assumed"] = (
            f"the safety gate assumed {' and '.join(missing)} 0 (not given): its verdicts hold only for a drive "
            "without current-loop lag or delay; give your drive's values"
        )
    return lags


def fit_options(args):
    """The fit's options (:class:`~friction_ros.core.identification.fit.fit_options.FitOptions`) from
    the command line; a bad value is refused naming its command-line option."""
    from friction_ros.core.identification.fit.fit_options import FitOptions
    from friction_ros.core.validation import ParameterError

    given = dict(
        train_seconds=args.train_seconds,
        train_window=args.train_window,
        optimizer=args.optimizer,
        maxiter=args.maxiter,
        seed=args.seed,
        eps=args.eps,
        high_threshold=args.high_threshold,
        load=args.load,
        ripple_period=args.ripple_period,
        residual=args.residual,
        max_samples=args.max_samples or None,
    )
    try:
        return FitOptions(**given)
    except ParameterError as exc:  # "train_seconds = ..." -> "--train-seconds = ..."
        text = str(exc)
        name = next((n for n in given if text.startswith(f"{n} = ")), None)
        if name is None:
            raise
        raise ParameterError("--" + name.replace("_", "-") + text[len(name) :]) from None


def log_options(args, columns) -> dict:
    """fit_bag's own keyword arguments from the command line (reading the logs, the gate, the
    outputs): all but the fit's options, the output paths and progress."""
    return dict(
        events_topic=args.events_topic,
        current_topic=args.current_topic,
        current_field=args.current_field,
        torque_constant=args.torque_constant,
        gear_ratio=args.gear_ratio,
        plots=not args.no_plots,
        torque_delay=args.torque_delay,
        plant_preset=args.plant_preset,
        gate=None if args.no_gate else gate_options(args),
        columns=columns,
        time_scale=args.time_scale,
        cross_validate=args.cross_validate,
        validate_on=args.validate_on,
        joint_type=args.joint_type,
    )
