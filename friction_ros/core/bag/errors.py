"""Errors of the bag I/O core.

Every error is a ``ValueError`` subclass whose message names the file/topic/type and the problem, so
nodes and CLIs can print one clear line instead of a traceback.
"""

from __future__ import annotations

from friction_ros.core.wire.cdr import WireDecodeError


class BagError(ValueError):
    """Base class: a bag cannot be read or written as requested."""


class NotMcapError(BagError):
    """The file is empty or not an MCAP file (bad magic bytes)."""


class TruncatedBagError(BagError):
    """The file is cut off before any readable message (e.g. header truncated)."""


class UnsupportedBagError(BagError):
    """Valid input in a format this reader does not handle (sqlite3 storage, file compression ...)."""


class DiskFullError(BagError):
    """Writing stopped because the disk is full (no space, quota or file size limit); the bag was
    closed with what reached the disk. ``kept``/``lost``: messages in the closed bag / not written;
    ``where``: the error and the disk (e.g. "no space left on /data"); ``advice``: what to do."""

    def __init__(self, message: str, kept: int = 0, lost: int = 0, where: str = "", advice: str = ""):
        super().__init__(message)
        self.kept, self.lost, self.where, self.advice = kept, lost, where, advice


class TopicNotFoundError(BagError, KeyError):
    """A requested topic is not in the bag."""

    def __str__(self) -> str:  # KeyError would otherwise quote the message
        return str(self.args[0]) if self.args else ""


class SchemaError(BagError):
    """A message definition is missing, unparsable, or does not match the expected type."""


class CdrError(BagError, WireDecodeError):
    """A CDR payload does not match its message definition."""


def check_wanted(path, want, skipped: dict, info: dict) -> None:
    """Every topic asked for (``want``, None = all) was found and decodes, else the error naming it."""
    for t in want or ():
        if t in skipped:
            raise SchemaError(f"{path}: topic {t} cannot be decoded: {skipped[t]}")
        if t not in info:
            raise TopicNotFoundError(
                f"{path}: topic {t} not found: topics are {', '.join(sorted(info)) or '(none)'}"
            )
