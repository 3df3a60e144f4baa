"""friction_local's receive filters on the raw can_id agree with python-can's own filter check."""

from __future__ import annotations

import random
import sys

import can

from friction_ros.can_bus.local_bus import LocalBus, RawFilter, pack_frame


def test_raw_filter_agrees_with_python_can_filters():
    """The raw-id filter passes exactly the frames python-can's own filter check passes: exact and
    masked, standard, extended and either, remote and error frames, no filters."""
    rng = random.Random(7)
    sets = [
        None,
        [{"can_id": 0x181 + k, "can_mask": 0x7FF, "extended": False} for k in range(5)],  # CiA 402
        [{"can_id": 2 << 5, "can_mask": 0x7E0, "extended": False}],  # ODrive
        [
            {"can_id": 0x1ABCDEF0, "can_mask": 0x1FFFFFFF, "extended": True},
            {"can_id": 0x29, "can_mask": 0x7FF},
        ],
        [{"can_id": 0x100, "can_mask": 0x700}],
    ]
    ids = [0x181, 0x185, 0x186, 0x040, 0x05F, 0x060, 0x029, 0x129, 0x1ABCDEF0, 0x0ABCDEF0]
    ids += [rng.randrange(0x800) for _ in range(200)] + [rng.randrange(1 << 29) for _ in range(50)]
    checked = passed = 0
    for filters in sets:
        bus = can.BusABC.__new__(LocalBus)  # python-can's check with these filters
        bus._filters = filters
        raw = RawFilter(filters)
        for arb in ids:
            for ext in (False, True):
                if not ext and arb > 0x7FF:
                    continue
                for rtr, err in ((False, False), (True, False), (False, True)):
                    m = can.Message(
                        arbitration_id=arb, is_extended_id=ext, is_remote_frame=rtr, is_error_frame=err
                    )
                    want = can.BusABC._matches_filters(bus, m)
                    assert raw.passes(pack_frame_id(m)) == want, (filters, m)
                    checked, passed = checked + 1, passed + want
    assert 0 < passed < checked


def pack_frame_id(m: can.Message) -> int:
    return int.from_bytes(pack_frame(m)[:4], sys.byteorder)
