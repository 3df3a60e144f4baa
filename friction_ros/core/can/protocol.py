"""Drive protocols: the interface between :class:`~friction_ros.core.can.axis.DriveAxis` and the wire.

Modelled on python-can's interface registry: a small base class per side of the bus and a registry of
names. :class:`DriveProtocol` is the host side (what ``drive_interface`` sends and receives for one
drive); :class:`EmulatedDriveProtocol` is the drive side (what the frame-level emulator answers). A
protocol is one module defining both and registering them::

    register_drive_protocol("my_protocol", MyProtocol)   # MyProtocol.emulated = MyEmulatedDrive

or, from another distribution, the entry point group ``friction_ros.drive_protocols``
(``my_protocol = my_package.module:MyProtocol``). :func:`protocol_names` lists the built-ins
(``odrive_cansimple``, ``mit``, ``cia402``), then entry points, then run-time registrations; both are loaded on
first use.

Units: a protocol reports and takes motor-side SI values (rad, rad/s, N*m, A, V; m and N for a
linear motor); :class:`~friction_ros.core.can.joint.JointConversion` in DriveAxis turns them into
joint values. Safety (watchdog, limits, stale telemetry, faults, telemetry gate) stays in DriveAxis.
"""

from __future__ import annotations

import importlib
import math
import threading
from collections.abc import Callable, Sequence
from importlib import metadata
from typing import TYPE_CHECKING, Any, NamedTuple

from friction_ros.core.can.frame import DecodeStats, Frame, SafeDecoder
from friction_ros.core.validation import ParameterError

if TYPE_CHECKING:
    from friction_ros.core.can.axis_config import AxisConfig
    from friction_ros.core.can.emulator import DriveEmulator, EmulatorConfig

ENTRY_POINT_GROUP = "friction_ros.drive_protocols"
BUILTIN = {
    "odrive_cansimple": "friction_ros.core.can.odrive_protocol:OdriveProtocol",
    "mit": "friction_ros.core.can.mit_protocol:MitProtocol",
    "cia402": "friction_ros.core.can.cia402.protocol:Cia402Protocol",
}
MOTION_PAIR = 0  # float_pairs(): (position, velocity) x motion_scale -> motor rad, rad/s
CURRENT_PAIR = 1  # float_pairs(): (current setpoint, measured) [A]
MOTION_REPORT = 2  # fast_reports(): (position, velocity, current) motor rad, rad/s, A
EFFORT_REPORT = 3  # fast_reports(): (torque [N*m], state, error)


class DriveTelemetry(NamedTuple):
    """What one received frame reports, motor side, SI; None = not in this frame.

    ``torque`` is the drive's torque estimate, ``current`` the measured q current; a frame with
    position and torque (one reply carrying both) passes the telemetry gate as one reading.
    """

    position: float | None = None  # rad (m)
    velocity: float | None = None  # rad/s (m/s)
    torque: float | None = None  # N*m (N), estimate
    torque_target: float | None = None  # N*m (N)
    current: float | None = None  # A, measured
    current_setpoint: float | None = None  # A
    bus_voltage: float | None = None  # V
    error: int | None = None  # drive fault code (0 = none)
    state: int | None = None  # drive state code (see DriveProtocol.closed_loop)


