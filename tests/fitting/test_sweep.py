"""Sweep loading and hygiene: real files load, bad files give one-line UserErrors."""

import numpy as np
import pytest

from host.errors import UserError
from host.fitting.sweep import MIN_POINTS, load_sweep, sweep_from_arrays


def _write(tmp_path, text, name="s.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def _good_rows(n=40, lo=100, hi=4000):
    raw = np.linspace(lo, hi, n).round()
    return raw, raw * 60.0 / 4095.0


def test_real_files_load_and_map_is_a_function(realdata_dir):
    for f in sorted(realdata_dir.glob("*.csv")):
        s = load_sweep(f)
        assert s.x.size == s.y.size == s.n_input - s.n_excluded
        assert np.all(np.diff(s.x) >= 0)
        assert np.isfinite(s.x).all() and np.isfinite(s.y).all()
        # no rail value is shared by two rows any more
        assert np.count_nonzero(s.x == s.x[0]) == 1
        assert np.count_nonzero(s.x == s.x[-1]) == 1


def test_rupayan_rail_ties_are_excluded(realdata_dir):
    s = load_sweep(realdata_dir / "esp32_adc_rupayan555.csv")
    assert s.n_input == 88
    assert s.exclusions == {"clipped_low": 11, "clipped_high": 4}
    assert s.x[0] > 0 and s.x[-1] < 4095


def test_rp2040_unsorted_noise_is_sorted(realdata_dir):
    s = load_sweep(realdata_dir / "rp2040_adc_kitanokitsune.csv")
    assert s.n_input == 32768 and s.n_excluded == 0
    assert np.all(np.diff(s.x) >= 0)


def test_hygiene_counts_each_reason():
    raw, ref = _good_rows(40)
    raw = np.concatenate([[0, 0, 0], raw, [4095, 4095], [np.nan, 500]])
    ref = np.concatenate([[0.0, 0.1, 0.2], ref, [59.9, 60.0], [1.0, np.inf]])
    s = sweep_from_arrays(raw, ref)
    assert s.exclusions == {"non_finite": 2, "clipped_low": 3, "clipped_high": 2}
    assert s.n_excluded == 7 and s.x.size == 40
    assert "3 clipped low" in s.describe()


def test_single_rail_reading_is_kept():
    raw, ref = _good_rows(40, lo=0, hi=4095)
    s = sweep_from_arrays(raw, ref)
    assert s.n_excluded == 0 and s.x[0] == 0 and s.x[-1] == 4095


def test_repeated_readings_at_the_ends_of_a_slow_sweep_are_kept():
    # a slow sweep that never reaches a rail: several readings per code, also at its first and
    # last code (this used to lose its 4 + 4 end rows as "clipped")
    rng = np.random.default_rng(3)
    raw = np.repeat(np.arange(100, 3901, 25), 4).astype(float)
    ref = raw * 60 / 4095 + rng.normal(0, 0.005, raw.size)
    s = sweep_from_arrays(raw, ref)
    assert s.exclusions == {} and s.x.size == raw.size


def test_clipping_away_from_a_rail_is_seen_by_the_reference_moving():
    # volts (no rail known): the divider saturates at 3.1 V while the reference goes on to 60 mm
    v = np.linspace(0.2, 3.1, 60)
    ref = v * 50 / 3.1
    raw = np.concatenate([v, np.full(5, 3.1)])
    ref = np.concatenate([ref, np.linspace(51, 60, 5)])
    s = sweep_from_arrays(raw, ref)
    assert s.exclusions == {"clipped_high": 6} and s.x[-1] < 3.1
    # the same ends without the runaway reference are repeated readings: kept
    steady = np.concatenate([ref[:60], ref[59] + np.array([0.002, -0.001, 0.0, 0.001, -0.002])])
    assert sweep_from_arrays(raw, steady).exclusions == {}


def test_full_scale_gives_rails_and_coverage_to_any_unit():
    v = np.linspace(0.2, 0.5, 40)
    assert sweep_from_arrays(v, v * 20).x.size == 40  # volts: no full scale known, no coverage check
    with pytest.raises(UserError, match="covers only 0.3 of its full scale 3.3"):
        sweep_from_arrays(v, v * 20, full_scale=3.3)
    # with a full scale, ties at 0 V are on the rail even when the reference barely moved
    raw = np.concatenate([[0.0, 0.0], np.linspace(0.1, 3.2, 40)])
    ref = np.concatenate([[0.0, 0.001], np.linspace(0.1, 3.2, 40) * 18])
    assert sweep_from_arrays(raw, ref).exclusions == {}
    assert sweep_from_arrays(raw, ref, full_scale=3.3).exclusions == {"clipped_low": 2}
    with pytest.raises(UserError, match="full scale must be a positive"):
        sweep_from_arrays(raw, ref, full_scale=-1.0)


def test_direction_column_follows_the_sort(tmp_path):
    raw, ref = _good_rows(30)
    lines = ["raw,reference,direction,temp"]
    for r, y in zip(raw[::-1], ref[::-1]):
        lines.append("%d,%.4f,-1,21.5" % (r, y))
    s = load_sweep(_write(tmp_path, "\n".join(lines) + "\n"))
    assert np.all(np.diff(s.x) > 0) and np.all(s.direction == -1)
    assert np.allclose(s.y, s.x * 60 / 4095, atol=1e-4)


def test_twenty_five_points_is_enough():
    raw, ref = _good_rows(25)
    assert sweep_from_arrays(raw, ref).x.size == 25


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("", "empty"),
        ("raw,reference\n", "no data rows"),
        ("raw,position\n1,2\n", "no 'reference' column"),
        ("raw,reference\n1,2\nabc,3\n", "s.csv: raw value 'abc' is not a number"),  # names the file
        ("raw,reference\n" + "".join("%d,%d\n" % (i * 100, i) for i in range(MIN_POINTS - 1)), "usable points"),
        ("raw,reference\n" + "".join("%d,%d\n" % (1000 + i, i) for i in range(40)), "covers only"),
        ("raw,reference,direction\n" + "".join("%d,%d,2\n" % (i * 100, i) for i in range(40)), "direction"),
    ],
)
def test_bad_input_is_a_one_line_user_error(tmp_path, text, fragment):
    with pytest.raises(UserError) as exc:
        load_sweep(_write(tmp_path, text))
    assert fragment in str(exc.value) and "\n" not in str(exc.value)


def test_missing_file_and_gap(tmp_path):
    with pytest.raises(UserError, match="no sweep file at"):
        load_sweep(tmp_path / "nope.csv")
    raw = np.concatenate([np.linspace(0, 1000, 20), np.linspace(3000, 4000, 20)])
    with pytest.raises(UserError, match="no readings between"):
        sweep_from_arrays(raw, raw / 100)
