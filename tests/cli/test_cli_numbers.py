"""Every numeric option of the command line goes through `gbviewer.cli.argtypes` (validate-backed): non-finite,
overflowing, zero and negative values where they make no sense give exit status 2 and one stderr line naming the
option, before anything is loaded."""

from __future__ import annotations

import argparse
import math

import pytest
from helpers import patch_commands
from hypothesis import given, settings
from hypothesis import strategies as st

import gbviewer as gb
from gbviewer import cli
from gbviewer.cli import argtypes
from gbviewer.cli.argtypes import Number, Numbers, Rate
from gbviewer.core.validate import F32_MAX
from gbviewer.model.camera import MAX_RATE, MIN_RATE

NUMERIC = (Number, Numbers, Rate)
NON_FINITE = ("nan", "inf", "-inf", "1e400", "-1e400")


def subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = cli.build_parser()
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices


def numeric_options() -> list[tuple[str, str, object]]:
    """(command, option, type) of every option whose type is one of the argtypes factories."""
    return [
        (name, action.option_strings[-1], action.type)
        for name, p in subparsers().items()
        for action in p._actions
        if isinstance(action.type, NUMERIC)
    ]


def accepts(check, text: str) -> bool:
    try:
        check(text)
    except argparse.ArgumentTypeError:
        return False
    return True


def bad_values(kind) -> list[str]:
    """Values `kind` must refuse: non-finite and overflowing ones always, 0 and -1 where its range excludes them;
    for tuples, each of those in each position of an otherwise valid tuple."""
    if isinstance(kind, Numbers):
        base = [next(v for v in ("1", "0.5", "0") if accepts(part, v)) for part in kind.parts]
        return [
            kind.sep.join(base[:i] + [bad] + base[i + 1 :])
            for i, part in enumerate(kind.parts)
            for bad in bad_values(part)
        ]
    return [v for v in (*NON_FINITE, "0", "-1") if v in NON_FINITE or not accepts(kind, v)]


CASES = [(cmd, opt, value) for cmd, opt, kind in numeric_options() for value in bad_values(kind)]


def test_no_option_bypasses_the_checked_types():
    """A new numeric option cannot forget the checks: plain int/float types (and choices=range) are not used."""
    for name, p in subparsers().items():
        for action in p._actions:
            assert action.type not in (int, float), (name, action.option_strings)
            assert not isinstance(action.choices, range), (name, action.option_strings)


def test_the_enumeration_covers_the_sizes_counts_and_rates():
    options = {(cmd, opt) for cmd, opt, _ in numeric_options()}
    expected = {
        ("render", o)
        for o in (
            "--camera",
            "--orbit",
            "--width",
            "--height",
            "--supersample",
            "--scale",
            "--background",
            "--sh-degree",
        )
    }
    expected |= {
        ("video", o)
        for o in (
            "--from",
            "--to",
            "--frames",
            "--seconds",
            "--fps",
            "--max-frames",
            "--size",
            "--inset",
            "--crf",
            "--width",
        )
    }
    expected |= {
        ("bench", o) for o in ("--rates", "--views", "--size", "--repeat", "--flicker-frames", "--flicker-step")
    }
    expected |= {("compare", "--rates"), ("compare", "--inset"), ("view", "--orbit"), ("demo", "--height")}
    assert expected <= options
    zero_refused = {(cmd, opt) for cmd, opt, value in CASES if value == "0" or value.endswith(",0")}
    for must in [
        ("render", "--width"),
        ("video", "--frames"),
        ("video", "--fps"),
        ("video", "--seconds"),
        ("bench", "--views"),
        ("bench", "--repeat"),
        ("render", "--scale"),
        ("video", "--max-frames"),
    ]:
        assert must in zero_refused
    assert any(opt == "--size" and "0" in value.split("x") for _, opt, value in CASES)