class DriveProtocol:
    """Host side of one drive's protocol (one instance per axis, built from its AxisConfig).

    Subclasses set :attr:`decoder` (a :class:`~friction_ros.core.can.frame.SafeDecoder`, whose stats
    are the axis' decode statistics) and implement :meth:`decode`, :meth:`torque_frame`,
    :meth:`enable_frames`, :meth:`disable_frames` and :meth:`receive_filters`; the rest has defaults.
    """

    name = ""
    emulated: type[EmulatedDriveProtocol] | None = None  # the drive side, for the emulator
    reports_state = True  # False: no state report; DriveAxis shows 1 (enabled) / 0, no closed-loop check
    motion_scale = 1.0  # float_pairs(): motor rad per wire unit of position and velocity

    def __init__(self, cfg: AxisConfig):
        self.cfg = cfg
        self.decoder: SafeDecoder = SafeDecoder()

    # ---- configuration (class level: used before an axis exists) ------------------------------------
    @classmethod
    def check_config(cls, cfg: AxisConfig) -> None:
        """Raise ParameterError (one line naming the value and what is allowed) for bad ids etc."""

    @classmethod
    def position_range(cls, cfg: AxisConfig) -> tuple[float, float]:
        """(largest |motor position| the wire carries, its resolution) [rad]; default (inf, 0)."""
        return math.inf, 0.0

    def reconfigure(self, cfg: AxisConfig) -> None:
        """A run-time parameter change (the read-only ones, protocol and ids, stay as they were)."""
        self.cfg = cfg

    @property
    def effort_source(self) -> str:
        """Where the joint effort comes from: ``current`` (q current x k_t) or ``torque_estimate``."""
        return self.cfg.effort_source

    # ---- receive ----------------------------------------------------------------------------------
    @property
    def stats(self) -> DecodeStats:
        return self.decoder.stats

    def decode(
        self, arb_id: int, data: bytes, is_remote: bool, is_extended: bool, is_error: bool
    ) -> DriveTelemetry | None:
        """One received frame -> what it reports, or None (ignored or rejected, counted in stats)."""
        raise NotImplementedError

    def receive_filters(self) -> list[dict]:
        """python-can ``can_filters`` entries passing this drive's frames (kernel filters)."""
        raise NotImplementedError

    def gated_ids(self) -> dict[int, str]:
        """Arbitration id -> telemetry gate channel (``motion``/``effort``) for frames that must
        decode: a rejected one counts as an implausible report of that channel."""
        return {}

    def float_pairs(self) -> dict[int, int]:
        """Hot path: ids whose payload is two little-endian float32, ``MOTION_PAIR`` (x
        :attr:`motion_scale`) or ``CURRENT_PAIR`` (A); DriveAxis decodes these inline."""
        return {}

    def fast_reports(self) -> dict[int, tuple[int, Callable[[bytes], tuple | None]]]:
        """Hot path of other telemetry frames of every period: id -> (``MOTION_REPORT`` or
        ``EFFORT_REPORT``, handler). ``handler(data)`` (never called for RTR, extended or error
        frames) decodes a frame as :meth:`decode` would, without counting it, and returns the report
        as that plain tuple (motor side, SI); or returns None, untouched, to leave the frame to
        :meth:`decode`. DriveAxis stores the tuple as it stores the same DriveTelemetry."""
        return {}

    def route_key(self, arb_id: int, data: bytes) -> int | None:
        """Several drives on one bus: the key of the drive a received frame comes from."""
        return None

    @property
    def own_route_key(self) -> int:
        """This drive's :meth:`route_key`."""
        return self.cfg.node_id

    def closed_loop(self, state: int) -> bool:
        """True when the reported drive state means torque control is active."""
        return True

    def state_name(self, state: int) -> str:
        return str(state)

    def error_text(self, code: int) -> str:
        """Words for a drive fault code, added to the fault line; default none."""
        return ""

    # ---- send -------------------------------------------------------------------------------------
    def startup_frames(self) -> list[Frame]:
        """Frames sent once when the bus opens (e.g. network management); default none."""
        return []

    def enable_frames(self) -> list[Frame]:
        """Clear errors, send the limits of :attr:`cfg`, zero torque, enter torque control."""
        raise NotImplementedError

    def disable_frames(self) -> list[Frame]:
        """Zero torque, then leave torque control (sent on disable, every fault and shutdown)."""
        raise NotImplementedError

    def quick_stop_frames(self) -> list[Frame]:
        """Stop now (the drive's emergency stop if it has one); default :meth:`disable_frames`."""
        return self.disable_frames()

    def torque_frame(self, motor_torque: float) -> Frame:
        """The command of one period: motor torque [N*m] (finite, already limited)."""
        raise NotImplementedError

    def poll_frames(self, enabled: bool) -> Sequence[Frame]:
        """Telemetry requests sent every period after the torque command (or alone, disabled)."""
        return ()

    def cycle_frames(self, t: float) -> list[Frame]:
        """Other frames sent every period at time ``t`` (e.g. a CANopen SYNC); default none."""
        return []


