"""The difference and error views in the real window (Xvfb, Mesa llvmpipe): a pane switched to the difference view
shows the colour-mapped difference to pane A, read back from the window; the PSNR/SSIM labels appear once the
analysis thread has computed them. Screenshots are kept in tests/output/."""

from __future__ import annotations

import time

import numpy as np
import pytest
from window_helpers import LABEL_BAND, agree, expected_pane, pane_pixels, press, shot, wait

import gbviewer as gb
from gbviewer.app.overlays.difference import BAR_H
from gbviewer.outputs import differences, metrics
from gbviewer.outputs.figure import to_uint8, upscale_nearest

pytestmark = pytest.mark.display


def wait_analysed(app, timeout: float = 180.0) -> None:
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < timeout:
        app.step()
        if app.panes.all_current() and app.analysis.current():
            app.run_frames(2)  # the re-colour is uploaded the frame after the result comes in
            return
        time.sleep(0.01)
    pytest.fail("the analysis did not finish")


def test_difference_and_error_views_and_psnr_labels(app):
    from imgui_bundle import imgui

    state = app.state
    state.set_pane_count(2)
    state.set_pane(0, mode="scalar", supersample=1, view="color")
    state.set_pane(1, mode="gaussian_blending", supersample=1, view="color")
    state.set_rate(1 / 4)
    wait(app)
    before = shot(app, "viewer-analysis-colour")
    b = state.panes[1]
    # X over pane B: its difference to pane A
    io = imgui.get_io()
    io.add_mouse_pos_event(b.rect.x + b.rect.w / 2, b.rect.y + b.rect.h / 2)
    app.step()
    press(app, imgui.Key.x)
    assert state.settings.panes[1].view == "difference"
    wait_analysed(app)
    img = shot(app, "viewer-analysis-difference")
    a_rgb, b_rgb = (state.panes[i].parts["a"].frame.rgb for i in range(2))
    d = differences.signed_difference(b_rgb, a_rgb)
    scale = differences.robust_scale(d)
    assert app.analysis.shown_scale[(1, "a")] == scale
    expected = upscale_nearest(to_uint8(differences.colour_difference(d, scale)), b.rect.h, b.rect.w)
    got = pane_pixels(img, b.rect)
    top = round(app.part_tops[(1, "a")] - b.rect.y)  # under the label and message lines: the colour bar
    below = top + BAR_H + 30
    assert agree(got[below:], expected[below:]) > 0.995
    assert agree(got[below:], expected_pane(app, 1)[below:]) < 0.5  # not the plain render
    assert (
        agree(pane_pixels(img, state.panes[0].rect)[LABEL_BAND:], pane_pixels(before, state.panes[0].rect)[LABEL_BAND:])
        > 0.995
    )  # pane A unchanged
    bar = got[top + 4 : top + 14, 8 : 8 + 160]  # the colour bar: dark in the middle, light at both ends
    assert bar[:, :8].mean() > 100 and bar[:, -8:].mean() > 100 and bar[:, 76:84].mean() < 60
    assert "B - A (scalar)" in b.parts["a"].legend

    # P: PSNR / SSIM labels on both panes, against the box reference (x1 scalar box-downsampled by 4)
    no_labels = img
    press(app, imgui.Key.p)
    assert app.analysis.options.fidelity
    wait_analysed(app)
    img = shot(app, "viewer-analysis-psnr")
    for i, rgb in enumerate((a_rgb, b_rgb)):
        job = state.panes[i].parts["a"].job
        x1 = gb.render(state.scene, job.camera.at_sampling_rate(4), "scalar").rgb
        p = metrics.psnr(rgb, metrics.box_downsample(x1, 4))
        text, stale = app.analysis.fidelity_line((i, "a"))
        assert not stale and text.startswith(f"PSNR {p:.2f} dB") and app.analysis.latest[(i, "a")].psnr == p
    ra = state.panes[0].rect
    line = next(i for i in app.placed if i.role == "message" and i.full.startswith("PSNR") and i.x < ra.x + ra.w)
    label = slice(round(line.y - ra.y), round(line.y + line.h - ra.y))  # pane A's PSNR line, where there was none
    assert np.abs(pane_pixels(img, ra)[label].astype(int) - pane_pixels(no_labels, ra)[label]).mean() > 3

    # Shift+X over pane B: the error view against the reference
    press(app, imgui.Key.x, shift=True)
    assert state.settings.panes[1].view == "error"
    wait_analysed(app)
    img = shot(app, "viewer-analysis-error")
    e = app.analysis.latest[(1, "a")].error
    coloured = differences.colour_difference(e, differences.robust_scale(e))
    expected = upscale_nearest(to_uint8(coloured), b.rect.h, b.rect.w)
    below = round(app.part_tops[(1, "a")] - b.rect.y) + BAR_H + 30
    assert agree(pane_pixels(img, b.rect)[below:], expected[below:]) > 0.995

    # moving the camera: the labels go stale, the panes show their renders again until the camera stops
    state.controller.orbit(40, 0)
    state.moved()
    app.step()
    assert app.analysis.fidelity_line((0, "a"))[1]
    wait_analysed(app)
    assert not app.analysis.fidelity_line((0, "a"))[1]
