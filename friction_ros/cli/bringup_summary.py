"""What friction-bringup prints around a run: the plan (each node process with its namespace, name,
parameter files, remappings and parameter overrides) and, at the end, one line per controller node
from the last diagnostics status of each of its joints (level and text, and the compensation state:
which source compensates, on how many joints, any fallback).

The summary's listener is one rclpy node in friction-bringup's process, spun on its own thread,
subscribed to the ``diagnostics`` topic of each namespace holding a controller (one message per
node per ``diagnostics_period``, 1 s by default): nothing in the nodes' control path waits for it.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence

LEVELS = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}
CONTROLLER = "compensating_controller"


def _members(specs: Sequence) -> list:
    out = []
    for s in specs:
        out += list(getattr(s, "members", None) or [s])
    return out


def plan_lines(specs: Sequence) -> list[str]:
    """One line per node (a composed process first names itself, its nodes indented below)."""

    def node_line(s, indent: str) -> str:
        ns = "/" + s.namespace.strip("/") if s.namespace else "/"
        parts = [f"{indent}{s.label}: {s.node}, namespace {ns}, name {s.name or s.node}"]
        parts.append("params " + (", ".join(str(p) for p in s.params) if s.params else "none"))
        if s.remaps:
            parts.append("remap " + ", ".join(f"{a}:={b}" for a, b in s.remaps.items()))
        if s.overrides:
            parts.append("set " + ", ".join(f"{k}={_value(v)}" for k, v in s.overrides.items()))
        return "; ".join(parts)

    lines = []
    for s in specs:
        members = getattr(s, "members", None)
        if members:
            lines.append(f"  one process, one executor ({len(members)} nodes):")
            lines += [node_line(m, "    ") for m in members]
        else:
            lines.append(node_line(s, "  "))
    return lines


def _value(v) -> str:
    """A parameter value as on a ROS command line (``true``, not ``True``)."""
    return ("true" if v else "false") if isinstance(v, bool) else str(v)


def controller_names(specs: Sequence) -> dict[str, str]:
    """{fully qualified node name: label} of the controller nodes."""
    out = {}
    for s in _members(specs):
        if s.node == CONTROLLER:
            ns = s.namespace.strip("/")
            out[(f"/{ns}" if ns else "") + f"/{s.name or s.node}"] = s.label
    return out


class DiagnosticsWatch:
    """The last diagnostics status per status name of the controller nodes (module docstring)."""

    def __init__(self, specs: Sequence):
        self.nodes = controller_names(specs)
        self.last: dict[str, tuple[int, str, dict[str, str]]] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._node = self._executor = None
        self._own_context = False

    def start(self) -> None:
        if not self.nodes:
            return
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        from friction_ros.nodes.qos import STATE_QOS

        if not rclpy.ok():  # friction-bringup keeps its own Ctrl-C handling (controllers stop first)
            rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
            self._own_context = True
        self._node = rclpy.create_node("friction_bringup_summary")
        for ns in sorted({name.rsplit("/", 1)[0] for name in self.nodes}):
            self._node.create_subscription(DiagnosticArray, f"{ns}/diagnostics", self._on_array, STATE_QOS)
        self._executor = SingleThreadedExecutor()
        self._executor.add_node(self._node)
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not self._stop.is_set():
            self._executor.spin_once(timeout_sec=0.1)

    def _on_array(self, msg) -> None:
        with self._lock:
            for st in msg.status:
                level = st.level[0] if isinstance(st.level, bytes) else int(st.level)
                self.last[st.name] = (level, st.message, {kv.key: kv.value for kv in st.values})

    def stop(self) -> None:
        if self._thread is None:
            return
        self._stop.set()
        self._thread.join(timeout=2)
        self._node.destroy_node()
        if self._own_context:
            import rclpy

            rclpy.try_shutdown()

    def summary_lines(self) -> list[str]:
        """One line per controller node: ``<label>: <LEVEL> <text>; compensation ...``."""
        with self._lock:
            last = dict(self.last)
        lines = []
        for full, label in self.nodes.items():
            own = {n: v for n, v in last.items() if n == full or n.startswith(full + "/")}
            if not own:
                lines.append(f"{label}: no diagnostics received")
                continue
            lines.append(f"{label}: {_describe(full, own)}")
        return lines


def _describe(full: str, own: dict[str, tuple[int, str, dict[str, str]]]) -> str:
    """Worst level, its text (and joints), and the compensation state over the node's statuses."""
    worst = max(level for level, _, _ in own.values())
    joint = {n: n[len(full) + 1 :] or "-" for n in own}
    texts: dict[str, list[str]] = {}
    for n, (level, text, _) in own.items():
        if level == worst:
            texts.setdefault(text, []).append(joint[n])
    several = len(own) > 1
    shown = "; ".join(
        f"{t}" + (f" ({', '.join(js)})" if several and len(texts) > 1 else "") for t, js in texts.items()
    )
    sources: dict[str, list[str]] = {}
    off, fallback = [], []
    for n, (_, _, values) in own.items():
        sources.setdefault(values.get("compensation", "?"), []).append(joint[n])
        if values.get("compensation_enabled") == "0":
            off.append(joint[n])
        if values.get("compensation_fallback") == "1":
            fallback.append(joint[n])
    if several:
        state = ", ".join(f"{s} on {len(js)} of {len(own)} joints" for s, js in sources.items())
    else:
        state = next(iter(sources))
    extra = ""
    if off:
        extra += f"; switched off: {', '.join(off)}"
    if fallback:
        extra += f"; fell back to none: {', '.join(fallback)}"
    return f"{LEVELS.get(worst, str(worst))} {shown}; compensation {state}{extra}"
