"""A CAN frame as plain data (no python-can dependency) and decode statistics shared by the codecs."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple


class Frame(NamedTuple):
    """One classic CAN frame: 11-bit (or 29-bit) id, payload bytes, remote (RTR) flag.

    ``dlc`` is the data length code; for data frames it equals ``len(data)``, for RTR frames it is
    the length requested (the payload is empty).
    """

    arbitration_id: int
    data: bytes
    is_remote: bool = False
    is_extended: bool = False
    dlc: int | None = None

    @property
    def length(self) -> int:
        return len(self.data) if self.dlc is None else self.dlc


@dataclass
class DecodeStats:
    """Counters of a decoder: every frame offered is counted exactly once in one of three bins.

    * ``decoded``: a supported message for one of our ids, well formed -> a message object.
    * ``ignored``: not for us (other node/protocol id, extended id, error frame, unsupported command).
    * ``rejected``: addressed to us with a supported command but malformed (wrong length, NaN/inf,
      out-of-range field).
    """

    decoded: int = 0
    ignored: int = 0
    rejected: int = 0
    last_reject_reason: str = ""

    @property
    def total(self) -> int:
        return self.decoded + self.ignored + self.rejected

    def as_dict(self) -> dict[str, int | str]:
        return {
            "decoded": self.decoded,
            "ignored": self.ignored,
            "rejected": self.rejected,
            "last_reject_reason": self.last_reject_reason,
        }


class SafeDecoder:
    """Base of the protocol decoders: ``decode`` never raises; every frame is counted.

    Subclasses implement ``_decode(arb_id, data, is_remote, is_extended, is_error)`` returning a
    message or None (after ``_ignore()``/``_reject(reason)``); an unexpected exception in it counts
    as a rejected frame with the exception as the reason, so a malformed frame cannot take a node down.
    """

    def __init__(self) -> None:
        self.stats = DecodeStats()

    def _reject(self, reason: str) -> None:
        self.stats.rejected += 1
        self.stats.last_reject_reason = reason

    def decode(
        self,
        arb_id: int,
        data: bytes,
        is_remote: bool = False,
        is_extended: bool = False,
        is_error: bool = False,
    ):
        """Return a message NamedTuple, or None when the frame is ignored or rejected."""
        try:
            return self._decode(arb_id, data, is_remote, is_extended, is_error)
        except Exception as exc:  # defensive: a decoder must never take the node down
            self._reject(f"id 0x{arb_id & 0x1FFFFFFF:X}: {type(exc).__name__}: {exc}")
            return None

    def decode_frame(self, frame: Frame):
        """:meth:`decode` of a :class:`Frame`."""
        return self.decode(frame.arbitration_id, frame.data, frame.is_remote, frame.is_extended)

    def _decode(self, arb_id, data, is_remote, is_extended, is_error):  # pragma: no cover
        raise NotImplementedError
