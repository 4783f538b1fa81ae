"""Level of detail (issue 24): a scene's splat hierarchy (`tree`, cached on disk by `cache`) and the cut through
it per camera (`cut`), whose Scene any renderer draws. Scene layer: imports io, scene and camera only."""

from .cache import hierarchy_for
from .cut import DEFAULT_BAND, Cut, check_tau, cut, cut_scene
from .tree import Hierarchy, build

__all__ = ["DEFAULT_BAND", "Cut", "Hierarchy", "build", "check_tau", "cut", "cut_scene", "hierarchy_for"]
