"""A pane's frames: what it shows, sampling rates, progressive and accumulated frames, display paths."""
