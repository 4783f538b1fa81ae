"""The `gbviewer` command line: info, render, demo (the main job), bench, eval, video, flicker, compare."""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from contextlib import contextmanager

from ..core.errors import GBViewerError
from ..render.budget import BUDGET_ENV
from . import bench, compare, flicker, info, render, trace, video, view
from . import eval as evaluation
from .argtypes import Parser

COMMANDS = (info, render, view, bench, evaluation, video, flicker, trace, compare)  # in the order --help lists them


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="gbviewer", description=__doc__)
    parser.add_argument("--debug", action="store_true", help="show tracebacks")
    sub = parser.add_subparsers(dest="command")
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def _join_signed_values(argv: list[str]) -> list[str]:
    """'--up -y' -> '--up=-y': argparse would take '-y' for an option."""
    out: list[str] = []
    for arg in argv:
        if out and out[-1] == "--up" and arg in ("-y", "-z", "+y", "+z"):
            out[-1] = f"--up={arg}"
        else:
            out.append(arg)
    return out


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised like Ctrl-C's KeyboardInterrupt so that every `finally` (temporary files, ffmpeg)
    runs before the process exits with 128 + the signal's number."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@contextmanager
def _signals_interrupt():
    """While the command runs (in the main thread), SIGTERM and SIGHUP raise `Terminated`."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: object) -> None:
        raise Terminated(signum)

    previous = {sig: signal.signal(sig, interrupt) for sig in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _quiet_stdout() -> None:
    """stdout's reader went away (`gbviewer info ... | head -1`): send what is left to /dev/null so that Python's
    final flush does not complain (the recipe of the `signal` module's documentation)."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())


def one_line(text: str) -> str:
    """`text` as one line: control characters (a newline in a file name, a terminal escape) written as escapes."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the exit status: 0, 2 for bad input (one line on stderr), 128 + N for signal N
    (SIGINT, SIGTERM, SIGHUP; SIGPIPE when stdout is closed early)."""
    parser = build_parser()
    argv = _join_signed_values(sys.argv[1:] if argv is None else argv)
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    first = next((a for a in argv if a != "--debug"), None)
    if first is None or (first not in commands and first not in ("-h", "--help")):
        argv = ["view", *argv] if first is None else [*argv[: argv.index(first)], "view", *argv[argv.index(first) :]]
    try:
        args, extra = parser.parse_known_args(argv)
        if extra:  # named by the command's own parser, whose --help lists what it takes
            commands[args.command].error(f"unrecognized arguments: {' '.join(extra)}")
    except SystemExit as exc:  # --help, or a usage error already printed in one line
        return int(exc.code or 0)
    try:
        with _signals_interrupt():
            status = args.func(args)
            sys.stdout.flush()
        return status
    except BrokenPipeError:
        _quiet_stdout()
        return 128 + signal.SIGPIPE
    except (GBViewerError, OSError) as exc:
        if args.debug:
            raise
        print(f"gbviewer: error: {one_line(str(exc))}", file=sys.stderr)
        return 2
    except MemoryError as exc:  # beyond the estimate render.budget refuses before a frame (e.g. long tile lists)
        if args.debug:
            raise
        print(
            f"gbviewer: error: out of memory ({one_line(str(exc)) or 'MemoryError'}); render smaller, or see "
            f"{BUDGET_ENV}",
            file=sys.stderr,
        )
        return 2
    except KeyboardInterrupt as exc:
        signum = exc.signum if isinstance(exc, Terminated) else signal.SIGINT
        print(f"gbviewer: interrupted ({signal.Signals(signum).name})", file=sys.stderr)
        return 128 + signum
