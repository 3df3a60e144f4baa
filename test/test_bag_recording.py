"""The bag recorder's bookkeeping (core.bag.recording) without ROS: topic choice, subscription QoS,
drops from sequence gaps and middleware losses, and the reports."""

from __future__ import annotations

from friction_ros.core.bag.recording import (
    SEQ_UNSUPPORTED,
    RecordingStats,
    TopicStats,
    subscription_qos,
    wanted_topic,
)
from friction_ros.core.joint_channel import OK, WARN


def _never() -> bool:
    return False


def test_topic_choice_and_qos_follow_the_publishers():
    assert wanted_topic("/a", ["/a"], False) and not wanted_topic("/b", ["/a"], False)
    assert wanted_topic("/b", [], True) and not wanted_topic("/rosout", ["/rosout"], True)
    q = subscription_qos([(False, True), (False, True)], 0)
    assert q == {"keep_all": True, "depth": 1, "reliable": True, "transient_local": True}
    q = subscription_qos([(True, True), (False, False)], 5)
    assert q == {"keep_all": False, "depth": 5, "reliable": False, "transient_local": False}
    assert subscription_qos([], 0)["transient_local"] is False  # no publisher: volatile


def test_sequence_gaps_count_as_drops_while_the_topic_has_one_publisher():
    st = TopicStats()
    for seq in (1, 2, 5, 6, 10):  # 3, 4 and 7..9 missing
        st.receive(seq, _never)
    assert (st.received, st.gaps, st.dropped) == (5, 5, 5)
    st.receive(1, _never)  # the publisher was replaced: numbers start again, no drop
    st.receive(2, _never)
    st.lost = 7  # the middleware's message_lost total is larger: it wins
    assert st.dropped == 7 and st.gaps == 5
    st.receive(None, _never)  # no sequence number: counted, not checked
    st.receive(SEQ_UNSUPPORTED + 3, _never)
    assert st.received == 9 and st.last_seq == 2


def test_several_publishers_interleave_their_numbers_without_drops():
    st = TopicStats()
    st.receive(1, _never)
    st.receive(40, lambda: True)  # a gap, but a second publisher appeared: not a drop
    assert st.several and st.gaps == 0
    st.receive(2, _never)
    st.receive(41, _never)
    assert st.gaps == 0
    st.publishers(1)  # back to one: its numbers are consecutive from the next one on
    st.receive(42, _never)
    st.receive(44, _never)
    assert not st.several and st.gaps == 1


def test_reports_log_new_drops_once_and_total_every_topic():
    rec = RecordingStats()
    a, b = rec.add("/a", 1), rec.add("/b", 2)
    assert b.several and not a.several
    for seq in (1, 2, 4):
        a.receive(seq, _never)
    b.receive(7, _never)
    assert rec.message_count == 4 and rec.dropped == 1
    ((level, line),) = rec.new_drops()
    assert level == WARN and line == "dropped 1 message(s) on /a (1 dropped, 3 recorded so far)"
    assert rec.new_drops() == []  # reported already
    level, text, values = rec.diagnostics()
    assert (level, text) == (WARN, "4 messages recorded, 1 dropped")
    assert values == {"messages": 4, "dropped": 1, "topics": 2, "/a received": 3, "/a dropped": 1,
                      "/b received": 1, "/b dropped": 0}  # fmt: skip
    assert rec.record() == {"messages": 4, "dropped": 1, "received:/a": 3, "dropped:/a": 1,
                            "received:/b": 1, "dropped:/b": 0}  # fmt: skip
    assert rec.summary("bags/x") == "wrote 4 messages on 2 topic(s) to bags/x; DROPPED 1 message(s) (/a: 1)"
    clean = RecordingStats()
    clean.add("/c", 1).receive(1, _never)
    assert clean.diagnostics()[0] == OK and clean.summary("d").endswith("; 0 dropped")
