"""The validation layer: every untrusted number and JSON document, including the edges of float and int."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from gbviewer.core.errors import GBViewerError, InvalidValue
from gbviewer.core.validate import F32_MAX, array, declared_count, field, integer, parse_json, read_json, real


@pytest.mark.parametrize(
    "bad", ["nan", "inf", "-inf", "1e400", float("nan"), float("inf"), "x", "", None, True, [1.0], "1,5"]
)
def test_real_rejects_what_is_not_a_finite_number(bad):
    with pytest.raises(InvalidValue, match="^--fps: expected"):
        real(bad, "--fps")


def test_real_ranges_and_float32():
    assert real("2.5", "x", lo=0, lo_open=True) == 2.5
    with pytest.raises(InvalidValue, match="expected > 0"):
        real(0, "x", lo=0, lo_open=True)
    with pytest.raises(InvalidValue, match="expected >= 1"):
        real(0.5, "x", lo=1)
    with pytest.raises(InvalidValue, match="expected <= 8"):
        real(9, "x", hi=8)
    assert real(F32_MAX, "x", f32=True) == F32_MAX
    with pytest.raises(InvalidValue, match="float32"):
        real(1e39, "--background", f32=True)  # finite as a double, +inf once cast
    assert np.isfinite(np.float32(real(F32_MAX, "x", f32=True)))


@pytest.mark.parametrize("good,expected", [("3", 3), (3, 3), (3.0, 3), ("3.0", 3), (np.int64(7), 7), (" 12 ", 12)])
def test_integer_accepts_integral_values(good, expected):
    assert integer(good, "n") == expected


@pytest.mark.parametrize("bad", ["2.5", 2.5, "nan", "inf", "1e400", True, None, "9" * 5000, "0x10", [3]])
def test_integer_rejects(bad):
    with pytest.raises(InvalidValue, match="^--views: expected"):
        integer(bad, "--views")


def test_integer_text_that_is_no_number_says_integer():
    with pytest.raises(InvalidValue, match="^'width': expected an integer, got 'abc'$"):
        integer("abc", "'width'")


def test_integer_bounds_name_the_option():
    with pytest.raises(InvalidValue, match=r"^--views: expected >= 1, got 0$"):
        integer(0, "--views", lo=1)
    with pytest.raises(InvalidValue, match=r"^n: expected <= 10"):
        integer(10**4000, "n", hi=10)


def test_declared_count_is_bounded_by_the_bytes_present():
    assert declared_count(10, "vertex", item_bytes=4, available=40) == 10
    with pytest.raises(InvalidValue, match="only 39 bytes"):
        declared_count(10, "vertex", item_bytes=4, available=39)
    with pytest.raises(InvalidValue):
        declared_count(2**40, "extra", item_bytes=1, available=1 << 20)
    with pytest.raises(InvalidValue):
        declared_count(-1, "vertex", item_bytes=4, available=40)


@pytest.mark.parametrize(
    "text,match",
    [
        ('{"w": Infinity}', "not a finite number"),
        ("[NaN]", "not a finite number"),
        ("[1e400]", "not a finite"),
        ('{"w": ' + "9" * 5000 + "}", "not valid JSON"),
        ("[" * 100_000 + "]" * 100_000, "nested deeper"),
        ("[" * 40 + "]" * 40, "nested deeper"),
        ('{"a": 1', "not valid JSON"),
        (b"\xff\xfe{", "not valid JSON"),
    ],
)
def test_parse_json_rejects_hostile_documents(text, match):
    with pytest.raises(InvalidValue, match=f"^doc.json: .*{match}"):
        parse_json(text, "doc.json")


def test_parse_json_size_cap_and_field(tmp_path):
    assert parse_json('{"a": [1, 2.5]}', "d") == {"a": [1, 2.5]}
    with pytest.raises(InvalidValue, match="more than the 10 allowed"):
        parse_json("[" + "1," * 10 + "1]", "d", max_bytes=10)
    path = tmp_path / "big.json"
    path.write_text("[" + " " * 100 + "]")
    with pytest.raises(InvalidValue, match=f"^{path}: .*more than the 50 allowed"):
        read_json(path, max_bytes=50)
    with pytest.raises(InvalidValue, match="cannot read"):
        read_json(tmp_path / "missing.json")
    with pytest.raises(InvalidValue, match="missing 'fx'"):
        field({"fy": 1}, "fx", "cameras.json entry 0")
    with pytest.raises(InvalidValue, match="expected a JSON object, got list"):
        field([], "fx", "cameras.json entry 0")
    assert issubclass(InvalidValue, GBViewerError)


def test_array_checks_shape_and_values():
    np.testing.assert_array_equal(array([[1, 0, 0], [0, 1, 0], [0, 0, 1]], "R", (3, 3)), np.eye(3))
    assert array(np.ones(3), "t", (3,), f32=True).dtype == np.float64
    for bad, match in [
        ([1, 2], "3 numbers, got"),
        ("123", "3 numbers"),
        ({"x": 1}, "3 numbers"),
        ([1, [2], 3], "3 numbers"),
        ([1, 2, 10**400], "3 numbers"),
        ([1, "a", 3], "3 numbers"),
        ([1, 2, float("nan")], "finite float32 numbers, got nan"),
        ([0, 0, 1e39], "finite float32 numbers"),
    ]:
        with pytest.raises(InvalidValue, match=f"^position: expected {match}"):
            array(bad, "position", (3,), f32=True)
    with pytest.raises(InvalidValue, match="^R: expected a 3x3 matrix"):
        array(np.eye(4), "R", (3, 3))
    assert array([0, 0, 1e39], "p", (3,))[2] == 1e39  # without f32: any finite float64


@given(
    st.one_of(
        st.floats(allow_nan=True, allow_infinity=True), st.integers(), st.text(max_size=50), st.booleans(), st.none()
    )
)
def test_real_either_returns_a_finite_bounded_value_or_raises_one_line(value):
    try:
        x = real(value, "opt", lo=0, hi=1e6, f32=True)
    except InvalidValue as exc:
        assert "\n" not in str(exc) and str(exc).startswith("opt: ")
    else:
        assert math.isfinite(x) and 0 <= x <= 1e6


@given(
    st.recursive(
        st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=5),
        lambda kids: st.lists(kids, max_size=3) | st.dictionaries(st.text(max_size=3), kids, max_size=3),
        max_leaves=30,
    )
)
def test_parse_json_roundtrip_or_one_line_error(doc):
    text = json.dumps(doc)  # may contain NaN / Infinity, which must be refused
    try:
        back = parse_json(text, "d", max_depth=8)
    except InvalidValue as exc:
        assert "\n" not in str(exc)
    else:
        assert back == doc
