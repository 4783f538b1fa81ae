"""Command-line option types: argparse `type=` factories backed by `gbviewer.core.validate`, and the parser whose
errors are one line.

Every numeric option of `gbviewer.cli` uses `Number`, `Numbers`, `Rate` or `Rates`, so it is finite, in range,
integral where it must be and representable in what it is cast to; tests enumerate the options by these types.
A failed check is an `argparse.ArgumentTypeError`, which argparse reports as `argument --NAME: <why>`.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import NoReturn

from ..core.errors import GBViewerError, InvalidValue
from ..core.validate import integer, real
from ..model.camera import MAX_IMAGE_SIZE as MAX_SIDE  # largest image width or height
from ..model.camera import parse_rate, parse_rates


class Parser(argparse.ArgumentParser):
    """An ArgumentParser (and, through add_subparsers, every subparser) whose errors are one line with a hint to
    --help instead of the usage block."""

    def error(self, message: str) -> NoReturn:
        one_line = " ".join(message.split())
        self.exit(2, f"{self.prog}: error: {one_line} (see {self.prog} --help)\n")


def _type_error(exc: GBViewerError, what: str) -> argparse.ArgumentTypeError:
    """The validate message without the placeholder name `what` (argparse names the option itself)."""
    return argparse.ArgumentTypeError(str(exc).removeprefix(f"{what}: "))


@dataclass(frozen=True)
class Number:
    """One number: an integer (`integral`) or a finite real in [lo, hi] ((lo, hi] with lo_open), fitting a float32
    with `f32`. `name` labels it inside a `Numbers` tuple."""

    integral: bool = False
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    f32: bool = False
    name: str = "value"

    def check(self, text: str) -> float:
        """The checked value; `InvalidValue` naming `name` otherwise."""
        if self.integral:
            return integer(text, self.name, lo=self.lo, hi=self.hi)  # type: ignore[arg-type]
        return real(text, self.name, lo=self.lo, hi=self.hi, lo_open=self.lo_open, f32=self.f32)

    def __call__(self, text: str) -> float:
        try:
            return self.check(text)
        except InvalidValue as exc:
            raise _type_error(exc, self.name) from None


@dataclass(frozen=True)
class Numbers:
    """A fixed number of `Number`s separated by `sep` (AZ,EL,DIST; R,G,B; WxH), each checked and named."""

    parts: tuple[Number, ...]
    sep: str = ","

    @property
    def metavar(self) -> str:
        return self.sep.join(p.name for p in self.parts)

    def __call__(self, text: str) -> tuple:
        items = text.lower().split(self.sep)
        if len(items) != len(self.parts):
            shown = text if len(text) <= 40 else text[:37] + "..."
            raise argparse.ArgumentTypeError(f"expected {self.metavar}, got {shown!r}")
        try:
            return tuple(p.check(t) for p, t in zip(self.parts, items))
        except InvalidValue as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None


@dataclass(frozen=True)
class Rate:
    """A sampling rate: 8, 1, 0.125 or 1/8 (`gbviewer.model.camera.parse_rate`); with `many`, comma-separated rates."""

    many: bool = False

    def __call__(self, text: str) -> float | list[float]:
        try:
            return parse_rates(text) if self.many else parse_rate(text)
        except InvalidValue as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix("rates: ")) from None


def count(hi: int | None = None, lo: int = 1) -> Number:
    """An integer >= lo (default: a count of at least one) and <= hi."""
    return Number(integral=True, lo=lo, hi=hi)


def positive(hi: float | None = None) -> Number:
    """A finite real > 0 and <= hi."""
    return Number(lo=0.0, lo_open=True, hi=hi)


SIDE = count(MAX_SIDE)
SIZE = Numbers((Number(True, 1, MAX_SIDE, name="W"), Number(True, 1, MAX_SIDE, name="H")), sep="x")
ORBIT = Numbers((Number(f32=True, name="AZ"), Number(f32=True, name="EL"), Number(lo=0.0, f32=True, name="DIST")))
BACKGROUND = Numbers(tuple(Number(lo=0.0, hi=1.0, name=c) for c in "RGB"))
PIXEL = Numbers((Number(True, 0, MAX_SIDE - 1, name="X"), Number(True, 0, MAX_SIDE - 1, name="Y")))
INSET = Numbers(
    (
        Number(f32=True, name="X"),
        Number(f32=True, name="Y"),
        Number(lo=0.0, lo_open=True, f32=True, name="W"),
        Number(lo=0.0, lo_open=True, f32=True, name="H"),
    )
)
