"""portable.us_from_ms, CircuitPython's microsecond clock made from supervisor.ticks_ms (its one
clock that allocates nothing): whole milliseconds as microseconds, across the millisecond
clock's wrap at 2**29, wrapping at 2**30 itself as MicroPython's ticks_us does, and allocating
nothing under heap_lock on the real MicroPython unix port."""

from firmware.portable import us_from_ms
from testkit.interpreters import run_micropython

MS_WRAP = 1 << 29


def readings(ms_values):
    it = iter(ms_values)
    clock = us_from_ms(lambda: next(it))
    return [clock() for _ in range(len(ms_values) - 1)]


def test_milliseconds_become_microseconds_across_both_wraps():
    # starts at 5 ms; 3 ms later; across the ms clock's wrap (2 + 3 ms later); then a long gap
    got = readings([5, 8, MS_WRAP - 2, 3, 3 + 1200000])
    expected = [3000, (MS_WRAP - 7) * 1000 % (1 << 30), 0, 0]
    expected[2] = (expected[1] + 5000) % (1 << 30)
    expected[3] = (expected[2] + 1200000 * 1000) % (1 << 30)  # 20 minutes: one long int, still right
    assert got == expected
    assert all(0 <= v < (1 << 30) for v in got)


def test_the_clock_allocates_nothing_on_micropython():
    src = (
        "import micropython\n"
        "from firmware.portable import us_from_ms\n"
        "t = [100]\n"
        "def ms():\n"
        "    return t[0]\n"
        "clock = us_from_ms(ms)\n"
        "out = []\n"
        "for step in (4, 4, 5):\n"
        "    t[0] += step\n"
        "    micropython.heap_lock()\n"
        "    v = clock()\n"
        "    micropython.heap_unlock()\n"
        "    out.append(v)\n"
        "print(out)\n"
    )
    proc = run_micropython(src)
    assert proc.stdout.strip() == "[4000, 8000, 13000]"
