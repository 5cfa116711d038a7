"""Numeric command-line options that refuse what no bench means: NaN, infinities, and values
outside the range the option can use, each as one `error: ...` line from the parser."""

import argparse
import math


def ranged(kind, lo, hi):
    """An argparse type: `kind` (int or float) within [lo, hi]."""

    def parse(text):
        try:
            value = kind(text)
        except (TypeError, ValueError):
            raise argparse.ArgumentTypeError("%r is not %s number" % (text, "a whole" if kind is int else "a")) from None
        if isinstance(value, float) and not math.isfinite(value):
            raise argparse.ArgumentTypeError("%r is not a finite number" % text)
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError("%s is outside %g..%g" % (text, lo, hi))
        return value

    parse.__name__ = "%s in %g..%g" % (kind.__name__, lo, hi)
    parse.range = (kind, lo, hi)
    return parse
