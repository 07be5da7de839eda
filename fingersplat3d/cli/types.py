"""Argument types of ``fs3d``: each parses one value or raises ``argparse.ArgumentTypeError`` with one sentence."""
from __future__ import annotations

import argparse

__all__ = ["size", "angles", "number", "COUNT", "STEPS", "POSITIVE", "angle_list", "view_pairs"]


def size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(part) for part in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 640x512, got {text!r}") from None
    return width, height


def angles(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"angles must be comma-separated degrees like -30,0,30, got {text!r}") from None


def number(kind, low: float, high: float = float("inf"), low_inclusive: bool = True):
    """An argparse type: a ``kind`` (int or float) within ``[low, high]`` (``(low, high]`` when not ``low_inclusive``)."""
    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {'a whole number' if kind is int else 'a number'}, got {text!r}") from None
        if not (value == value and (value >= low if low_inclusive else value > low) and value <= high):
            bound = f"{'at least' if low_inclusive else 'more than'} {low:g}" + ("" if high == float("inf") else f" and at most {high:g}")
            raise argparse.ArgumentTypeError(f"must be {bound}, got {text}")
        return value
    return parse


COUNT = number(int, 1)
STEPS = number(int, 0, 1_000_000)
POSITIVE = number(float, 0.0, 1e6, low_inclusive=False)
SEED = number(int, 0)
"""Random seeds: numpy's generators take non-negative integers."""
PX_PER_MM = number(float, 0.5, 500.0)
"""Photo pixels per millimetre at the finger: a distant phone photo's few to a microscope's hundreds."""
FINGER_MM = number(float, 3.0, 60.0)
"""A finger's width in millimetres: a child's little finger to a large thumb, with room either side."""


def angle_list(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give angles in degrees separated by commas, e.g. -30,0,30") from None
    if not values or not all(abs(v) < 180 for v in values):
        raise argparse.ArgumentTypeError(f"{text!r}: give angles between -180 and 180 degrees")
    return values


def view_pairs(text: str) -> list[tuple[str, str]]:
    pairs = []
    for item in text.split(","):
        a, colon, b = item.strip().partition(":")
        if not colon or not a or not b or a == b:
            raise argparse.ArgumentTypeError(f"{item!r}: give pairs of two different views as A:B, e.g. center:left")
        pairs.append((a, b))
    return pairs
