"""The documentation's commands work, and the README stays a front door.

Every fenced block with the info string ``bash runnable`` in README.md and docs/*.md is run with
``bash -euo pipefail`` from the repository root, with this venv's executables first on PATH and a
timeout (docs/development.md, "Runnable command blocks"). Only fast commands are marked runnable.
Also: README.md is under 300 lines, and no user-facing text names an issue number.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: a fenced block whose info string is exactly ``bash runnable``
RUNNABLE = re.compile(r"^```bash runnable[ \t]*\n(.*?)^```[ \t]*$", re.M | re.S)
#: seconds one block may take (the blocks are chosen to take under ~20 s on a 2-core machine)
BLOCK_TIMEOUT = 120.0
README_MAX_LINES = 300
ISSUE_NUMBER = re.compile(r"\bissues?\s*#?\s*\d+", re.I)
#: user-facing text: the README, the docs and the command-line tools' help and messages
USER_FACING = [*DOCS, *sorted((ROOT / "friction_ros" / "cli").glob("*.py"))]


def runnable_blocks(text: str) -> list[tuple[int, str]]:
    """(line number of the opening fence, code) of every ``bash runnable`` block in ``text``."""
    return [(text.count("\n", 0, m.start()) + 1, m.group(1)) for m in RUNNABLE.finditer(text)]


def run_block(code: str, timeout: float = BLOCK_TIMEOUT) -> tuple[int, str]:
    """Run ``code`` as a reader would, from the repository root with the venv's commands on PATH:
    (exit status, last lines of the output); a timeout is a failure (status -1)."""
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env.setdefault("MPLBACKEND", "Agg")
    try:
        p = subprocess.run(
            ["bash", "-euo", "pipefail", "-c", code],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
            start_new_session=True,
        )
    except subprocess.TimeoutExpired as exc:
        out = (
            (exc.stdout or b"").decode(errors="replace")
            if isinstance(exc.stdout, bytes)
            else exc.stdout or ""
        )
        return -1, f"timed out after {timeout:g} s\n{out[-2000:]}"
    return p.returncode, (p.stdout + p.stderr)[-3000:]


def _all_blocks() -> list[tuple[str, str]]:
    out = []
    for path in DOCS:
        for line, code in runnable_blocks(path.read_text()):
            out.append((f"{path.relative_to(ROOT)}:{line}", code))
    return out


BLOCKS = _all_blocks()


@pytest.mark.parametrize("where,code", BLOCKS, ids=[w for w, _ in BLOCKS])
def test_runnable_block_succeeds(where, code):
    status, output = run_block(code)
    assert status == 0, (
        f"{where}: the runnable block failed (status {status}):\n{code}\n--- output ---\n{output}"
    )


def test_the_docs_have_runnable_blocks():
    where = [w for w, _ in BLOCKS]
    assert any(w.startswith("README.md:") for w in where), "README.md has no runnable block"
    assert len(where) >= 3, where


def test_only_blocks_marked_runnable_are_extracted():
    text = (
        "intro\n"
        "```bash\nmake demo\n```\n"
        "```bash runnable\nfriction-fit --help\necho ok\n```\n"
        "```python\nprint(1)\n```\n"
        "```bash runnable\ntrue\n```\n"
    )
    assert runnable_blocks(text) == [(5, "friction-fit --help\necho ok\n"), (12, "true\n")]


def test_a_failing_command_fails_the_block():
    status, output = run_block("friction-fit --joint-type bogus log.csv")
    assert status == 2 and "bogus" in output
    # a failure before the last line counts too (bash -e), and inside a pipe (pipefail)
    assert run_block("false\necho after")[0] != 0
    assert run_block("friction-bag info /nonexistent/bag | cat")[0] != 0
    assert run_block("true\necho fine")[0] == 0


def test_a_block_that_hangs_fails_after_the_timeout():
    status, output = run_block("sleep 30", timeout=0.5)
    assert status == -1 and "timed out" in output


def test_readme_is_a_front_door_under_300_lines():
    n = len((ROOT / "README.md").read_text().splitlines())
    assert n < README_MAX_LINES, f"README.md has {n} lines: move details to docs/"


def test_no_user_facing_text_names_an_issue_number():
    hits = []
    for path in USER_FACING:
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if ISSUE_NUMBER.search(line):
                hits.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
    assert not hits, "issue numbers in user-facing text:\n" + "\n".join(hits)


def test_the_issue_number_check_would_catch_one():
    assert ISSUE_NUMBER.search("Goals (issue 17)") and ISSUE_NUMBER.search("see Issue #5")
    assert not ISSUE_NUMBER.search("no issue here, 17 joints")


LINK = re.compile(r"\]\(([^)\s]+)\)")


def _anchor(heading: str) -> str:
    """GitHub's anchor of a Markdown heading: lower case, punctuation dropped, spaces to '-'."""
    text = re.sub(r"[`*]", "", heading.strip().lower())
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def test_every_relative_link_of_the_docs_resolves():
    broken = []
    for path in DOCS:
        for target in LINK.findall(path.read_text()):
            if re.match(r"[a-z]+:", target):
                continue  # http(s), mailto: not checked here
            file_part, _, anchor = target.partition("#")
            dest = (path.parent / file_part).resolve() if file_part else path
            if not dest.exists():
                broken.append(f"{path.relative_to(ROOT)}: {target} (no such file)")
                continue
            if anchor and dest.suffix == ".md":
                anchors = {_anchor(h) for h in re.findall(r"^#+ (.+)$", dest.read_text(), re.M)}
                if anchor not in anchors:
                    broken.append(f"{path.relative_to(ROOT)}: {target} (no such heading)")
    assert not broken, "broken links:\n" + "\n".join(broken)
