"""--seed and --frame on every command that renders a mode: they set the stochastic modes' keep decisions (and only
theirs), reproduce the library's image bit for bit, and a bad value or one that would change nothing is one line with
exit status 2."""

from __future__ import annotations

import re

import numpy as np
import pytest

import gbviewer as gb
from gbviewer import cli
from gbviewer.cli import main
from gbviewer.cli.options import settings_of
from gbviewer.render import Mode

SCENE = str(gb.DEFAULT_SCENE)
COMMANDS = {  # each command that renders modes, with its required arguments
    "render": [SCENE, "--out", "x.png", "--mode", "stochastic:2"],
    "compare": [SCENE, "--out", "x.png", "--modes", "scalar,stochastic:2,stochastic_popfree"],
    "video": [SCENE, "--out", "x.mp4", "--modes", "scalar,stochastic:2,stochastic_popfree"],
    "flicker": [SCENE, "--out", "x", "--modes", "scalar,stochastic:2,stochastic_popfree"],
    "bench": [SCENE, "--modes", "scalar,stochastic:2,stochastic_popfree"],
    "eval": [SCENE, "--data", "d", "--modes", "scalar,stochastic:2,stochastic_popfree"],
    "trace": [SCENE, "--pixel", "1,1", "--modes", "scalar,stochastic:2,stochastic_popfree"],
}


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_sets_seed_and_frame_of_its_stochastic_modes(command):
    args = cli.build_parser().parse_args([command, *COMMANDS[command], "--seed", "4294967295", "--frame", "7"])
    settings = settings_of(args)
    assert any(s.mode == Mode.STOCHASTIC for s in settings)
    for s in settings:
        stochastic = s.mode in (Mode.STOCHASTIC, Mode.STOCHASTIC_POPFREE)
        assert (s.seed, s.frame) == ((2**32 - 1, 7) if stochastic else (0, 0)), s.spec
    args = cli.build_parser().parse_args([command, *COMMANDS[command], "--frame", "2"])
    assert {(s.seed, s.frame) for s in settings_of(args) if s.mode == Mode.STOCHASTIC} == {(0, 2)}


def test_render_is_the_library_image_for_that_seed_and_frame(tmp_path):
    size = ["--width", "48", "--height", "36", "--backend", "cpu"]
    images = {}
    for seed, frame in ((5, 2), (5, 3), (6, 2)):
        out = tmp_path / f"{seed}-{frame}.npy"
        assert (
            main(
                [
                    "render",
                    SCENE,
                    "--mode",
                    "stochastic",
                    "--seed",
                    str(seed),
                    "--frame",
                    str(frame),
                    *size,
                    "--out",
                    str(out),
                ]
            )
            == 0
        )
        images[seed, frame] = np.load(out)
    scene = gb.load(SCENE)
    lib = gb.render(scene, gb.orbit_camera(scene, width=48, height=36), "stochastic", seed=5, frame=2)
    np.testing.assert_array_equal(images[5, 2], lib.rgb)
    assert not np.array_equal(images[5, 2], images[5, 3]) and not np.array_equal(images[5, 2], images[6, 2])


@pytest.mark.parametrize(
    "argv, message",
    [
        (["render", SCENE, "--mode", "scalar", "--seed", "3"], "--seed 3 applies to the stochastic modes"),
        (
            ["trace", SCENE, "--pixel", "1,1", "--modes", "scalar,stopthepop", "--frame", "1"],
            "--frame 1 applies to the stochastic modes .* given \\(scalar, stopthepop\\) have none",
        ),
        (["render", SCENE, "--mode", "stochastic", "--seed", "-1"], "argument --seed: expected >= 0, got -1"),
        (
            ["flicker", SCENE, "--modes", "stochastic", "--frame", "4294967296"],
            "argument --frame: expected <= 4294967295",
        ),
    ],
)
def test_bad_seed_or_frame_is_one_line_exit_2(argv, message, tmp_path, capsys):
    out = [] if argv[0] == "trace" else ["--out", str(tmp_path / ("x" if argv[0] == "flicker" else "x.png"))]
    assert main([*argv, *out]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and re.search(message, err), err
    assert not list(tmp_path.iterdir())
