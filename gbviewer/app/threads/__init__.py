"""The viewer's background threads: the per-slot thread, the render thread and scene loading."""