@pytest.mark.parametrize("cmd, opt, value", CASES, ids=[f"{c} {o}={v}" for c, o, v in CASES])
def test_bad_number_one_line_exit_2(cmd, opt, value, capsys, monkeypatch):
    patch_commands(monkeypatch, "load", lambda *a: pytest.fail("loaded a scene despite a bad option"))
    assert cli.main([cmd, f"{opt}={value}"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.splitlines()) == 1, err
    assert err.startswith(f"gbviewer {cmd}: error: argument {opt}: ") and err.endswith(f"(see gbviewer {cmd} --help)\n")


@pytest.mark.parametrize(
    "argv, line",
    [
        (["render", "s.ply", "--width", "-5"], "gbviewer render: error: argument --width: expected >= 1, got -5"),
        (["render", "s.ply", "--width", "0"], "gbviewer render: error: argument --width: expected >= 1, got 0"),
        (["video", "s.ply", "--frames", "0"], "gbviewer video: error: argument --frames: expected >= 1, got 0"),
        (
            ["render", "s.ply", "--scale", "1e400"],
            "gbviewer render: error: argument --scale: sampling rate '1e400': expected a finite number, got '1e400'",
        ),
        (
            ["render", "s.ply", "--orbit", "30,20,inf"],
            "gbviewer render: error: argument --orbit: DIST: expected a finite float32 number, got 'inf'",
        ),
        (
            ["video", "s.ply", "--fps", "inf"],
            "gbviewer video: error: argument --fps: expected a finite number, got 'inf'",
        ),
        (
            ["video", "s.ply", "--seconds", "nan"],
            "gbviewer video: error: argument --seconds: expected a finite number, got 'nan'",
        ),
        (["bench", "s.ply", "--views", "0"], "gbviewer bench: error: argument --views: expected >= 1, got 0"),
        (
            ["render", "s.ply", "--background", "1e39,0,0"],
            "gbviewer render: error: argument --background: R: expected <= 1, got 1e+39",
        ),
        (
            ["render", "s.ply", "--orbit", "30,20"],
            "gbviewer render: error: argument --orbit: expected AZ,EL,DIST, got '30,20'",
        ),
        (["render", "s.ply", "--out", "x.png", "--bogus"], "gbviewer render: error: unrecognized arguments: --bogus"),
        (["render", "s.ply"], "gbviewer render: error: the following arguments are required: --out"),
    ],
)
def test_issue_cases(argv, line, capsys):
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.splitlines() == [f"{line} (see {line.split(':')[0]} --help)"]


def test_help_still_works(capsys):
    assert cli.main(["render", "--help"]) == 0
    assert "--max-frames" in (cli.main(["video", "-h"]) == 0 and capsys.readouterr().out)


def _within(part: Number, x: float) -> bool:
    return (
        math.isfinite(x)
        and (part.lo is None or (x > part.lo if part.lo_open else x >= part.lo))
        and (part.hi is None or x <= part.hi)
        and (not part.f32 or abs(x) <= F32_MAX)
        and (not part.integral or isinstance(x, int))
    )


KINDS = sorted({repr(kind): kind for _, _, kind in numeric_options()}.items())
number_text = st.one_of(
    st.text(max_size=60),
    st.floats().map(repr),
    st.integers().map(str),
    st.sampled_from(
        ["nan", "inf", "-inf", "1e400", "-0", "1_0", "0x10", " 7 ", "1/8", "1/0", "3e38", "3.5e38", "1e-400", "١٢"]
    ),
)


@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_factories_return_checked_values_or_one_line_errors(data):
    """Random text and numbers: every factory gives a finite value in its range, or ArgumentTypeError in one line."""
    _, kind = data.draw(st.sampled_from(KINDS))
    if isinstance(kind, Numbers):
        text = kind.sep.join(data.draw(st.lists(number_text, min_size=1, max_size=len(kind.parts) + 1)))
    elif isinstance(kind, Rate) and kind.many:
        text = ",".join(data.draw(st.lists(number_text, min_size=0, max_size=4)))
    else:
        text = data.draw(number_text)
    try:
        value = kind(text)
    except argparse.ArgumentTypeError as exc:
        assert len(str(exc).splitlines()) == 1 and str(exc).strip()
        return
    if isinstance(kind, Numbers):
        assert len(value) == len(kind.parts) and all(_within(p, x) for p, x in zip(kind.parts, value))
    elif isinstance(kind, Rate):
        assert all(MIN_RATE <= r <= MAX_RATE for r in (value if kind.many else [value]))
    else:
        assert _within(kind, value)


def test_rendered_size_is_bounded_before_rendering(tmp_path, capsys, monkeypatch):
    scene, out = str(gb.DEFAULT_SCENE), str(tmp_path / "x.png")
    monkeypatch.setattr(cli.render, "get_renderer", lambda *a: pytest.fail("rendered an oversized image"))
    assert cli.main(["render", scene, "--width", "640", "--scale", "64", "--out", out]) == 2
    assert capsys.readouterr().err == (
        f"gbviewer: error: --scale: image side rendered at x64: expected <= {argtypes.MAX_SIDE}, got 40960\n"
    )
