"""The window's building blocks: the key map, input, dialogs, layout, text placement and image blits."""
