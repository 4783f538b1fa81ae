"""Settings persistence, bad settings files, recent files, display detection."""

from __future__ import annotations

import json

from hypothesis import given
from hypothesis import settings as settings_hyp
from hypothesis import strategies as st

from gbviewer.app import has_display_env, settings
from gbviewer.app.settings import AppSettings, PaneSettings


def test_settings_round_trip_and_persistence(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "cfg"))
    assert settings.settings_path() == tmp_path / "cfg" / "gbviewer" / "settings.json"
    s = AppSettings()
    s.pane_count, s.layout, s.rate, s.window = 3, "grid", 0.125, (1200, 800)
    s.panes[2] = PaneSettings("analytic", 4, "alpha", True, "mip", 0.3)
    s.recent = settings.add_recent([], tmp_path / "a.ply")
    s.projection = "orthographic"
    path = settings.save_settings(s)
    assert path.exists()
    back, warning = settings.load_settings()
    assert warning == "" and back == s.normalised()
    assert back.panes[2] == PaneSettings("analytic", 4, "alpha", True, "mip", 0.3)
    assert back.projection == "orthographic"


def test_bad_settings_fall_back_to_defaults_with_a_warning(tmp_path):
    p = tmp_path / "settings.json"
    p.write_text("{not json")
    s, warning = settings.load_settings(p)
    assert s == AppSettings() and "unreadable" in warning
    p.write_text(
        json.dumps(
            {
                "pane_count": 99,
                "rate": -1,
                "layout": "spiral",
                "panes": [{"mode": "nope", "supersample": 40, "view": "x", "extra": 1}],
                "up": "sideways",
                "window": "big",
                "unknown_key": 1,
                "projection": "fisheye",
            }
        )
    )
    s, warning = settings.load_settings(p)
    assert warning == ""
    assert s.pane_count == 4 and s.rate == 1.0 and s.layout == "row" and s.up == "-y"
    assert s.projection == "perspective"
    assert s.panes[0] == PaneSettings("scalar", 8, "color") and len(s.panes) == 4


def test_recent_files_most_recent_first_without_duplicates(tmp_path):
    r: list[str] = []
    for name in ["a", "b", "a", "c"]:
        r = settings.add_recent(r, tmp_path / name)
    assert [p.rsplit("/", 1)[-1] for p in r] == ["c", "a", "b"]
    for k in range(20):
        r = settings.add_recent(r, tmp_path / f"f{k}")
    assert len(r) == settings.MAX_RECENT


def test_display_detection():
    assert has_display_env({})[0] is False and "DISPLAY" in has_display_env({})[1]
    assert has_display_env({"DISPLAY": ":1"}) == (True, "")
    assert has_display_env({"WAYLAND_DISPLAY": "wayland-0"})[0]


def test_hostile_settings_values_fall_back_without_stopping_the_viewer(tmp_path):
    p = tmp_path / "settings.json"
    big = "9" * 4000  # an integer too large for a float
    p.write_text(
        f'{{"rate": {big}, "fov_y_deg": {big}, "background": [{big}, 0, 0], "pane_count": {big}, '
        f'"window": [{big}, "x"], "panes": [{{"split_pos": {big}, "supersample": "x", "view": []}}], '
        f'"loupe_zoom": "nan", "fly_speed": "1e400", "up": [], "layout": {{}}, "recent": 5}}'
    )
    s, warning = settings.load_settings(p)
    assert warning == ""
    assert (s.rate, s.fov_y_deg, s.background, s.pane_count) == (1.0, 50.0, (0.0, 0.0, 0.0), 4)
    assert s.window == (8192, 860) and s.panes[0] == PaneSettings() and s.recent == []
    for text in ("[1, 2]", "[" * 5000, '{"rate": NaN}' * 2, "\xff", '{"rate": 1e400}'):  # 1e400: beyond double
        p.write_bytes(text.encode("latin-1"))
        s, warning = settings.load_settings(p)
        assert s == AppSettings() and "unreadable settings" in warning and str(p) in warning
        assert "\n" not in warning


@settings_hyp(max_examples=150, deadline=None)
@given(
    st.dictionaries(
        st.sampled_from(sorted(AppSettings.__dataclass_fields__)),
        st.recursive(
            st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=4),
            lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=3), kids, max_size=3),
            max_leaves=12,
        ),
    )
)
def test_any_settings_object_normalises_to_valid_settings(doc):
    s = AppSettings.from_doc(doc)
    assert 1 <= s.pane_count <= settings.MAX_PANES and len(s.panes) == settings.MAX_PANES
    assert 0.125 <= s.rate <= 8 and all(0 <= v <= 1 for v in s.background)
    assert all(1 <= p.supersample <= 8 and 0 <= p.split_pos <= 1 for p in s.panes)
    assert s == s.normalised()
