"""A mode spec keeps every part on every surface: `RenderSettings.parse` is the one parser, the commands' --mode and
--modes go through it (property tests on each command's own argument handling), an option fills only what the spec
leaves unset and one that disagrees with it is one line, exit 2."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from helpers import random_scene
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import gbviewer as gb
from gbviewer import cli
from gbviewer.cli import main
from gbviewer.core.errors import GBViewerError, RenderError
from gbviewer.render import Mode, RenderSettings
from gbviewer.render.modes import MAX_QUEUE, STOPTHEPOP_QUEUE
from gbviewer.render.presets import PRESETS
from gbviewer.render.view_filter import ViewFilter

VIEW = ["--orbit", "30,20,0", "--width", "320", "--height", "240", "--scale", "1/8"]  # 40x30 pixels


def spec_view(scene: gb.Scene) -> gb.Camera:
    return gb.orbit_camera(scene, 30, 20, width=320, height=240).at_sampling_rate(1 / 8)


@pytest.mark.parametrize("spec, label, n", [("scalar:3", "scalar 3x3", 3), ("preset:spark:2", "preset:spark 2x2", 2)])
def test_render_keeps_the_specs_supersampling(tmp_path, capsys, bundled_scene, spec, label, n):
    out = tmp_path / "f.npy"
    assert main(["render", str(gb.DEFAULT_SCENE), *VIEW, "--mode", spec, "--backend", "cpu", "--out", str(out)]) == 0
    assert f" {label} on cpu" in capsys.readouterr().out
    np.testing.assert_array_equal(np.load(out), gb.render(bundled_scene, spec_view(bundled_scene), spec).rgb)
    assert not np.array_equal(np.load(out), gb.render(bundled_scene, spec_view(bundled_scene), "scalar").rgb)


def test_trace_keeps_presets_and_lod(tmp_path, bundled_scene):
    specs = ["preset:antimatter15", "scalar+lod:40"]
    assert (
        main(
            [
                "trace",
                str(gb.DEFAULT_SCENE),
                *VIEW,
                "--pixel",
                "20,15",
                "--modes",
                ",".join(specs),
                "--json",
                str(tmp_path / "t.json"),
            ]
        )
        == 0
    )
    traces = json.loads((tmp_path / "t.json").read_text())["traces"]
    assert [t["mode"] for t in traces] == [RenderSettings.parse(s).label for s in specs]
    cam = spec_view(bundled_scene)
    for trace, spec in zip(traces, specs):
        np.testing.assert_allclose(trace["color"], gb.render(bundled_scene, cam, spec).rgb[15, 20], atol=1e-5)
    assert traces[0]["color"] != pytest.approx(gb.render(bundled_scene, cam, "scalar").rgb[15, 20], abs=1e-5)


@pytest.mark.parametrize(
    "command, extra, says",
    [
        ("render", ["--mode", "scalar:3", "--supersample", "2", "--out", "x.png"], "sets supersample 3; supersample 2"),
        ("render", ["--mode", "scalar+lod:4", "--lod", "8", "--out", "x.png"], "sets lod 4; lod 8"),
        ("render", ["--mode", "preset:antimatter15", "--sh-degree", "3", "--out", "x.png"], "sets sh degree 0"),
        ("trace", ["--modes", "scalar,mip:3", "--supersample", "2", "--pixel", "1,1"], "'mip:3' sets supersample 3"),
    ],
)
def test_an_option_that_disagrees_with_the_spec_is_one_line(tmp_path, capsys, monkeypatch, command, extra, says):
    monkeypatch.chdir(tmp_path)
    assert main([command, str(gb.DEFAULT_SCENE), *VIEW, *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and says in err and "give one of them" in err
    assert not (tmp_path / "x.png").exists()


def test_options_fill_only_what_the_spec_leaves_unset():
    assert RenderSettings.parse("scalar", supersample=2, lod=3.0) == RenderSettings(supersample=2, lod=3.0)
    assert RenderSettings.parse("scalar:2", supersample=2).supersample == 2  # agreeing is not a conflict
    assert RenderSettings.parse("preset:antimatter15", sh_degree=None).sh_degree == 0
    assert RenderSettings.parse(Mode.MIP, supersample=4) == RenderSettings(Mode.MIP, 4)
    with pytest.raises(RenderError, match="sets view filter"):
        RenderSettings.parse("preset:spark", view_filter=ViewFilter(0.1))
    with pytest.raises(RenderError, match="sets supersample 3"):  # the library takes the same rule
        gb.render(random_scene(5), gb.orbit_camera(random_scene(5), width=8, height=8), "scalar:3", supersample=1)


def test_settings_named_after_a_preset_are_that_preset():
    """RenderSettings(preset="spark") drew plain scalar labelled 'preset:spark' (the name alone, none of its
    filter or rules); an unknown name was kept too. Both are one line; parse makes the preset's settings."""
    with pytest.raises(RenderError, match=r"preset 'spark': is scalar, .*RenderSettings.parse\('preset:spark'\)"):
        RenderSettings(preset="spark")
    with pytest.raises(RenderError, match="preset 'nope': unknown; expected one of inria"):
        RenderSettings(preset="nope")
    with pytest.raises(RenderError, match="preset 'antimatter15'"):
        dataclasses.replace(RenderSettings.parse("preset:antimatter15"), sh_degree=3)
    assert RenderSettings(preset="inria").spec == "preset:inria"