class EmulatedDriveProtocol:
    """Drive side of a protocol, inside :class:`~friction_ros.core.can.emulator.DriveEmulator`.

    ``drive`` gives the motor-side measurements (``motor_position``, ``motor_velocity``,
    ``motor_torque_measured``, ``applied_torque``), ``axis_error`` (shared) and ``cfg``. The emulator
    owns the plant, time, latency, loss and silence; this class owns the drive's state machine.
    """

    def __init__(self, drive: DriveEmulator):
        self.drive = drive
        self.decoder: SafeDecoder = SafeDecoder()

    @classmethod
    def check_config(cls, cfg: EmulatorConfig) -> None:
        """Raise ParameterError for ids this protocol cannot carry."""

    def cyclic(self) -> list[tuple[float, Any]]:
        """``(rate_hz, key)`` of the frames sent on their own; :meth:`telemetry_frame` builds them."""
        return []

    def telemetry_frame(self, key: Any) -> Frame:
        raise NotImplementedError

    def handle(self, msg: Any, t: float) -> list[Frame]:
        """React to one decoded command; returns the replies to transmit."""
        raise NotImplementedError

    @property
    def armed(self) -> bool:
        """True while the drive applies torque (torque control entered, no error)."""
        raise NotImplementedError

    def motor_torque(self) -> float:
        """Motor torque the drive applies now [N*m] (0 when not armed)."""
        raise NotImplementedError

    def fault(self) -> None:
        """An error was raised: leave torque control as the real drive does."""

    @property
    def position_offset(self) -> float:
        """Motor position the drive reports as zero [rad] (a set-zero command moves it)."""
        return 0.0


# ---- registry ------------------------------------------------------------------------------------
_lock = threading.Lock()
_registered: dict[str, type[DriveProtocol] | str] = {}
_entry_points_loaded = False


def register_drive_protocol(name: str, cls: type[DriveProtocol]) -> None:
    """Make ``cls`` (a DriveProtocol subclass) available as protocol ``name``."""
    if not (isinstance(cls, type) and issubclass(cls, DriveProtocol)):
        raise TypeError(f"drive protocol {name!r}: {cls!r} is not a DriveProtocol subclass")
    with _lock:
        _registered[name] = cls
    cls.name = cls.name or name


def _load_entry_points() -> None:
    global _entry_points_loaded
    if _entry_points_loaded:
        return
    _entry_points_loaded = True
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        _registered.setdefault(ep.name, ep.value)


def protocol_names() -> tuple[str, ...]:
    """Registered protocol names: built-ins, entry points, then run-time registrations."""
    with _lock:
        _load_entry_points()
        return (*BUILTIN, *(n for n in _registered if n not in BUILTIN))


def drive_protocol(name: str) -> type[DriveProtocol]:
    """The protocol class registered as ``name``; ParameterError listing the names if unknown."""
    with _lock:
        _load_entry_points()
        target = _registered.get(name, BUILTIN.get(name))
    if target is None:
        raise ParameterError(
            f"protocol = {name!r} is not allowed: must be one of {', '.join(protocol_names())}"
        )
    if isinstance(target, str):
        module, _, attr = target.partition(":")
        try:
            cls = getattr(importlib.import_module(module), attr)
        except (ImportError, AttributeError) as exc:
            raise ParameterError(f"protocol = {name!r} cannot be loaded from {target}: {exc}") from None
        register_drive_protocol(name, cls)
        return cls
    return target


class ProtocolNames(Sequence):
    """The registered names, read when used: ``choices`` of a parameter or an argparse option, so
    a protocol registered after import appears in help texts and allowed values."""

    def __getitem__(self, i):
        return protocol_names()[i]

    def __len__(self) -> int:
        return len(protocol_names())

    def __contains__(self, name) -> bool:
        return name in protocol_names()

    def __repr__(self) -> str:
        return repr(protocol_names())


PROTOCOLS = ProtocolNames()
