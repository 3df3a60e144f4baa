"""Disk full while writing a bag: which errors, which disk, and space kept back to close the bag.

A full disk shows as ``ENOSPC`` (no space left), ``EDQUOT`` (the user's quota) or ``EFBIG`` (a file
size limit, e.g. ``ulimit -f``, with SIGXFSZ ignored). Closing a bag then still needs room for its
MCAP summary and metadata.yaml, so the writer keeps a :class:`SpaceReserve`: a file of real
(allocated, incompressible) blocks next to the bag, deleted when the disk fills. Its size follows
the summary's: twice the schemas, channels and chunk indexes registered so far plus 64 KiB, rounded
up to a power of two (at least 256 KiB).
"""

from __future__ import annotations

import errno
import os
from pathlib import Path

DISK_FULL = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
_WHAT = {
    errno.ENOSPC: "no space left",
    errno.EDQUOT: "disk quota exceeded",
    errno.EFBIG: "file size limit reached",
}
_ADVICE = {errno.EFBIG: "raise the file size limit (ulimit -f) or record to another disk"}
MIN_RESERVE = 256 * 1024
CHUNK_INDEX_BYTES = 256  # summary bytes per chunk (chunk index with a few channels), generous


def is_disk_full(exc: BaseException) -> bool:
    return isinstance(exc, OSError) and exc.errno in DISK_FULL


def mount_point(path: str | os.PathLike) -> Path:
    """The mount point of the file system holding ``path`` (the highest parent on the same device)."""
    p = Path(path).resolve()
    while not p.exists() and p != p.parent:
        p = p.parent
    dev = p.stat().st_dev
    while p != p.parent and p.parent.stat().st_dev == dev:
        p = p.parent
    return p


def describe(exc: OSError, path: str | os.PathLike) -> str:
    """``"no space left on /mnt/data (2.0 MiB file system, 0 B free)"``: the error and the disk."""
    where = mount_point(path)
    if exc.errno == errno.EFBIG:  # a limit on one file's size: the disk's free space does not matter
        return f"{_WHAT[exc.errno]} on {where}"
    try:
        st = os.statvfs(where)
        size = f" ({_size(st.f_blocks * st.f_frsize)} file system, {_size(st.f_bavail * st.f_frsize)} free)"
    except OSError:
        size = ""
    return f"{_WHAT.get(exc.errno, exc.strerror)} on {where}{size}"


def advice(exc: OSError) -> str:
    """What the user can do about ``exc``."""
    return _ADVICE.get(exc.errno, "free space there or record to another disk")


def _size(n: int) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return ""


def reserve_size(summary_bytes: int) -> int:
    """Reserve for a summary of about ``summary_bytes``: 2 x + 64 KiB, next power of two, >= 256 KiB."""
    need = 2 * summary_bytes + 65536
    return max(MIN_RESERVE, 1 << (need - 1).bit_length())


class SpaceReserve:
    """A file of ``size`` allocated bytes at ``path``; :meth:`release` deletes it to free the space."""

    def __init__(self, path: Path, size: int = MIN_RESERVE):
        self.path = path
        self.size = 0
        self.grow(size)

    def grow(self, size: int) -> None:
        """Enlarge to ``size`` bytes (OSError when the disk is full: the caller closes the bag)."""
        if size <= self.size:
            return
        with open(self.path, "ab") as f:
            try:
                os.posix_fallocate(f.fileno(), 0, size)
            except OSError as exc:
                if exc.errno in DISK_FULL:
                    raise
                f.seek(0, os.SEEK_END)  # no fallocate here: write incompressible bytes
                for done in range(f.tell(), size, 65536):
                    f.write(os.urandom(min(65536, size - done)))
        self.size = size

    def release(self) -> None:
        self.path.unlink(missing_ok=True)
        self.size = 0
