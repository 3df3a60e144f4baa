"""A non-blocking sequence of expedited SDO transfers (CiA 301 7.2.4.3), driven once per period.

One request is outstanding at a time; ``poll(t)`` returns the next request frame (or a retry after
``timeout``), ``on_response(data)`` takes the drive's answer. Uploaded values land in ``values``.
An abort or ``retries`` timeouts end the script with ``error`` set to one line naming the object.
"""

from __future__ import annotations

from typing import NamedTuple

from friction_ros.core.can.cia402 import frames as fr
from friction_ros.core.can.cia402 import objects as ob
from friction_ros.core.can.frame import Frame


class SdoStep(NamedTuple):
    index: int
    subindex: int
    value: int | None = None  # None: upload (read)
    size: int = 4
    signed: bool = False

    @property
    def name(self) -> str:
        return f"0x{self.index:04X}:{self.subindex:02X}"


class SdoScript:
    def __init__(self, node_id: int, steps: list[SdoStep], timeout: float = 0.1, retries: int = 3):
        self.node_id = node_id
        self.steps = list(steps)
        self.timeout = timeout
        self.retries = retries
        self.values: dict[tuple[int, int], int] = {}
        self.error = ""
        self._i = 0
        self._sent_at: float | None = None
        self._tries = 0

    @property
    def done(self) -> bool:
        return self._i >= len(self.steps) or bool(self.error)

    def extend(self, steps: list[SdoStep]) -> None:
        self.steps.extend(steps)

    def poll(self, t: float) -> Frame | None:
        if self.done:
            return None
        if self._sent_at is not None and t - self._sent_at < self.timeout:
            return None
        step = self.steps[self._i]
        if self._sent_at is not None:
            self._tries += 1
            if self._tries > self.retries:
                what = "reading" if step.value is None else "writing"
                self.error = f"SDO timeout {what} {step.name} on node {self.node_id} ({self._tries} tries)"
                return None
        self._sent_at = t
        if step.value is None:
            return fr.sdo_upload(self.node_id, step.index, step.subindex)
        return fr.sdo_download(self.node_id, step.index, step.subindex, step.value, step.size, step.signed)

    def on_response(self, data: bytes) -> None:
        if self.done or self._sent_at is None:
            return
        r = fr.decode_sdo_response(data)
        step = self.steps[self._i]
        if (r.index, r.subindex) != (step.index, step.subindex):
            return  # a late answer to an earlier (retried) request
        if r.kind == "abort":
            what = "reading" if step.value is None else f"writing {step.value} to"
            self.error = (
                f"drive node {self.node_id} refused {what} {step.name}: "
                f"SDO abort 0x{r.value:08X} ({ob.sdo_abort_text(r.value)})"
            )
            return
        if step.value is None and r.kind == "upload":
            self.values[(step.index, step.subindex)] = r.value
        elif not (step.value is not None and r.kind == "download"):
            return
        self._i += 1
        self._sent_at = None
        self._tries = 0
