"""Subscriptions that survive any payload: the one way every friction_ros node subscribes.

A subscription of a message type that rclpy deserialises in C fails *before* the node's callback,
in the executor, and ends the node; a raw subscription whose callback decodes with the project's
codec (:mod:`friction_ros.core.wire`, :mod:`friction_ros.core.bag.cdr`) raises ``CdrError`` inside
the callback and ends it as well. :func:`safe_subscription` subscribes raw (CDR bytes) and runs
decoding and the callback inside one guard:

* a payload that does not decode (garbage, truncated, empty, oversized, another type's bytes) is
  counted (:attr:`SafeSubscription.undecodable`) and logged as a WARN with the topic, the reason
  and the count, at most once a second; the node keeps running;
* a decoded message whose callback raises anything else is counted
  (:attr:`SafeSubscription.failed`) and logged as an ERROR with the exception, its text and where
  it was raised (file:line), at most once a second: a programming error stays visible in the log
  (and in tests) without ending the node.

``decode``: :data:`MESSAGE` (default: ``rclpy.serialization.deserialize_message`` into
``msg_type``, the callback gets the message object), :data:`BYTES` (the callback gets the CDR
bytes and decodes them itself, e.g. with ``JointStateDecoder``), or any ``bytes -> object``
function. A callback with two parameters also gets the message info (as rclpy gives it).
SIGINT/SIGTERM's :class:`~.stopping.StopRequested` is a BaseException and passes through.
"""

from __future__ import annotations

import inspect
import math
import os
import struct
import time
import traceback
from collections.abc import Callable
from typing import Any

from rclpy.node import Node
from rclpy.serialization import deserialize_message

from friction_ros.core.wire import WireDecodeError

MESSAGE = "message"  # decode: rclpy's deserialiser into msg_type
BYTES = None  # decode: none, the callback takes the CDR bytes
LOG_PERIOD_S = 1.0  # at most one log line per subscription and kind in this time

_DECODE_ERRORS = (WireDecodeError, struct.error, UnicodeDecodeError)


def _does_not_decode(exc: BaseException) -> bool:
    """A decoding failure: the project's codecs (``WireDecodeError``, of which the bag codec's
    ``CdrError`` is one), struct or UTF-8 errors, or rclpy's deserialiser (a RuntimeError whose text
    says so; rclpy exports no class for it)."""
    return isinstance(exc, _DECODE_ERRORS) or (
        isinstance(exc, RuntimeError) and str(exc).startswith("failed to deserialize")
    )


def _reason(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return text.split(", at /")[0]  # rclpy appends the C++ source location


def _where(exc: BaseException) -> str:
    frames = traceback.extract_tb(exc.__traceback__)
    if not frames:
        return ""
    f = frames[-1]
    return f" at {os.path.basename(f.filename)}:{f.lineno} in {f.name}"


def _takes_info(callback: Callable) -> bool:
    """Whether ``callback`` takes (message, message info), as rclpy decides it."""
    try:
        inspect.signature(callback).bind(object())
        return False
    except TypeError:
        return True


class SafeSubscription:
    """One guarded raw subscription (see the module docstring); ``subscription`` is rclpy's."""

    def __init__(
        self,
        node: Node,
        msg_type: Any,
        topic: str,
        callback: Callable,
        qos: Any,
        decode: str | Callable[[bytes], Any] | None = MESSAGE,
        **kwargs,
    ):
        self.logger = node.get_logger()
        self.undecodable = 0  # payloads that did not decode
        self.failed = 0  # decoded messages whose callback raised
        self._logged_at = {"undecodable": -math.inf, "failed": -math.inf}
        self._unlogged = {"undecodable": 0, "failed": 0}
        if decode == MESSAGE:
            decode = lambda data: deserialize_message(data, msg_type)  # noqa: E731
        self.topic = topic
        guarded = self._make_guard(callback, decode, _takes_info(callback))
        self.subscription = node.create_subscription(msg_type, topic, guarded, qos, raw=True, **kwargs)
        self.topic = self.subscription.topic_name

    def _make_guard(self, callback: Callable, decode, with_info: bool) -> Callable:
        if decode is None:  # the callback decodes: one try, nothing else on the hot path
            if with_info:

                def guard(data, info):
                    try:
                        callback(data, info)
                    except Exception as exc:  # noqa: BLE001 - the guard: see the module docstring
                        self._caught(exc, _does_not_decode(exc))

                return guard

            def guard(data):
                try:
                    callback(data)
                except Exception as exc:  # noqa: BLE001
                    self._caught(exc, _does_not_decode(exc))

            return guard

        def guard_decoded(data, *info):
            try:
                msg = decode(data)
            except Exception as exc:  # noqa: BLE001 - anything the decoder raises: it does not decode
                self._caught(exc, True)
                return
            try:
                callback(msg, *info)
            except Exception as exc:  # noqa: BLE001
                self._caught(exc, _does_not_decode(exc))

        if with_info:
            return lambda data, info: guard_decoded(data, info)
        return lambda data: guard_decoded(data)

    def report_undecodable(self, exc: BaseException) -> None:
        """Count and log a payload of this subscription that did not decode later, outside the
        callback (a node that keeps the bytes and decodes them in its control period)."""
        self._caught(exc, True)

    def _caught(self, exc: BaseException, undecodable: bool) -> None:
        kind = "undecodable" if undecodable else "failed"
        if undecodable:
            self.undecodable += 1
            n = self.undecodable
        else:
            self.failed += 1
            n = self.failed
        now = time.monotonic()
        if now - self._logged_at[kind] < LOG_PERIOD_S:
            self._unlogged[kind] += 1
            return
        self._logged_at[kind] = now
        more = self._unlogged[kind]
        self._unlogged[kind] = 0
        since = f", {more} more since the last report" if more else ""
        if undecodable:
            self.logger.warning(
                f"{self.topic}: ignored a message that does not decode ({_reason(exc)}); "
                f"{n} undecodable message(s) so far{since}; the node keeps running"
            )
        else:
            self.logger.error(
                f"{self.topic}: the callback raised {type(exc).__name__}: {_reason(exc)}{_where(exc)}; "
                f"{n} message(s) failed so far{since}; the node keeps running"
            )


def safe_subscription(
    node: Node,
    msg_type: Any,
    topic: str,
    callback: Callable,
    qos: Any,
    decode: str | Callable[[bytes], Any] | None = MESSAGE,
    **kwargs,
) -> SafeSubscription:
    """Subscribe ``node`` to ``topic`` so that no payload and no callback error ends it
    (:class:`SafeSubscription`); ``kwargs`` go to ``create_subscription`` (e.g. event_callbacks)."""
    return SafeSubscription(node, msg_type, topic, callback, qos, decode, **kwargs)
