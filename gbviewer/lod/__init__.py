"""Level of detail (docs/lod.md): a scene's splat hierarchy (`tree`, cached on disk by `cache`) and the cut through
it per camera (`cut`), whose Scene any renderer draws (the CPU renderer draws it in place: `cut_view`), and a large
scene's sparse stand-in for the previews before its hierarchy is there (`sparse`). Scene layer: imports io, scene
and camera only."""

from .cache import hierarchy_for, hierarchy_state
from .cut import DEFAULT_BAND, Cut, check_plain, check_tau, cut, cut_rows, cut_scene, cut_view
from .sparse import stand_in
from .tree import Hierarchy, build

__all__ = [
    "DEFAULT_BAND",
    "Cut",
    "Hierarchy",
    "build",
    "check_plain",
    "check_tau",
    "cut",
    "cut_rows",
    "cut_scene",
    "cut_view",
    "hierarchy_for",
    "hierarchy_state",
    "stand_in",
]
