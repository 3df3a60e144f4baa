"""Bag core (no rclpy): rosbags interoperability both ways, ros2 profile details, recovery, errors."""

from __future__ import annotations

import shutil
import subprocess
import sys

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader

from friction_ros.core.bag import (
    BagError,
    BagWriter,
    CdrError,
    NotMcapError,
    SchemaError,
    TopicNotFoundError,
    TruncatedBagError,
    encode,
    load_installed,
    make_qos,
    read_bag,
    run_metadata,
)

JS = "sensor_msgs/msg/JointState"
F64 = "std_msgs/msg/Float64"
EV = "friction_msgs/msg/ExperimentEvent"
T0 = 1_700_000_000_000_000_000


def js_msg(i: int, names=("joint1", "joint2")) -> dict:
    k = len(names)
    return {
        "header": {"stamp": {"sec": 1000 + i, "nanosec": 7 * i}, "frame_id": "base"},
        "name": list(names),
        "position": [0.001 * i + j for j in range(k)],
        "velocity": [0.5 * i - j for j in range(k)],
        "effort": [] if i % 7 == 0 else [np.sin(i) + j for j in range(k)],
    }


def write_sample(path, n=500, **kw) -> dict:
    defs = {t: load_installed(t) for t in (JS, F64, EV)}
    sent = {"/joint_states": [], "/command": [], "/events": []}
    with BagWriter(path, metadata=run_metadata(preset="abb_m19s", program="plateaus"), **kw) as w:
        w.add_topic("/joint_states", JS, qos_profiles=[make_qos(depth=10)])
        w.add_topic("/command", F64, qos_profiles=[make_qos("best_effort")])
        w.add_topic("/events", EV)
        for i in range(n):
            t = T0 + i * 1_000_000
            m = js_msg(i)
            w.write("/joint_states", encode(defs[JS], JS, m), t, t - 1000)
            sent["/joint_states"].append(m)
            w.write("/command", encode(defs[F64], F64, {"data": -0.25 * i}), t + 10)
            sent["/command"].append(-0.25 * i)
            if i % 100 == 0:
                ev = {
                    "program": "plateaus",
                    "segment": f"plateau+{i}",
                    "index": i // 100,
                    "event": 0,
                    "target": 0.1,
                }
                w.write("/events", encode(defs[EV], EV, ev), t + 20)
                sent["/events"].append(ev)
    return sent


def test_rosbags_reads_our_bag(tmp_path):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    bag = tmp_path / "run_a"
    sent = write_sample(bag)
    assert sorted(p.name for p in bag.iterdir()) == ["metadata.yaml", "run_a_0.mcap"]
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    ts = get_typestore(Stores.EMPTY)
    got: dict[str, list] = {}
    with Reader(bag) as r:  # parses metadata.yaml
        conns = {c.topic: c for c in r.connections}
        assert {t: (c.msgtype, c.msgcount) for t, c in conns.items()} == {
            "/joint_states": (JS, 500),
            "/command": (F64, 500),
            "/events": (EV, 5),
        }
        assert conns["/joint_states"].ext.offered_qos_profiles[0].depth == 10
        assert conns["/command"].ext.offered_qos_profiles[0].reliability.name == "BEST_EFFORT"
        assert conns["/joint_states"].digest.startswith("RIHS01_")
        for c in r.connections:  # types only from the embedded schema text (complete definitions)
            ts.register(get_types_from_msg(c.msgdef.data, c.msgtype))
        for c, _t, raw in r.messages():
            got.setdefault(c.topic, []).append(ts.deserialize_cdr(raw, c.msgtype))
    for m, s in zip(got["/joint_states"], sent["/joint_states"], strict=True):
        assert m.header.stamp.sec == s["header"]["stamp"]["sec"] and m.header.frame_id == "base"
        assert list(m.name) == s["name"]
        np.testing.assert_array_equal(m.position, s["position"])
        np.testing.assert_array_equal(m.effort, s["effort"])
    assert [m.data for m in got["/command"]] == sent["/command"]
    assert [m.segment for m in got["/events"]] == [e["segment"] for e in sent["/events"]]


