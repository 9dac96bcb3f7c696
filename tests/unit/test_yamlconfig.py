"""The one reader of a program's YAML file (qos/yamlconfig.py): the file read, empty refused, errors as the
program's own type with the shared helpers' text."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from micros_rt.exceptions import MicrosRtError, ProfileError
from micros_rt.qos.yamlconfig import expect_mapping, load_document, parse_document


class _ConfigError(MicrosRtError, ValueError):
    pass


def _keys(root: yaml.Node, source: str) -> list[str]:
    expect_mapping(root, source, "the top level", "a mapping")
    assert isinstance(root, yaml.MappingNode)
    if any(k.value == "bad" for k, _ in root.value):
        raise _ConfigError(f"{source}: bad")
    return [k.value for k, _ in root.value]


def test_parse_document_gives_the_root_to_the_parser_and_errors_as_the_program_s_type() -> None:
    assert parse_document("a: 1\nb: 2\n", _keys, source="f.yaml", empty="empty", error=_ConfigError) == ["a", "b"]
    cases = [("", "f.yaml: empty file; say something"),
             ("[1", "f.yaml: not valid YAML"),
             ("- 1\n", "f.yaml:1: the top level: expected a mapping, got a list"),
             ("bad: 1\n", "f.yaml: bad")]
    for text, words in cases:
        with pytest.raises(_ConfigError) as info:
            parse_document(text, _keys, source="f.yaml", empty="empty file; say something", error=_ConfigError)
        assert str(info.value).startswith(words), info.value
        assert not isinstance(info.value, ProfileError)


def test_load_document_names_the_file(tmp_path: Path) -> None:
    (tmp_path / "c.yaml").write_text("x: 1\n")
    assert load_document(tmp_path / "c.yaml", _keys, what="the thing", empty="empty") == ["x"]
    with pytest.raises(ProfileError, match=r"nope.yaml: cannot read the thing: \[Errno 2\]"):
        load_document(str(tmp_path / "nope.yaml"), _keys, what="the thing", empty="empty")
    (tmp_path / "e.yaml").write_text("\n")
    with pytest.raises(_ConfigError, match=r"e.yaml: nothing here$"):
        load_document(tmp_path / "e.yaml", _keys, what="the thing", empty="nothing here", error=_ConfigError)
