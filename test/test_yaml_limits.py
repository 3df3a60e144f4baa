"""Every YAML reader (friction_ros.core.yaml_files) refuses input that would take unbounded time or
memory, quickly and in one line naming the input and the limit: alias bombs, recursive aliases,
deep nesting, oversized files, devices and pipes; ordinary files (aliases included) load as before.
Bag metadata and offered QoS strings go through the same reader."""

from __future__ import annotations

import os
import time

import pytest
import yaml

from friction_ros.core import yaml_files
from friction_ros.core.validation import ParameterError
from friction_ros.core.yaml_files import (
    MAX_ALIAS_EXPANSION,
    MAX_DEPTH,
    MAX_FILE_BYTES,
    YamlLimitError,
    check_parameter_file,
    load_yaml,
    parse_yaml,
)


def _bomb(levels: int, fan: int = 4) -> str:
    rows = ["n0: &n0 {node: {ros__parameters: {x: 1}}}"]
    rows += [
        f"n{i}: &n{i} {{" + ", ".join(f"k{j}: *n{i - 1}" for j in range(fan)) + "}" for i in range(1, levels)
    ]
    return "\n".join(rows) + "\n"


def test_an_alias_bomb_is_refused_at_once_with_the_limit(tmp_path):
    path = tmp_path / "bomb.yaml"
    path.write_text(_bomb(30))
    assert len(path.read_bytes()) < 1500  # a kilobyte ...
    t0 = time.perf_counter()
    with pytest.raises(YamlLimitError) as err:
        check_parameter_file(path)
    assert time.perf_counter() - t0 < 5.0  # ... that expands to 4^29 nodes is refused, not expanded (years)
    text = str(err.value)
    assert str(path) in text and f"limit of {MAX_ALIAS_EXPANSION}" in text and "\n" not in text
    size = 7  # nodes of n0 = {node: {ros__parameters: {x: 1}}}
    expanded, distinct = 1 + 1 + size, 1 + 1 + size  # the document's mapping, key n0 and its value
    for _ in range(29):
        size = 1 + 4 * (1 + size)  # a mapping of 4 keys, each value the previous level
        expanded, distinct = expanded + 1 + size, distinct + 1 + 5  # in the file: key, mapping, 4 keys
    assert f"expand to {expanded - distinct:.3g} more nodes" in text


def test_aliases_below_the_limit_load_as_plain_yaml():
    text = _bomb(6)  # 4^5 copies of a 4-node mapping: ~5,000 nodes added
    assert parse_yaml(text) == yaml.safe_load(text)
    gains = "pid: &pid {p: 1.0, i: 0.1, d: 0.01}\nj1: {gains: *pid}\nj2: {gains: *pid}\n"
    assert parse_yaml(gains)["j2"]["gains"] == {"p": 1.0, "i": 0.1, "d": 0.01}


@pytest.mark.parametrize(
    "text, words",
    [
        ("a: &a [*a]", ["recursive alias"]),
        ("a: &a {b: *a}", ["recursive alias"]),
        (
            "x: " + "[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1),
            ["nested deeper", f"limit of {MAX_DEPTH}", "line 1"],
        ),
        ("x: " + "[" * 200_000, ["nested deeper"]),  # Python's recursion limit is never reached
        (
            "a0: &a0 [1]\n" + "".join(f"a{i}: &a{i} [*a{i - 1}]\n" for i in range(1, MAX_DEPTH + 2)),
            ["levels deep with its aliases"],
        ),
    ],
)
def test_recursion_and_depth_are_refused(text, words):
    with pytest.raises(YamlLimitError) as err:
        parse_yaml(text, "parameter file 'p.yaml'")
    assert str(err.value).startswith("parameter file 'p.yaml' refused: ")
    for w in words:
        assert w in str(err.value)
    assert parse_yaml("x: " + "[" * (MAX_DEPTH - 2) + "]" * (MAX_DEPTH - 2)) is not None  # just inside: fine


def test_size_devices_and_pipes_are_refused_without_reading_them(tmp_path):
    big = tmp_path / "big.yaml"
    big.write_text("x: '" + "a" * MAX_FILE_BYTES + "'\n")
    with pytest.raises(YamlLimitError, match=f"bytes, over the limit of {MAX_FILE_BYTES} bytes"):
        load_yaml(big, "parameter file")
    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)  # opening it would block until a writer comes
    for path in (fifo, "/dev/zero"):
        with pytest.raises(ParameterError, match="not a regular file"):
            load_yaml(path, "parameter file")
    ok = tmp_path / "ok.yaml"
    ok.write_text("x: '" + "a" * (MAX_FILE_BYTES - 100) + "'\n")
    assert len(load_yaml(ok)["x"]) == MAX_FILE_BYTES - 100


def test_syntax_errors_still_name_line_and_column():
    with pytest.raises(ParameterError, match=r"^f is not valid YAML \(line 2, column 1\)"):
        parse_yaml("a: [1,\n: : :", "f")


def test_bag_metadata_and_qos_strings_use_the_same_limits(tmp_path):
    from friction_ros.core.bag import BagError, bag_files, parse_qos

    with pytest.raises(BagError, match="offered_qos_profiles refused: .*aliases"):
        parse_qos(_bomb(30))
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text(_bomb(30))
    (bag / "x_0.mcap").write_bytes(b"")
    t0 = time.perf_counter()
    _, files = bag_files(bag)  # unusable metadata: the .mcap files of the directory are used instead
    assert files == [bag / "x_0.mcap"] and time.perf_counter() - t0 < 5.0


def test_the_python_parser_is_used_without_libyaml(monkeypatch):
    """The limits do not depend on libyaml: the same checks with PyYAML's own event parser."""
    from yaml.loader import Parser, Reader, Scanner

    class PyEvents(Reader, Scanner, Parser):
        def __init__(self, stream):
            Reader.__init__(self, stream)
            Scanner.__init__(self)
            Parser.__init__(self)

    class Loader(yaml_files.Composer, yaml_files.SafeConstructor, yaml_files.Resolver, PyEvents):
        __init__ = yaml_files._LimitedLoader.__init__
        compose_node = yaml_files._LimitedLoader.compose_node

    monkeypatch.setattr(yaml_files, "_EventParser", PyEvents)
    monkeypatch.setattr(yaml_files, "_LimitedLoader", Loader)
    with pytest.raises(YamlLimitError, match="aliases"):
        parse_yaml(_bomb(30))
    with pytest.raises(YamlLimitError, match="nested deeper"):
        parse_yaml("[" * 1000)
    assert parse_yaml("a: &x {p: 1}\nb: *x") == {"a": {"p": 1}, "b": {"p": 1}}
