"""Damaged bags said plainly: a fit with a warning counting the lost messages, or one line and exit 2.

A small real bag (the DFKI pendulum excerpt as JointState, 17 chunks) is damaged on purpose: a chunk
failing its CRC, a corrupt message index or summary, then 200 seeded single-byte flips and
truncations. ``friction-bag info``, the loader and (for a subset) ``friction-fit`` must never raise
anything but a one-line error, never lose messages silently and never change the input.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import random
import shutil
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from friction_ros.cli import bag as bag_cli
from friction_ros.cli import fit as fit_cli
from friction_ros.core.bag import BagWriter, encode, load_installed, read_bag
from friction_ros.core.identification.data.log_loading import load_log

PENDULUM = Path(__file__).parent / "data" / "dfki_pendulum" / "control_method_pd_system_identification.csv"
JS = "sensor_msgs/msg/JointState"
T0 = 1_700_000_000_000_000_000
FIT = ["--models", "coulomb_viscous", "--no-plots", "--no-gate", "--residual", "none", "--quiet"]


@pytest.fixture(scope="module")
def pendulum(tmp_path_factory) -> Path:
    """The pendulum excerpt (1170 samples, 3.9 s) as a bag of small zstd chunks; returns its .mcap file."""
    rows = np.loadtxt(PENDULUM, delimiter=",", skiprows=1)
    defs = load_installed(JS)
    path = tmp_path_factory.mktemp("damage") / "pend"
    with BagWriter(path, chunk_size=8192, flush_interval=3600) as w:
        w.add_topic("/joint_states", JS)
        for t, q, v, tau in rows:
            ns = T0 + int(round(t * 1e9))
            stamp = {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}
            m = {"header": {"stamp": stamp, "frame_id": ""}, "name": ["pendulum"]}
            m.update(position=[q], velocity=[v], effort=[tau])
            w.write("/joint_states", encode(defs, JS, m), ns)
    return path / "pend_0.mcap"


def _chunks(f: Path):
    with open(f, "rb") as fh:
        return sorted(make_reader(fh).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)


def _messages_in(ch, f: Path) -> int:
    """Messages of the intact bag in the chunk of chunk index ``ch`` (chunks are in time order)."""
    t = read_bag(f)["/joint_states"].log_time
    return int(np.sum((t >= ch.message_start_time) & (t <= ch.message_end_time)))


def _damaged(src: Path, dst: Path, edit) -> Path:
    b = bytearray(src.read_bytes())
    b = edit(b) or b
    dst.write_bytes(bytes(b))
    return dst


def _run(main, argv) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(argv)
    return rc, out.getvalue(), err.getvalue()


def _digest(f: Path) -> str:
    return hashlib.sha256(f.read_bytes()).hexdigest()


# ------------------------------------------------------------------------------------------ intact
def test_independent_readers_agree_on_the_intact_bag(pendulum):
    from rosbags.rosbag2 import Reader

    bag = read_bag(pendulum.parent)
    assert len(bag["/joint_states"]) == 1170 and not bag.damaged and not bag.warnings
    with Reader(pendulum.parent) as r:
        assert sum(1 for _ in r.messages()) == 1170
    with open(pendulum, "rb") as fh:
        assert sum(1 for _ in make_reader(fh).iter_messages()) == 1170
    rc, out, _ = _run(bag_cli.main, ["info", str(pendulum.parent)])
    assert rc == 0 and "status:   complete" in out


# ------------------------------------------------------------------------------------------ specific damage
def test_chunk_failing_its_crc_is_counted_in_info_and_fit(pendulum, tmp_path):
    ch = _chunks(pendulum)[5]
    n_lost = _messages_in(ch, pendulum)
    assert 40 < n_lost < 100

    def flip_crc(b):  # the chunk's uncompressed CRC: opcode, length, start, end, size, then the CRC
        b[ch.chunk_start_offset + 9 + 24] ^= 0x01

    f = _damaged(pendulum, tmp_path / "crc.mcap", flip_crc)
    before = _digest(f)
    bag = read_bag(f)
    assert bag.damaged and bag.lost == {"/joint_states": n_lost} and bag.lost_count == n_lost
    assert len(bag["/joint_states"]) == 1170 - n_lost
    assert any(f"chunk at byte {ch.chunk_start_offset} fails its CRC check" in w for w in bag.warnings)
    t0 = int(read_bag(pendulum)["/joint_states"].log_time[0])  # when the lost messages were logged
    a, b = (ch.message_start_time - t0) * 1e-9, (ch.message_end_time - t0) * 1e-9
    assert any(f"messages logged {a:.3f} s to {b:.3f} s after the start" in w for w in bag.warnings)
    rc, out, _ = _run(bag_cli.main, ["info", str(f)])
    assert rc == 0 and f"status:   DAMAGED: {n_lost} messages lost (/joint_states {n_lost})" in out
    data = load_log(f)
    assert f"file is damaged: {n_lost} messages lost (/joint_states {n_lost})" in data.meta["warnings"][0]
    rc, out, err = _run(fit_cli.main, [str(f), *FIT, "--out", str(tmp_path / "fit")])
    assert rc == 0, err
    assert f"warning: {f}: file is damaged: {n_lost} messages lost (/joint_states {n_lost})" in out
    assert _digest(f) == before


def _same_messages(a, b) -> None:
    ja, jb = a["/joint_states"], b["/joint_states"]
    np.testing.assert_array_equal(ja.log_time, jb.log_time)
    for k in ("position", "velocity", "effort"):
        np.testing.assert_array_equal(ja[k], jb[k])


def test_damaged_summary_falls_back_to_a_linear_scan(pendulum, tmp_path):
    ch = _chunks(pendulum)[3]
    intact = read_bag(pendulum)
    data = pendulum.read_bytes()
    # the footer (opcode, length, summary start, ...) is the last record before the closing magic
    summary_start = int.from_bytes(data[-37 + 9 : -37 + 17], "little")
    at = data.index(ch.chunk_start_offset.to_bytes(8, "little"), summary_start)  # chunk 3's chunk index

    def index_flipped(b):
        b[at + 6] ^= 0x40

    def footer_crc_flipped(b):
        b[-12] ^= 0x01

    def index_flipped_no_crc(b):  # a writer without CRCs: the chunk index points outside the file
        b[at + 6] ^= 0x40
        b[-12:-8] = bytes(4)

    for edit in (index_flipped, footer_crc_flipped, index_flipped_no_crc):
        f = _damaged(pendulum, tmp_path / f"{edit.__name__}.mcap", edit)
        bag = read_bag(f)
        _same_messages(bag, intact)
        assert bag.damaged and bag.lost == {}, edit.__name__
        assert any("was read by a linear scan of its records" in w for w in bag.warnings), edit.__name__
        rc, out, _ = _run(bag_cli.main, ["info", str(f)])
        assert rc == 0 and "status:   DAMAGED: no messages lost" in out and "linear scan" in out


def test_damaged_message_index_falls_back_to_a_scan_of_the_chunk(pendulum, tmp_path):
    """The user's crash: a flipped byte in an index record made the reader index past the chunk."""
    ch = _chunks(pendulum)[2]
    entries = ch.message_index_offsets[1] + 9 + 6  # channel 1's message index: first (time, offset) entry
    intact = read_bag(pendulum)
    for name, at in (("offset", entries + 8 + 2), ("time", entries + 1), ("count", entries - 2)):
        f = _damaged(pendulum, tmp_path / f"{name}.mcap", lambda b, at=at: b.__setitem__(at, b[at] ^ 0x10))
        bag = read_bag(f)
        _same_messages(bag, intact)
        assert bag.damaged and bag.lost == {}, name
        assert any("message index of the chunk" in w and "linear scan" in w for w in bag.warnings), name


