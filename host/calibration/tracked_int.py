"""How large the numbers inside a firmware function get: `track(func, inputs, k)` runs the
firmware's own integer function (bcm_fixed.bcm3, pwl_fixed.pwl, poly_fixed.poly, under CPython)
on `TrackedInt`s, which record the largest magnitude any operation produces. The export
(host/calibration/fixed_export.py) refuses constants whose intermediates pass 2**30, so there is
no second copy of the firmware's arithmetic to drift apart from it."""


class TrackedInt(int):
    """An int whose arithmetic records the largest magnitude it produces (see `track`)."""

    peak = 0

    def _out(self, value):
        value = int(value)
        if abs(value) > TrackedInt.peak:
            TrackedInt.peak = abs(value)
        return TrackedInt(value)

    def __add__(self, o):
        return self._out(int(self) + int(o))

    def __radd__(self, o):
        return self._out(int(o) + int(self))

    def __sub__(self, o):
        return self._out(int(self) - int(o))

    def __rsub__(self, o):
        return self._out(int(o) - int(self))

    def __mul__(self, o):
        return self._out(int(self) * int(o))

    def __rmul__(self, o):
        return self._out(int(o) * int(self))

    def __floordiv__(self, o):
        return self._out(int(self) // int(o))

    def __rfloordiv__(self, o):
        return self._out(int(o) // int(self))

    def __rshift__(self, o):
        return self._out(int(self) >> int(o))

    def __rrshift__(self, o):
        return self._out(int(o) >> int(self))

    def __lshift__(self, o):
        return self._out(int(self) << int(o))

    def __rlshift__(self, o):
        return self._out(int(o) << int(self))

    def __and__(self, o):
        return self._out(int(self) & int(o))

    def __rand__(self, o):
        return self._out(int(o) & int(self))

    def __neg__(self):
        return self._out(-int(self))


def track(func, inputs, k):
    """Largest |intermediate| of the firmware function `func(x, k)` over all `inputs`."""
    tk = [TrackedInt(v) for v in k]
    TrackedInt.peak = max(abs(int(v)) for v in k)
    for x in inputs:
        TrackedInt.peak = max(TrackedInt.peak, abs(int(x)))
        func(TrackedInt(int(x)), tk)
    return TrackedInt.peak
