"""The pixel inspector: its state and thread, and its imgui view and table."""
