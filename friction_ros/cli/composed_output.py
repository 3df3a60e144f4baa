"""Which node a line of a composed process is about (:mod:`friction_ros.nodes.composition`), so that
its output is labelled per node as if each node ran in its own process.

A line belongs to a node when it is one of its log lines (rcutils' default format
``[LEVEL] [time] [logger]: text``, logger ``namespace.name`` or a child ``namespace.name.child``)
or composition's ``error: LABEL: text`` (the node that refused to start; the prefix is removed, as
the node's own process prints ``error: text``). Other lines (a traceback, a continuation) belong
to the node of the line before; lines before any node's belong to the process.
"""

from __future__ import annotations

import re

_LOG_LINE = re.compile(r"^\[[A-Z]+\] \[[0-9.]+\] \[([^\]]+)\]: ")


class LineRouter:
    """Route the lines of one composed process: ``route(line) -> (label, text)``.

    ``labels``: the members' labels (``[namespace/]name``, as friction-bringup labels a node);
    ``process``: the process's own label. :attr:`last_error` is the label of the newest
    ``error:`` line (the node the process failed for), or None.
    """

    def __init__(self, labels: list[str], process: str):
        self.process = process
        self.current = process
        self.last_error: str | None = None
        self._by_logger = {lbl.replace("/", "."): lbl for lbl in labels}
        self._labels = sorted(labels, key=len, reverse=True)  # "ns/a_b" before "ns/a"

    def _of_logger(self, logger: str) -> str | None:
        while logger:
            if logger in self._by_logger:
                return self._by_logger[logger]
            logger = logger.rpartition(".")[0]
        return None

    def route(self, line: str) -> tuple[str, str]:
        m = _LOG_LINE.match(line)
        if m:
            self.current = self._of_logger(m.group(1)) or self.process
            return self.current, line
        if line.startswith("error: "):
            rest = line[len("error: ") :]
            label = next((lbl for lbl in self._labels if rest.startswith(f"{lbl}: ")), None)
            if label is not None:
                self.current = self.last_error = label
                return label, "error: " + rest[len(label) + 2 :]
            self.last_error = self.current
        return self.current, line
