"""The viewer's background sources: a colour the user picks (the panel, `gbviewer view --background`, saved in the
settings: FIXED) or, with a dataset open, its photos' backdrop (PHOTOS; gbviewer.io.datasets.backdrop, whose
`choose_background` is the rule the viewer starts from, as eval, compare and bench do)."""

from __future__ import annotations

from ..io.datasets.backdrop import PHOTOS

FIXED = "fixed"

__all__ = ["FIXED", "PHOTOS"]
