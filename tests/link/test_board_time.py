"""Host waits measured in the board's own time (host.link.board_time.BoardTime): acquire.settle() and
acquire.collect() give the actuator the same board seconds whatever the host's wall clock does,
so a virtual board that falls behind on a loaded machine is not cut short. The board here is a
fake link (the hardware side), whose records carry their t_us and are handed out one per poll
or, for a board that has fallen behind, one every few polls."""

import numpy as np
import pytest

from firmware import protocol as P
from host.guided import acquire
from host.guided.acquire import settle
from host.link.board_time import BoardTime

T = P.FIELDS.index("t_us")
D2 = P.FIELDS.index("d2_um")


def rows(t_us, d2=0):
    r = np.zeros((len(t_us), P.RECORD_WORDS), dtype=np.int32)
    r[:, T] = t_us
    r[:, D2] = d2
    return r


class Frame:
    def __init__(self, records):
        self._records = records

    def records(self):
        return self._records


class FakeLink:
    """A board streaming at `hz` of its own time from `t0_us`, one record per `every` polls of
    frames(); d2(t) gives D2 in um at board time t (s). Commands are only recorded."""

    def __init__(self, hz=200, every=1, t0_us=0, d2=lambda t: 0):
        self.period_us = 1000000 // hz
        self.every = every
        self.t_us = t0_us
        self.d2 = d2
        self.polls = 0
        self.sent = []
        self.board_s = 0.0

    def call(self, *args):
        self.sent.append(args)

    def start_stream(self, hz):
        self.period_us = 1000000 // hz
        self.sent.append(("stream", "on", hz))

    def stop_stream(self):
        self.sent.append(("stream", "off"))

    def heartbeat_if_due(self):
        pass

    def frames(self, timeout=0.05):
        self.polls += 1
        if self.polls % self.every:
            return []
        r = rows([self.t_us & 0x3FFFFFFF], self.d2(self.board_s))
        self.t_us += self.period_us
        self.board_s += self.period_us / 1e6
        return [Frame(r)]


def test_board_time_counts_across_the_t_us_wrap_and_ignores_a_restart():
    clock = BoardTime()
    wrap = 1 << 30
    assert clock.add(rows([wrap - 3000, wrap - 1000])) == pytest.approx(0.002)
    assert clock.add(rows([1000, 3000])) == pytest.approx(0.006)  # 2 ms to the wrap, 1 ms after, 2 ms
    assert clock.add(rows([])) == pytest.approx(0.006)
    assert clock.add(rows([500])) == pytest.approx(0.006)  # back to 500 us: the firmware restarted
    assert clock.add(rows([2500])) == pytest.approx(0.008)


@pytest.mark.parametrize("every", [1, 4])
def test_collect_spans_the_same_board_seconds_on_a_board_that_falls_behind(every):
    link = FakeLink(hz=200, every=every, t0_us=(1 << 30) - 100000)  # across the wrap, too
    rec = acquire.collect(link, 0.3)
    assert len(rec) == 61  # t = 0, 5, ... 300 ms of the board's time, however many polls it took
    assert link.polls == 61 * every
    assert link.sent[0] == ("stream", "on", acquire.STREAM_HZ) and link.sent[-1] == ("stream", "off")


def test_collect_gives_up_on_a_board_that_sends_nothing(monkeypatch):
    monkeypatch.setattr(acquire, "NO_DATA_S", 0.2)
    link = FakeLink(every=10 ** 9)
    assert len(acquire.collect(link, 0.1)) == 0 and link.polls >= 2


@pytest.mark.parametrize("every", [1, 3])
def test_settle_times_out_and_holds_in_board_seconds(every):
    def d2(t):  # reaches the 30 mm target 1 s into the board's time
        return 30000 if t >= 1.0 else 10000

    ok, value, seconds = settle(FakeLink(every=every, d2=d2), "position", 30000, "d2_um", 50, timeout_s=0.5, hold_s=0.3)
    assert not ok and value == 10000 and seconds == pytest.approx(0.5)
    ok, value, seconds = settle(FakeLink(every=every, d2=d2), "position", 30000, "d2_um", 50, timeout_s=5, hold_s=0.3)
    # inside once the 10-record window (0.1 s at 100 Hz) is all at the target, then held 0.3 s
    assert ok and value == 30000 and seconds == pytest.approx(1.0 + 0.09 + 0.3)


def test_settle_judges_a_tenth_of_a_second_whatever_rate_the_stream_runs_at():
    """A log's tee keeps the stream at 1 kHz whatever settle asks (host move --log): the window is
    still 0.1 s of the board's time (100 records), not 10 records (10 ms of noise)."""

    class TeedLink(FakeLink):
        def start_stream(self, hz):
            self.sent.append(("stream", "on", hz))  # the tee's rate stays

    def d2(t):
        return 30000 if t >= 1.0 - 1e-9 else 10000  # (the fake's clock sums 1 ms steps in floats)

    link = TeedLink(hz=1000, d2=d2)
    ok, value, seconds = settle(link, "position", 30000, "d2_um", 50, timeout_s=5, hold_s=0.3)
    # the window all at the target from 1.099 s, held 0.3 s (+ one record: the floats' sum of 1 ms steps)
    assert ok and value == 30000 and seconds == pytest.approx(1.0 + 0.099 + 0.3, abs=0.0015)


def test_settle_gives_up_when_the_board_stops_streaming(monkeypatch):
    monkeypatch.setattr(acquire, "NO_DATA_S", 0.2)
    ok, value, seconds = settle(FakeLink(every=10 ** 9), "position", 30000, "d2_um", 50, timeout_s=5)
    assert not ok and value is None and seconds == 0.0
