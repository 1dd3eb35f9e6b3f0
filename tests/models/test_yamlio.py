"""The project's YAML reader refuses anchors and aliases, and reads everything else as
``yaml.safe_load`` does."""

from __future__ import annotations

import io

import pytest
import yaml

from models.yamlio import YamlAliasError, _load_pure, safe_load_yaml


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
@pytest.mark.parametrize("load", [safe_load_yaml, _load_pure])
def test_anchors_and_aliases_are_refused_with_their_line(text, line, what, load):
    with pytest.raises(YamlAliasError) as err:
        load(text)
    assert f"{what} are not accepted" in str(err.value) and f"line {line}" in str(err.value)
    assert isinstance(err.value, yaml.YAMLError)


def test_python_tags_are_still_refused():
    with pytest.raises(yaml.YAMLError):
        safe_load_yaml("!!python/object/apply:os.system ['true']\n")


def test_the_c_and_the_python_paths_read_the_same():
    text = ("name: x\nswing:\n  polygon:\n    vertices: [[1, 0, 0], [0, 1, 0.5], [0, 0, 1]]\n"
            "    interior: [0.6, 0.5, 0.6]\nprovenance: {a: [1.5e-3, .inf, null, 'two words']}\n")
    assert safe_load_yaml(text) == _load_pure(text) == yaml.safe_load(text)
