"""What every subcommand's parser shares."""

from __future__ import annotations

import argparse


def add_json(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print machine-readable JSON only")


def whole(minimum: int, maximum: int | None = None):
    """An argparse type: a whole number of at least ``minimum`` (and at most ``maximum``;
    argparse's one-line error otherwise, before anything runs)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{value} is below {minimum}")
        if maximum is not None and value > maximum:
            raise argparse.ArgumentTypeError(f"{value} is above {maximum}")
        return value

    parse.__name__ = (f"whole number >= {minimum}" if maximum is None
                      else f"whole number in [{minimum}, {maximum}]")
    return parse


def width_height(text: str) -> tuple[int, int]:
    """An argparse type: ``WxH`` (width first, as every size on the command line is given)
    -> (W, H), both whole numbers of at least 1."""
    w, sep, h = text.lower().partition("x")
    if not (sep and all(v.isascii() and v.isdecimal() for v in (w, h))
            and int(w) > 0 and int(h) > 0):
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, e.g. 320x240, got {text!r}")
    return int(w), int(h)


width_height.__name__ = "WIDTHxHEIGHT"