def test_a_spec_with_an_exponent_reads_back():
    """RenderSettings(lod=1e6).spec wrote 'scalar+lod:1e+06', whose '+' split the spec: eval (which hands its modes
    to the workers as specs) refused its own --lod 1000000. A spec writes no '+' in a number, and reads one."""
    for lod in (1e6, 1e-5, 123456.7):
        s = RenderSettings(supersample=2, lod=lod)
        assert "e+" not in s.spec and RenderSettings.parse(s.spec) == s
    assert (
        RenderSettings.parse("scalar+lod:1e+06") == RenderSettings.parse("scalar+lod:1e06") == RenderSettings(lod=1e6)
    )
    with pytest.raises(RenderError, match="expected MODE"):
        RenderSettings.parse("scalar+06")


def test_render_and_trace_take_a_render_settings_alike():
    """trace_pixel took a RenderSettings as its mode while gb.render read its repr as a spec and refused it in a
    garbled line; both take one now, by one rule (it says everything: other options are refused)."""
    scene = random_scene(40, seed=14)
    cam = gb.orbit_camera(scene, width=12, height=8)
    settings = RenderSettings.parse("preset:spark:2+lod:3", background=(0.2, 0.3, 0.4))
    frame = gb.render(scene, cam, settings)
    assert np.array_equal(frame.rgb, gb.render(scene, cam, "preset:spark:2+lod:3", background=(0.2, 0.3, 0.4)).rgb)
    assert np.allclose(gb.trace_pixel(scene, cam, 5, 4, settings).color, frame.rgb[4, 5], atol=1e-6)
    for call in (
        lambda: gb.render(scene, cam, settings, supersample=2),
        lambda: gb.trace_pixel(scene, cam, 5, 4, settings, background=(1, 1, 1)),
    ):
        with pytest.raises(RenderError, match="a RenderSettings says everything"):
            call()


# ---- property: a spec string reaches every command's settings whole ------------------------------------------------

PRESET_NAMES = sorted(PRESETS)
MODES = [m.label for m in Mode]


