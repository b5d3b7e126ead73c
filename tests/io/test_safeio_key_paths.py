"""A non-finite or overflowing number in a JSON or YAML file is refused naming the key path
that holds it (``camera.dist[2]``), not only the file (:mod:`virtus.io.safeio`)."""

from __future__ import annotations

import pytest

from virtus.errors import InputError
from virtus.io.safeio import parse_json, parse_yaml


@pytest.mark.parametrize(
    ("text", "tail"),
    [
        ('{"camera": {"dist": [0, 0, NaN]}}', "got 'NaN' in camera.dist[2]"),
        ('{"a": 1, "b": {"c": -Infinity}}', "got '-Infinity' in b.c"),
        ('{"a": 1e999}', "got '1e999' in a"),
        ('[1, [2, Infinity]]', "got 'Infinity' in [1][1]"),
        ('{"a": NaN, "b": NaN}', "got 'NaN' in a"),  # the first in the file
        ("NaN", "got 'NaN'"),
    ],
)  # fmt: skip
def test_json_names_the_key_path(text: str, tail: str) -> None:
    with pytest.raises(InputError, match=r"^rig r\.json: expected ") as error:
        parse_json(text, "rig r.json")
    assert str(error.value).endswith(tail)


@pytest.mark.parametrize(
    ("text", "tail"),
    [
        ("objects:\n  - {type: sphere, radius_m: .nan}\n",
         "got '.nan at line 2' in objects[0].radius_m"),
        ("ambient: .inf\n", "got '.inf at line 1' in ambient"),
        ("a: [1, [2, 1.0e+400]]\n", "got '1.0e+400 at line 1' in a[1][1]"),
        ("- {a: {b: [0, -.inf]}}\n", "in [0].a.b[1]"),
        ("a: &x {b: .nan}\nc: *x\n", "in a.b"),
        ("seed: 1" + "0" * 400 + "\n", "in seed"),
        (".nan\n", "got '.nan at line 1'"),
    ],
)  # fmt: skip
def test_yaml_names_the_key_path(text: str, tail: str) -> None:
    with pytest.raises(InputError, match=r"^scene s\.yaml: expected ") as error:
        parse_yaml(text, "scene s.yaml")
    assert str(error.value).endswith(tail)


def test_finite_documents_are_unchanged() -> None:
    assert parse_json('{"a": [1, 2.5, {"b": -3e10}]}', "x") == {"a": [1, 2.5, {"b": -3e10}]}
    assert parse_yaml("a: [1, 2.5, {b: -3.0e+10}]\n", "x") == {"a": [1, 2.5, {"b": -3e10}]}
    assert parse_json('{"a": NaN}', "x", allow_nan=True)["a"] != 0.0  # reports keep NaN
