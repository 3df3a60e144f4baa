"""QoS profiles of the friction_ros topics (documented in README "Interfaces").

* ``COMMAND_QOS``: reliable, keep-last **1**. A queued stale torque command is a safety bug
  (ros_odrive #32): the newest command is the only one that matters.
* ``STATE_QOS``: reliable, keep-last 10. Joint states, controller/estimator states and events are
  recorded for identification, so they must not be dropped under load; the depth absorbs bursts.
* ``RECORDED_QOS``: reliable, keep-last 5000, for the *publishers* of topics that are recorded or
  evaluated (joint states, controller state, estimates, events). A reliable keep-last writer drops
  what a slow reader has not acknowledged once its history is full, so the writer's depth is what
  decides whether a recorder or an evaluator that falls behind (CPU contention, a burst) loses
  samples: 5000 periods is 5 s at 1 kHz. Subscribers that control keep STATE_QOS (a controller
  must not work through a backlog of stale states).
* ``LOCKSTEP_RECORDED_QOS``: RECORDED_QOS 60,000 deep, for the joint states of a lockstep plant. A
  lockstep graph runs as fast as its CPU allows and no recorder paces it: on a busy machine a
  recorder in another process fell more than 5000 states behind a plant and experiment composed in
  one process (1329 states lost in a 108 s run). The history holds what is not acknowledged, so
  the memory is spent only while a reader lags (~0.2 kB a state).
* ``SENSOR_QOS``: best effort, keep-last 5 (rclpy's sensor-data profile) for high-rate telemetry
  that may be lost (raw drive state).
* ``LATCHED_QOS``: reliable, transient-local depth 1 for coefficients that late joiners need.
"""

from __future__ import annotations

from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)

from friction_ros.core.bag.recording import subscription_qos

COMMAND_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
STATE_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=10,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
RECORDED_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=5000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
LOCKSTEP_RECORDED_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=60_000,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)
SENSOR_QOS = qos_profile_sensor_data
LATCHED_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.TRANSIENT_LOCAL,
)


def recording_qos(publishers, depth: int) -> QoSProfile:
    """A recorder's subscription QoS for a topic's publishers (``get_publishers_info_by_topic``):
    :func:`friction_ros.core.bag.recording.subscription_qos` of what they offer, as an rclpy profile."""
    offered = [
        (
            i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT,
            i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL,
        )
        for i in publishers
    ]
    q = subscription_qos(offered, depth)
    return QoSProfile(
        history=HistoryPolicy.KEEP_ALL if q["keep_all"] else HistoryPolicy.KEEP_LAST,
        depth=q["depth"],
        reliability=ReliabilityPolicy.RELIABLE if q["reliable"] else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if q["transient_local"] else DurabilityPolicy.VOLATILE,
    )