def test_mcap_follows_ros2_profile(tmp_path):
    bag = tmp_path / "run_p"
    write_sample(bag, n=50)
    with open(bag / "run_p_0.mcap", "rb") as f:
        r = make_reader(f)
        assert r.get_header().profile == "ros2"
        s = r.get_summary()
        assert s.statistics.message_count == 50 + 50 + 1
        assert s.statistics.channel_message_counts
        assert all(ci.compression == "zstd" and ci.message_index_offsets for ci in s.chunk_indexes)
        schemas = {x.name: x for x in s.schemas.values()}
        assert set(schemas) == {JS, F64, EV}
        assert all(x.encoding == "ros2msg" for x in schemas.values())
        js = schemas[JS].data.decode()
        assert "\n" + "=" * 80 + "\nMSG: std_msgs/Header\n" in js
        assert "\nMSG: builtin_interfaces/Time\n" in js and js.count("MSG: ") == 2
        for ch in s.channels.values():
            assert ch.message_encoding == "cdr"
        q = yaml.safe_load(s.channels[1].metadata["offered_qos_profiles"])
        assert q[0]["reliability"] == "reliable" and q[0]["history"] == "keep_last"
        md = {m.name: m.metadata for m in r.iter_metadata()}
        assert md["friction_ros"]["preset"] == "abb_m19s" and md["friction_ros"]["program"] == "plateaus"
        assert yaml.safe_load(md["rosbag2"]["serialized_metadata"])["version"] == 9


def test_reader_values_and_joint_selection(tmp_path):
    bag = tmp_path / "run_r"
    sent = write_sample(bag, n=300)
    b = read_bag(bag)
    assert not b.truncated and not b.warnings
    assert b.run_metadata["preset"] == "abb_m19s"
    js = b.topic("/joint_states", JS)
    assert len(js) == 300 and js.joint_names == ["joint1", "joint2"]
    j2 = js.joint("joint2")
    np.testing.assert_allclose(j2.position, [s["position"][1] for s in sent["/joint_states"]])
    eff = np.array([s["effort"][1] if s["effort"] else np.nan for s in sent["/joint_states"]])
    np.testing.assert_array_equal(j2.effort, eff)
    np.testing.assert_allclose(j2.stamp - 1000, np.arange(300) + 7e-9 * np.arange(300), atol=1e-6)
    np.testing.assert_array_equal(js.log_time, T0 + np.arange(300) * 1_000_000)
    np.testing.assert_array_equal(js.publish_time, js.log_time - 1000)
    np.testing.assert_array_equal(b["/command"]["data"], sent["/command"])
    assert list(b["/events"]["segment"]) == [e["segment"] for e in sent["/events"]]


def test_reader_reads_rosbags_writer_bag(tmp_path):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_JAZZY)
    JointState = ts.types[JS]
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    out = tmp_path / "foreign"
    n = 200
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection("/robot/arm/joint_states_any", JS, typestore=ts)
        for i in range(n):
            names = ["a", "b", "elbow"] if i < 150 else ["elbow", "a"]  # joint order changes mid-bag
            pos = np.arange(len(names), dtype=float) + i
            m = JointState(Header(Time(i, 0), "f"), names, pos, pos * 2, np.array([], dtype=float))
            w.write(c, T0 + i * 1000, ts.serialize_cdr(m, JS))
    for path in (out, next(out.glob("*.mcap"))):  # the directory and the bare .mcap file
        b = read_bag(path, "/robot/arm/joint_states_any")
        el = b["/robot/arm/joint_states_any"].joint("elbow")
        exp = np.where(np.arange(n) < 150, 2.0, 0.0) + np.arange(n)
        np.testing.assert_array_equal(el.position, exp)
        np.testing.assert_array_equal(el.velocity, 2 * exp)
        assert np.isnan(el.effort).all()
        a = b["/robot/arm/joint_states_any"].joint("b")
        assert np.isnan(a.position[150:]).all() and (a.position[:150] == 1 + np.arange(150)).all()


@pytest.mark.parametrize("compression", ["lz4", "none"])
def test_reader_other_compressions(tmp_path, compression):
    sent = write_sample(tmp_path / "c", n=100, compression=compression)
    b = read_bag(tmp_path / "c")
    np.testing.assert_array_equal(b["/command"]["data"], sent["/command"])


