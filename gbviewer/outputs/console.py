"""The terminal the command line's tables print to."""

from __future__ import annotations


def wide_console():
    """A rich console; into a file or pipe 200 columns wide, so that no number is cut short."""
    from rich.console import Console

    term = Console()
    return term if term.is_terminal else Console(width=max(term.width, 200))
