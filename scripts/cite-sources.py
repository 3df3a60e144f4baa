#!/usr/bin/env python3
"""Rewrite citations of the five source documents from their old internal form to their labels.

docs/sources.md lists the sources and their citation labels. Old notes cite them as "seed 000" ...
"seed 004" and as sections of the project's notes on them ("extract A.2.4", "extract 9.7", "B-T8").
This script rewrites, in the given files and folders:

    seed 003 eq. (4)      -> ABB M19-S paper eq. (4)
    the seed 003 paper    -> the ABB M19-S paper
    extract A.2.4         -> ABB M19-S paper A.2.4     (the letter's source: the nearest source named
                                                        before it in the file, else after it)
    extract 9 item 4      -> GA friction thesis 2002 section 9 item 4
    B-T8                  -> Tilakaratna et al. 2004 B-T8

Preset names (``seed004_dc_motor``), module names (``seed001.py``) and file names are never touched;
a second run changes nothing. docs/sources.md (which keeps the old-to-new mapping), this script and
its test are skipped.

    python scripts/cite-sources.py friction_ros/core bench docs      # rewrite, list each change
    python scripts/cite-sources.py --check .                         # exit 1 while any remain
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LABELS = {
    "000": "Chatterjee et al. 2017",
    "001": "GA friction thesis 2002",
    "002": "Tilakaratna et al. 2004",
    "003": "ABB M19-S paper",
    "004": "AI friction chapter",
}
SKIP_FILES = {"docs/sources.md", "scripts/cite-sources.py", "test/test_source_citations.py"}
SKIP_DIRS = {".git", ".venv", "build", "install", "log", "bags", "__pycache__", ".pytest_cache"}
SUFFIXES = {".py", ".md", ".yaml", ".yml", ".txt", ".cfg", ".toml", ".sh", ".xml", ".rst", ""}

# which source a section of the notes belongs to, where the section alone decides it
E1_SOURCE = {n: "003" for n in (1, 7, 8, 9)} | {n: "004" for n in (2, 3, 4, 5, 6, 10, 11, 12, 13)}
C_SOURCE = {1: "004", 2: "004", 3: "003", 4: "004", 5: "004", 6: "003"}
LETTER_SOURCES = {"A": ("000", "003"), "B": ("002", "004")}

SEED = r"[Ss]eeds? (00[0-4])(?![0-9_])"
NOUN = r"(?:paper|thesis|report|chapter)"
SECTION = (
    r"(?:section )?(?:[A-E](?:\.\d+)+[a-z]?(?: \([a-z]\))?|[AB]-T\d+(?:/[AB]-T\d+)*"
    r"|\d+(?:\.\d+)*(?:-\d+(?:\.\d+)*)?(?: item \d+[a-z]?)?)"
)
RE_SEED_NOUN = re.compile(r"\b(?:(the) )?" + SEED + r" " + NOUN + r"\b")
RE_SEED = re.compile(r"\b(?:[Ee]xtract )?" + SEED)
RE_EXTRACT = re.compile(r"\b[Ee]xtract (\()?(" + SECTION + r")(?(1)\))(?=[\s,;:./)\]\"'`]|$)")
RE_TEST_ROW = re.compile(r"(?<![\w/-])([AB])-T\d+(?:/[AB]-T\d+)*\b")
RE_ANY_LABEL = re.compile("|".join(re.escape(v) for v in LABELS.values()) + "|" + SEED)


def _source_of(match: re.Match) -> str:
    text = match.group(0)
    for key, label in LABELS.items():
        if text == label:
            return key
    return match.group(1)


def _resolve(section: str, text: str, pos: int) -> str | None:
    """The source a notes section belongs to (None: cannot tell)."""
    sec = section.removeprefix("section ")
    if sec[0].isdigit():
        return "001"
    if sec.startswith("E.1."):
        return E1_SOURCE.get(int(re.match(r"E\.1\.(\d+)", sec).group(1)))
    if sec.startswith("C."):
        return C_SOURCE.get(int(re.match(r"C\.(\d+)", sec).group(1)))
    if sec[1:3] == "-T":  # acceptance-test rows: A-T for the report, B-T for the manipulator paper
        return "000" if sec[0] == "A" else "002"
    allowed = LETTER_SOURCES.get(sec[0], ())
    mentions = [(m.start(), _source_of(m)) for m in RE_ANY_LABEL.finditer(text)]
    before = [s for p, s in mentions if p < pos and s in allowed]
    after = [s for p, s in mentions if p > pos and s in allowed]
    return before[-1] if before else (after[0] if after else None)


def _label_for(key: str) -> str:
    return LABELS[key]


def rewrite(text: str) -> tuple[str, list[str]]:
    """Return (new text, unresolved notes sections)."""

    def seed_noun(m: re.Match) -> str:
        label = _label_for(m.group(2))
        noun = m.group(0).rsplit(" ", 1)[1]
        keep = not re.search(NOUN, label)
        return (f"{m.group(1)} " if m.group(1) else "") + label + (f" {noun}" if keep else "")

    text = RE_SEED_NOUN.sub(seed_noun, text)
    text = RE_SEED.sub(lambda m: _label_for(m.group(1)), text)
    unresolved: list[str] = []

    def extract(m: re.Match) -> str:
        section = m.group(2)
        key = _resolve(section, text, m.start())
        if key is None:
            unresolved.append(m.group(0))
            return m.group(0)
        if section[0].isdigit():
            section = "section " + section
        return f"{_label_for(key)} {section}"

    text = RE_EXTRACT.sub(extract, text)

    def test_row(m: re.Match) -> str:
        head = text[: m.start()]
        if any(head.endswith(label + " ") for label in LABELS.values()):
            return m.group(0)
        return f"{_label_for('000' if m.group(1) == 'A' else '002')} {m.group(0)}"

    text = RE_TEST_ROW.sub(test_row, text)
    return text, unresolved


def _files(paths: list[str]) -> list[Path]:
    out: list[Path] = []
    for arg in paths:
        path = Path(arg).resolve()
        if not path.exists():
            raise SystemExit(_fail(f"no such file or folder: {arg!r} (give existing files or folders)"))
        found = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
        for p in found:
            rel = p.relative_to(ROOT).as_posix() if p.is_relative_to(ROOT) else p.as_posix()
            parts = set(Path(rel).parts)
            if rel in SKIP_FILES or parts & SKIP_DIRS or p.suffix not in SUFFIXES:
                continue
            out.append(p)
    return out


def _fail(message: str) -> int:
    print(f"error: {message}", file=sys.stderr)
    return 2


def _read(path: Path) -> str | None:
    try:
        return path.read_text(encoding="utf-8")
    except (UnicodeDecodeError, OSError):
        return None


def _name(path: Path) -> str:
    return path.relative_to(ROOT).as_posix() if path.is_relative_to(ROOT) else str(path)


def check(files: list[Path]) -> list[str]:
    """Lines ``path:line: text`` that the rewrite would change or cannot resolve."""
    hits = []
    for path in files:
        text = _read(path)
        if text is None:
            continue
        new, unresolved = rewrite(text)
        for n, (a, b) in enumerate(zip(text.splitlines(), new.splitlines()), 1):
            if a != b or any(u in a for u in unresolved):
                hits.append(f"{_name(path)}:{n}: {a.strip()}")
    return hits


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("paths", nargs="+", help="files or folders (searched recursively)")
    ap.add_argument("--check", action="store_true", help="change nothing; exit 1 if any remain")
    args = ap.parse_args(argv)
    files = _files(args.paths)
    if args.check:
        hits = check(files)
        print("\n".join(hits) if hits else f"no internal source citations in {len(files)} files")
        return 1 if hits else 0
    total = 0
    for path in files:
        text = _read(path)
        if text is None:
            continue
        new, unresolved = rewrite(text)
        for section in unresolved:
            print(f"{_name(path)}: cannot tell which source {section!r} belongs to; fix it by hand")
        if new == text:
            continue
        old_lines, new_lines = text.splitlines(), new.splitlines()
        for n, (a, b) in enumerate(zip(old_lines, new_lines), 1):
            if a != b:
                print(f"{_name(path)}:{n}: {b.strip()}")
                total += 1
        path.write_text(new, encoding="utf-8")
    print(f"{total} lines rewritten in {len(files)} files")
    return 0


if __name__ == "__main__":
    sys.exit(main())