def test_truncated_file_recovers_complete_chunks(tmp_path):
    bag = tmp_path / "k"
    defs = load_installed(F64)
    with BagWriter(bag) as w:
        w.add_topic("/x", F64)
        for i in range(1000):
            w.write("/x", encode(defs, F64, {"data": float(i)}), T0 + i)
            if i % 100 == 99:
                w.flush()  # what the flush_interval timer does
    f = bag / "k_0.mcap"
    data = f.read_bytes()
    with open(f, "rb") as fh:
        chunks = sorted(make_reader(fh).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    ends = [c.chunk_start_offset + c.chunk_length for c in chunks]
    assert len(ends) == 10
    cut_dir = tmp_path / "cut"
    for cut in [
        ends[0] - 5,
        ends[3] + 3,
        ends[6] + 40,
        (ends[8] + ends[9]) // 2,
        ends[9] + 1,
        len(data) - 30,
    ]:
        shutil.rmtree(cut_dir, ignore_errors=True)
        cut_dir.mkdir()
        (cut_dir / "cut_0.mcap").write_bytes(data[:cut])
        b = read_bag(cut_dir)
        complete = sum(e <= cut for e in ends)
        got = b["/x"]["data"] if "/x" in b else np.array([])
        assert len(got) == 100 * complete, cut
        np.testing.assert_array_equal(got, np.arange(100 * complete))
        assert b.truncated and "truncated" in b.warnings[0]


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "friction_ros.cli.bag", *args], capture_output=True, text=True
    )


def test_unreadable_inputs_clear_errors(tmp_path):
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    text = tmp_path / "notes.mcap"
    text.write_text("hello, this is not a bag\n")
    good = tmp_path / "g"
    write_sample(good, n=20)
    head = tmp_path / "head.mcap"
    head.write_bytes((good / "g_0.mcap").read_bytes()[:12])
    (tmp_path / "emptydir").mkdir()
    cases = [
        (empty, NotMcapError, "empty"),
        (text, NotMcapError, "not an MCAP file"),
        (head, TruncatedBagError, "header record is truncated"),
        (tmp_path / "missing", BagError, "no such bag"),
        (tmp_path / "emptydir", NotMcapError, "no .mcap file"),
    ]
    for path, exc, words in cases:
        with pytest.raises(exc, match=words):
            read_bag(path)
        r = _cli("info", str(path))
        assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
        assert r.stderr.startswith("error: ") and words in r.stderr and r.stderr.count("\n") == 1
    with pytest.raises(TopicNotFoundError, match="topic /nope not found: topics are /command, /events"):
        read_bag(good, ["/nope"])
    with pytest.raises(
        SchemaError, match="has type std_msgs/msg/Float64, expected sensor_msgs/msg/JointState"
    ):
        read_bag(good).topic("/command", JS)
    assert isinstance(TopicNotFoundError("x"), ValueError)


def test_wrong_schema_is_reported(tmp_path):
    """Payloads that do not match the channel's schema: CdrError naming the topic."""
    bag = tmp_path / "w"
    f64 = load_installed(F64)
    with BagWriter(bag) as w:
        w.add_topic("/joint_states", JS)  # declared JointState ...
        for i in range(5):
            w.write("/joint_states", encode(f64, F64, {"data": 1.0}), T0 + i)  # ... but Float64 payloads
        w.add_topic("/ok", F64)
        w.write("/ok", encode(f64, F64, {"data": 2.0}), T0)
    with pytest.raises(CdrError, match="topic /joint_states .sensor_msgs/msg/JointState.: payload too short"):
        read_bag(bag, "/joint_states")
    b = read_bag(bag)  # not requested by name: skipped with a reason, other topics still read
    assert "/joint_states" in b.skipped and b["/ok"]["data"][0] == 2.0
    with pytest.raises(SchemaError, match="cannot be decoded"):
        b["/joint_states"]
    r = _cli("info", str(bag))
    assert r.returncode == 0 and "/joint_states" in r.stdout