@st.composite
def specs(draw) -> tuple[str, RenderSettings, bool]:
    """A spec text, the RenderSettings it means (built field by field, not through parse) where the default precision
    is exact, and whether the text names a precision."""
    n = draw(st.integers(1, 8))
    lod = draw(st.none() | st.floats(0, 1e6, allow_nan=False, allow_subnormal=False))
    explicit_n = n > 1 or draw(st.booleans())
    tail = (f":{n}" if explicit_n else "") + ("" if lod is None else f"+lod:{lod!r}")
    if draw(st.booleans()):
        p = PRESETS[draw(st.sampled_from(PRESET_NAMES))]
        expected = RenderSettings(
            Mode.parse(p.mode), n, sh_degree=p.sh_degree, view_filter=p.view_filter, preset=p.name, lod=lod
        )
        return f"preset:{draw(st.sampled_from([p.name, p.name.upper()]))}{tail}", expected, False
    name = draw(st.sampled_from([*MODES, "supersample"]))
    mode = Mode.SCALAR if name == "supersample" else Mode.parse(name)
    spelled = draw(st.sampled_from([name, name.upper(), name.replace("_", "-")]))
    if mode == Mode.GAUSSIAN_BLENDING:  # its precision named or not: '+fast', '+exact' before '+lod'
        named = draw(st.sampled_from(["", "fast", "exact"]))
        head = (f":{n}" if explicit_n else "") + (f"+{named}" if named else "")
        spec = spelled + head + ("" if lod is None else f"+lod:{lod!r}")
        return spec, RenderSettings(mode, n, lod=lod, precision=named or "exact"), bool(named)
    if mode != Mode.STOPTHEPOP:
        return spelled + tail, RenderSettings(mode, n, lod=lod), False
    queue = draw(st.integers(0, MAX_QUEUE))  # 'stopthepop:K[:N]': its queue length comes before the supersampling
    explicit_k = queue != STOPTHEPOP_QUEUE or explicit_n or draw(st.booleans())
    spec = spelled + (f":{queue}" if explicit_k else "") + tail
    return spec, RenderSettings(mode, n, lod=lod, queue=queue), False


PICTURES = {"render", "compare", "video"}  # commands whose unnamed gaussian_blending precision is fast


def expected_by(command: str, case: tuple[str, RenderSettings, bool]) -> RenderSettings:
    """What `command` makes of a drawn spec: the picture commands draw gaussian_blending fast unless it says +exact."""
    _, settings, named = case
    return settings if named or command not in PICTURES else dataclasses.replace(settings, precision="fast")


class Seen(GBViewerError):
    """Raised by the spy once the command has read its modes: nothing is rendered."""


COMMANDS = {  # the arguments each command needs besides its modes (its own parser fills the rest)
    "render": lambda spec, out: ["render", "scene.ply", "--mode", spec, "--out", str(out / "x.png")],
    "trace": lambda spec, out: ["trace", "scene.ply", "--modes", spec, "--pixel", "0,0"],
    "compare": lambda spec, out: ["compare", "scene.ply", "--modes", spec, "--out", str(out / "x.png")],
    "video": lambda spec, out: ["video", "scene.ply", "--modes", spec, "--out", str(out / "x.mp4")],
    "flicker": lambda spec, out: ["flicker", "scene.ply", "--modes", spec, "--out", str(out / "f")],
    "bench": lambda spec, out: ["bench", "scene.ply", "--modes", spec, "--backends", "cpu"],
    "eval": lambda spec, out: ["eval", "scene.ply", "--data", str(out), "--modes", spec],
}


def read_modes(monkeypatch, argv: list[str]) -> list[RenderSettings]:
    """What the command's own code makes of its mode arguments: main(argv) runs it up to its `settings_of`."""
    seen: list[list[RenderSettings]] = []

    def spy(args, *a, **k):
        seen.append(real(args, *a, **k))
        raise Seen("read")

    from gbviewer.cli import options

    real = options.settings_of
    for module in cli.COMMANDS:
        if hasattr(module, "settings_of"):
            monkeypatch.setattr(module, "settings_of", spy)
        if hasattr(module, "load"):
            monkeypatch.setattr(module, "load", lambda path, *a, **k: random_scene(5))
    assert main(argv) == 2 and len(seen) == 1, argv
    return seen[0]


@pytest.mark.parametrize("command", sorted(COMMANDS))
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=specs(), other=specs())
def test_a_spec_reaches_each_command_whole(tmp_path, monkeypatch, command, case, other):
    spec, exact, _ = case
    assert RenderSettings.parse(spec) == exact and RenderSettings.parse(exact.spec) == exact
    expected, also = expected_by(command, case), expected_by(command, other)
    got = read_modes(monkeypatch, COMMANDS[command](spec, tmp_path))
    assert got == [expected]
    if command != "render" and also.spec != expected.spec:  # a list keeps each one's parts too
        got = read_modes(monkeypatch, COMMANDS[command](f"{spec},{other[0]}", tmp_path))
        assert got == [expected, also]