def test_damaged_chunk_length_is_found_from_its_contents(pendulum, tmp_path):
    ch = _chunks(pendulum)[4]
    f = _damaged(pendulum, tmp_path / "len.mcap", lambda b: b.__setitem__(ch.chunk_start_offset + 2, 0x7F))
    bag = read_bag(f)
    _same_messages(bag, read_bag(pendulum))
    assert any("length of the chunk" in w for w in bag.warnings)


def test_first_chunk_and_summary_damaged_counts_from_the_message_indexes(pendulum, tmp_path):
    """Without a usable summary the loss is counted from the message indexes that follow the chunk."""
    ch = _chunks(pendulum)[6]
    n_lost = _messages_in(ch, pendulum)

    def flip(b):
        b[ch.chunk_start_offset + 9 + 24] ^= 0x01
        b[-12] ^= 0x01

    bag = read_bag(_damaged(pendulum, tmp_path / "both.mcap", flip))
    assert bag.lost == {"/joint_states": n_lost}


# ------------------------------------------------------------------------------------------ fuzz
def _one_line_error(rc: int, err: str, f: Path) -> None:
    assert rc == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert str(f) in err, err


def test_fuzz_flips_and_truncations(pendulum, tmp_path):
    data = pendulum.read_bytes()
    full = read_bag(pendulum)["/joint_states"]
    rng = random.Random(20261127)
    tally = {"intact": 0, "warned": 0, "refused": 0}
    d = tmp_path / "cases"
    for i in range(200):
        b = bytearray(data)
        if i % 4 == 3:
            b = b[: rng.randrange(len(b))]
        else:
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        shutil.rmtree(d, ignore_errors=True)
        d.mkdir()
        f = d / "case.mcap"
        f.write_bytes(bytes(b))
        rc, out, err = _run(bag_cli.main, ["info", str(f)])
        if rc != 0:
            _one_line_error(rc, err, f)
        try:
            rec = load_log(f)
        except ValueError as exc:
            assert "\n" not in str(exc) and str(f) in str(exc), exc
            tally["refused"] += 1
            continue
        bag = read_bag(f)
        js = bag["/joint_states"]
        assert set(js.log_time.tolist()) <= set(full.log_time.tolist())
        if len(js) < len(full):  # never silent: the record warns and info says so
            assert bag.damaged or bag.truncated
            assert rec.meta["warnings"] and any(w in out for w in ("DAMAGED", "TRUNCATED", "NOT CLOSED"))
        if bag.damaged and bag.lost_count is not None:
            assert len(js) + bag.lost_count == len(full)
        tally["warned" if rec.meta["warnings"] else "intact"] += 1
        if i % 20 == 0:
            rc, out, err = _run(fit_cli.main, [str(f), *FIT, "--out", str(tmp_path / f"fit{i}")])
            if rc != 0:
                _one_line_error(rc, err, f)
            elif bag.damaged or bag.truncated:
                assert "warning:" in out and any(w in out for w in ("damaged", "truncated", "not closed"))
        assert f.read_bytes() == bytes(b)  # the input is never changed
    print(f"200 damaged copies: {tally}")
    assert sum(tally.values()) == 200 and tally["warned"] > 150


def test_zeroed_blocks(pendulum, tmp_path):
    """A disk or copy error zeroes whole 512-byte blocks: every block of the file, one at a time."""
    data = pendulum.read_bytes()
    full = len(read_bag(pendulum)["/joint_states"])
    f = tmp_path / "zeroed.mcap"
    for start in range(0, len(data), 512):
        b = bytearray(data)
        b[start : start + 512] = bytes(len(b[start : start + 512]))
        f.write_bytes(bytes(b))
        bag = read_bag(f)
        n = len(bag["/joint_states"]) if "/joint_states" in bag else 0
        assert bag.damaged or (bag.truncated and n == full), start  # the last block holds the footer
        if n < full:
            assert bag.lost_count is None or n + bag.lost_count == full, start
