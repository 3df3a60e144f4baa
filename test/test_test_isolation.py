"""The test suite's own isolation: every pytest process (xdist worker) holds a ROS domain of its own."""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys

import conftest
import pytest


def test_this_process_holds_the_lock_of_its_domain():
    domain = int(os.environ["ROS_DOMAIN_ID"])
    assert 1 <= domain <= conftest.DOMAIN_MAX
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert os.environ["FRICTION_CAN_DIR"].endswith(f"d{domain}")
    # another process cannot take it while this one runs
    code = (
        "import fcntl, sys\n"
        f"f = open({str(conftest._LOCK_DIR / f'{domain}.lock')!r}, 'a')\n"
        "try:\n    fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)\nexcept OSError:\n    sys.exit(3)\n"
    )
    assert subprocess.run([sys.executable, "-c", code]).returncode == 3


def test_a_taken_domain_is_skipped_by_the_worker_stride(monkeypatch):
    held: list = []
    monkeypatch.setattr(conftest, "_held", held)
    try:
        mine = int(os.environ["ROS_DOMAIN_ID"])
        base = 60 if not 60 <= mine <= 70 else 80
        first = conftest.claim_domain(base, 1, 3)
        second = conftest.claim_domain(base, 1, 3)  # base + 1 is held now (by this process)
        assert first == base + 1 and second == base + 4
    finally:
        for f in held:
            fcntl.flock(f, fcntl.LOCK_UN)
            f.close()


def test_every_id_is_tried_once_and_none_free_is_one_clear_error(monkeypatch, tmp_path):
    monkeypatch.setattr(conftest, "_LOCK_DIR", tmp_path)
    monkeypatch.setattr(conftest, "DOMAIN_MAX", 3)
    held: list = []
    monkeypatch.setattr(conftest, "_held", held)
    try:
        assert sorted(conftest.claim_domain(2, 0, 1) for _ in range(3)) == [1, 2, 3]
        with pytest.raises(RuntimeError, match="no free ROS domain id in 1..3"):
            conftest.claim_domain(1, 0, 1)
    finally:
        for f in held:
            f.close()
