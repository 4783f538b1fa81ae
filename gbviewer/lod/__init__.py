"""Level of detail (docs/lod.md): a scene's splat hierarchy (`tree`, cached on disk by `cache`) and the cut through
it per camera (`cut`), whose Scene any renderer draws (the CPU renderer draws it in place: `cut_view`). Scene
layer: imports io, scene and camera only."""

from .cache import hierarchy_for
from .cut import DEFAULT_BAND, Cut, check_plain, check_tau, cut, cut_scene, cut_view
from .tree import Hierarchy, build

__all__ = ["DEFAULT_BAND", "Cut", "Hierarchy", "build", "check_plain", "check_tau", "cut", "cut_scene", "cut_view",
           "hierarchy_for"]
