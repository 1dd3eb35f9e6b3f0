"""The project's YAML reader refuses anchors and aliases, and reads everything else as
``yaml.safe_load`` does."""

from __future__ import annotations

import io

import pytest
import yaml

from models.yamlio import YamlAliasError, safe_load_yaml


def test_plain_documents_read_as_safe_load_reads_them():
    text = "a: [1, 2.5, x]\nb: {c: null, d: true}\n"
    assert safe_load_yaml(text) == yaml.safe_load(text)
    assert safe_load_yaml(io.StringIO(text)) == yaml.safe_load(text)
    assert safe_load_yaml("") is None


@pytest.mark.parametrize(("text", "line", "what"), [
    ("a: &x [1, 2]\nb: *x\n", 1, "anchors"),
    ("a: 1\nb:\n  - &y {c: 2}\n", 3, "anchors"),
    ("a: *z\n", 1, "aliases"),
])
def test_anchors_and_aliases_are_refused_with_their_line(text, line, what):
    with pytest.raises(YamlAliasError) as err:
        safe_load_yaml(text)
    assert f"{what} are not accepted" in str(err.value) and f"line {line}" in str(err.value)
    assert isinstance(err.value, yaml.YAMLError)


def test_python_tags_are_still_refused():
    with pytest.raises(yaml.YAMLError):
        safe_load_yaml("!!python/object/apply:os.system ['true']\n")
