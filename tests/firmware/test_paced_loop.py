"""hal.PacedLoop, the loop timer where there is no timer interrupt (CircuitPython), on a clock the
test turns by hand: a step each period counted from when the last was due, none early, a late
one not shifting the rest, a loop left far behind starting again from now, and the clock's wrap."""

from firmware.hal import PacedLoop


def paced(period, mask, start):
    clock = {"now": start}
    steps = []
    loop = PacedLoop(250, lambda timer: steps.append(clock["now"]))
    loop._ticks, loop.period, loop._mask = (lambda: clock["now"]), period, mask
    loop._next = (start + period) & mask
    return loop, clock, steps


def test_a_step_each_period_none_early_and_a_late_one_shifts_nothing():
    loop, clock, steps = paced(4, (1 << 29) - 1, 100)
    for now in (101, 102, 103):
        clock["now"] = now
        assert not loop.run_due()
    for now in (104, 105, 106, 107, 109, 110, 111, 112):  # the step due at 108 runs late, at 109
        clock["now"] = now
        loop.run_due()
    assert steps == [104, 109, 112]  # and the next is still due at 112, not at 113


def test_a_loop_left_far_behind_starts_again_from_now():
    loop, clock, steps = paced(4, (1 << 29) - 1, 100)
    clock["now"] = 130  # a 26 ms pause: not seven steps in a row to catch up
    assert loop.run_due() and not loop.run_due()
    clock["now"] = 133
    assert not loop.run_due()
    clock["now"] = 134
    assert loop.run_due() and steps == [130, 134]


def test_the_clock_wraps_without_a_step_lost_or_doubled():
    mask = (1 << 29) - 1
    loop, clock, steps = paced(4, mask, mask - 5)
    for k in range(1, 20):
        clock["now"] = (mask - 5 + k) & mask
        loop.run_due()
    assert len(steps) == 4  # at 4, 8, 12 and 16 ticks after the start, across the wrap
    assert [(s - (mask - 5)) & mask for s in steps] == [4, 8, 12, 16]


def test_deinit_stops_it():
    loop, clock, steps = paced(4, (1 << 29) - 1, 0)
    loop.deinit()
    clock["now"] = 50
    assert not loop.run_due() and steps == []
