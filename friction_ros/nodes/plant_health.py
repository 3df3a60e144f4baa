"""The plant_simulator's health: its diagnostics status and its loop statistics (rate, overruns,
missed commands, state-to-command latency), as a mixin of :class:`~friction_ros.nodes.plant_simulator.PlantSimulator`."""

from __future__ import annotations

import math
import time

from friction_ros.nodes.diagnostics import ERROR, OK, WARN
from friction_ros.nodes.loops import LatencyHistogram, LoopStats


class PlantHealth:
    """Mixin: needs the plant node's ``sim`` (core PlantStepper), ``loop``, ``diag``, ``owner`` and parameters ``p``."""

    def _publish_diagnostics(self) -> None:
        sim = self.sim
        values = {
            "mode": self.p["mode"],
            "steps": sim.steps,
            "sim_time": self.plant.time,
            "commands_rejected": sim.commands_rejected,
            "commands_ignored": sim.commands_ignored,
            **sim.rejections.values(),
        }
        if self.multi:
            values["unknown_joint_names"] = sim.unknown_names
        level, text = OK, "running"
        if self.loop is not None:
            s = self.loop.stats
            values.update(
                cycles=s.cycles,
                overruns=s.overruns,
                missed_commands=sim.missed,
                max_lateness_s=s.max_lateness,
            )
            fresh = sim.fresh(time.monotonic(), self.p["command_timeout"])
            if not all(fresh):
                level = WARN
                if self.multi:
                    stale = ", ".join(j for j, f in zip(self.joints, fresh, strict=True) if not f)
                    text = f"no fresh command for {stale}: applying zero torque to them"
                else:
                    text = "no fresh command: applying zero torque"
            if self._latency.n:
                values.update(
                    latency_p50_s=self._latency.percentile(50), latency_p99_s=self._latency.percentile(99)
                )
        if self.multi:
            for i, j in enumerate(self.joints):
                values[f"{j}.preset"] = self.presets[i].name
                values[f"{j}.commands_rejected"] = sim.rejected_by_joint[i]
                if self.loop is not None:
                    values[f"{j}.command_fresh"] = fresh[i]
        new = sim.rejections.total - self._diag_rejected
        self._diag_rejected = sim.rejections.total
        if new:
            level = max(level, WARN)
            text = f"{new} joint_commands rejected since the last status (last: {sim.rejections.last_reason})"
        if self.owner.conflict:  # two command sources: the plant follows neither (zero torque)
            level, text = ERROR, self.owner.status() + ": following neither (zero torque)"
        self.diag.publish(level, text, values)

    def _reset_statistics(self) -> None:
        """Start the statistics window (once): missed commands, latency and loop timing from here."""
        self._stats_reset_at = math.inf  # once
        self.sim.missed = 0
        self._latency = LatencyHistogram()
        if self.loop is not None:
            self.loop.stats = LoopStats()
        self._stats_wall0 = time.monotonic()
        self._stats_steps0 = self.sim.steps
        self._stats_sim0 = self.plant.time

    def loop_statistics(self) -> dict:
        """Loop rate, overruns, missed commands and state-to-command latency percentiles.

        Rates and counts cover the statistics window (from the first command + ``stats_delay``);
        ``*_total`` figures cover the whole run including start-up.
        """
        now = time.monotonic()
        total = now - self._start_wall
        wall = now - self._stats_wall0
        out = {
            "mode": self.p["mode"],
            "steps": self.sim.steps,
            "sim_time": self.plant.time,
            "wall_time_total": total,
            "sim_seconds_per_wall_second_total": self.plant.time / total if total > 0 else 0.0,
            "window_wall_time": wall,
            "window_steps": self.sim.steps - self._stats_steps0,
            "sim_seconds_per_wall_second": (self.plant.time - self._stats_sim0) / wall if wall > 0 else 0.0,
            "commands_rejected": self.sim.commands_rejected,
        }
        if self.loop is not None:
            s = self.loop.stats
            out.update(
                cycles=s.cycles,
                overruns=s.overruns,
                missed_commands=self.sim.missed,
                rate_hz=s.cycles / wall if wall > 0 else 0.0,
                max_lateness_s=s.max_lateness,
                mean_lateness_s=s.total_lateness / s.cycles if s.cycles else 0.0,
            )
            if self._latency.n:
                out.update(
                    latency_samples=self._latency.n,
                    latency_p50_s=self._latency.percentile(50),
                    latency_p99_s=self._latency.percentile(99),
                    latency_max_s=self._latency.max,
                )
        return out
