"""The CUDA backend's bookkeeping of its CUDA-GL texture registrations (gbviewer.render.cuda).

The native renderer keeps one CUDA registration per GL texture name between frames (registering costs more than
the copy). GL reuses the names of deleted textures, and names are unique per share group only, so a name can come
back as another texture: of another size (the native side then registers again) or of the same size (the old
registration would write into the deleted texture's storage). This keeps, per name, the texture object the
registration was made for and drops the registration when the name arrives with another object."""

from __future__ import annotations

from collections.abc import Callable


class TextureRegistrations:
    """GL name -> the texture object (moderngl) the native registration of that name belongs to. `release(glo)`
    drops the native registration of a name (its GL context current)."""

    def __init__(self, release: Callable[[int], None]) -> None:
        self._release = release
        self._objects: dict[int, object] = {}  # kept alive: identity, not id(), tells two textures apart

    def claim(self, texture) -> int:
        """Before a render into `texture`: its GL name, with any registration made for another texture of that name
        dropped first."""
        glo = int(texture.glo)
        known = self._objects.get(glo)
        if known is not None and known is not texture:
            del self._objects[glo]
            self._release(glo)
        self._objects[glo] = texture
        return glo

    def forget(self, glo: int) -> None:
        """The texture `glo` is about to be deleted: drop its registration."""
        self._objects.pop(int(glo), None)
        self._release(int(glo))

    def __len__(self) -> int:
        return len(self._objects)
