"""`host compare`: every model at every order, scored, plotted and tabulated."""

import csv
import math
import subprocess
import sys

import numpy as np
import pytest

from host.fitting.compare import compare_models, parse_models, parse_orders, write_outputs
from host.fitting.noise_floor import estimate_noise

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _knee_sweep(path, n=600, seed=2):
    """A pot with two soft knees, measured against a reference (noise 0.02 mm): a CSV sweep."""
    rng = np.random.default_rng(seed)
    pos = np.sort(rng.uniform(0.0, 60.0, n))
    code = 4095.0 * pos / 60.0 - 250.0 * np.exp(-pos / 3.0) + 250.0 * np.exp((pos - 60.0) / 3.0)
    code = np.clip(np.round(code + rng.normal(0, 1.0, n)), 0, 4095)
    ref = pos + rng.normal(0, 0.02, n)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["raw", "reference"])
        w.writerows(zip(code.astype(int), np.round(ref, 4)))
    return path


def test_parse_orders_and_models():
    assert parse_orders("2-5") == [2, 3, 4, 5]
    assert parse_orders("2-4,10, 3") == [2, 3, 4, 10]
    for bad in ("5-2", "x", "0-3", ""):
        with pytest.raises(ValueError):
            parse_orders(bad)
    assert parse_models("bcm, pwl,bcm") == ["bcm", "pwl"]
    assert "pchip" in parse_models("all")
    with pytest.raises(ValueError, match="unknown model"):
        parse_models("pcm,nurbs")


def test_compare_scores_every_model_and_order(tmp_path):
    from host.fitting.sweep import load_sweep

    sweep = load_sweep(_knee_sweep(tmp_path / "knee.csv"))
    noise = estimate_noise(sweep.x, sweep.y)
    models = ["pcm", "cheb", "spline", "lut", "pwl", "pchip"]
    seen = []
    rows = compare_models(sweep.x, sweep.y, [2, 3, 4, 6], models, noise=noise, progress=lambda *a: seen.append(a[0]))
    assert seen == models
    assert [(r["model"], r["order"]) for r in rows] == [(m, o) for m in models for o in (2, 3, 4, 6)]
    m = len(sweep.x)
    for r in rows:
        assert not r["error"]
        assert r["norm2"] == pytest.approx(r["rms"] * math.sqrt(m))
        assert r["rms_over_noise"] == pytest.approx(r["rms"] / noise)
        assert r["rms_over_noise"] > 0.8  # nothing fits below the noise floor
    by = {(r["model"], r["order"]): r for r in rows}
    assert by["pcm", 4]["norm2"] == pytest.approx(by["cheb", 4]["norm2"], rel=1e-6)
    assert by["pwl", 6]["n_params"] == 10 and by["lut", 6]["n_params"] == 6 and by["spline", 6]["n_params"] == 8
    for name in models:  # more freedom never fits worse for nested models
        if name in ("pcm", "cheb"):
            assert by[name, 6]["norm2"] <= by[name, 2]["norm2"]


def test_a_failing_cell_is_reported_not_fatal():
    x = np.linspace(0, 10, 6)
    rows = compare_models(x, x**2, [2, 8], ["pcm"], noise=None)
    assert not rows[0]["error"] and math.isnan(rows[0]["rms_over_noise"])
    assert "at least" in rows[1]["error"] and math.isnan(rows[1]["norm2"])


def test_outputs_png_markdown_and_csv_with_a_row_per_model_and_order(tmp_path):
    x = np.linspace(0, 4095, 500)
    y = 60 * x / 4095 + np.sin(x / 500)
    rows = compare_models(x, y, [2, 3, 5], ["pcm", "lut", "pwl"], noise=0.01)
    csv_path, md_path, png_path = write_outputs(rows, tmp_path / "out", "demo", "demo", len(x), 0.01)
    assert png_path.read_bytes()[:8] == PNG_MAGIC and png_path.stat().st_size > 10_000
    with open(csv_path) as fh:
        table = list(csv.DictReader(fh))
    assert [(r["model"], int(r["order"])) for r in table] == [(m, o) for m in ("pcm", "lut", "pwl") for o in (2, 3, 5)]
    assert float(table[0]["norm2"]) == pytest.approx(rows[0]["norm2"], rel=1e-6)
    md = md_path.read_text()
    assert "| order | pcm | lut | pwl |" in md
    assert md.count("\n| pcm | ") + md.count("\n| lut | ") + md.count("\n| pwl | ") == 9


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "host", "compare", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=300)


def test_cli_writes_plot_and_table_and_prints_progress(tmp_path):
    sweep = _knee_sweep(tmp_path / "knee.csv")
    out = tmp_path / "cmp"
    proc = _cli(sweep, "--orders", "2-4", "--models", "bcm,pcm,lut,pwl", "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert (out / "knee.png").read_bytes()[:8] == PNG_MAGIC
    assert (out / "knee.md").is_file()
    with open(out / "knee.csv") as fh:
        assert len(list(csv.DictReader(fh))) == 4 * 3
    assert "[4/4] pwl" in proc.stderr and "noise floor" in proc.stderr
    assert "| order | bcm | pcm | lut | pwl |" in proc.stdout


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_cli_progress_says_about_how_long_is_left(tmp_path, jobs):
    """After each model but the last, the progress line on stderr estimates the time left; in
    one process (orders shown as they start) and with worker processes (a line per model)."""
    import re

    proc = _cli(_knee_sweep(tmp_path / "knee.csv"), "--orders", "2-3", "--models", "pcm,lut,pwl", "--out",
                tmp_path / "cmp", "--jobs", jobs)
    assert proc.returncode == 0, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.startswith("[")]
    assert [line[:5] for line in lines] == ["[1/3]", "[2/3]", "[3/3]"], proc.stderr
    for line in lines[:-1]:
        assert re.search(r"2 fits in [0-9.]+ s, about [0-9.]+ (s|min) left$", line), line
    assert "left" not in lines[-1], lines[-1]


def test_quiet_leaves_stderr_empty_and_the_tables_on_stdout(tmp_path):
    """--quiet silences the progress (host.terminal, as every command); the results stay."""
    proc = _cli(_knee_sweep(tmp_path / "knee.csv"), "--orders", "2-3", "--models", "pcm,pwl", "--out",
                tmp_path / "cmp", "-q")
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    assert "| order | pcm | pwl |" in proc.stdout


def test_time_left_is_the_wall_time_per_model_so_far_times_the_models_to_go():
    from host.commands.compare import time_left

    assert time_left(6.0, 2, 5) == ", about 9.0 s left"
    assert time_left(12.0, 1, 3) == ", about 24 s left"
    assert time_left(60.0, 1, 7) == ", about 6 min left"
    assert time_left(6.0, 5, 5) == ""  # nothing left to estimate


@pytest.mark.parametrize(
    "args, message",
    [
        (["--orders", "9-3"], "bad order range"),
        (["--models", "pcm,nope"], "unknown model"),
    ],
)
def test_cli_bad_input_is_one_line(tmp_path, args, message):
    proc = _cli(_knee_sweep(tmp_path / "k.csv"), *args, "--out", tmp_path / "o")
    assert proc.returncode == 2
    assert message in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_cli_missing_file_is_one_line(tmp_path):
    proc = _cli(tmp_path / "nope.csv", "--out", tmp_path / "o")
    assert proc.returncode == 2 and "no sweep file at" in proc.stderr


def test_pwl_objective_never_rises_with_the_order_in_a_comparison(realdata_dir):
    from host.fitting.sweep import load_sweep

    # this short real curve put independent free-knot searches in worse optima at 12 knots than at 11
    sweep = load_sweep(realdata_dir / "esp32_adc_yasirfaur.csv")
    rows = compare_models(sweep.x, sweep.y, list(range(2, 16)), ["pwl"])
    norms = [r["norm2"] for r in rows]
    assert all(b <= a * (1 + 1e-9) for a, b in zip(norms, norms[1:])), norms
    assert norms[-1] < 0.5 * norms[3]


def test_bcm_is_warm_started_from_the_previous_degree():
    from host.fitting.example_sweep import DEFAULT_PATH
    from host.fitting.models import fit_model
    from host.fitting.sweep import load_sweep

    # each degree starts from the previous row's fit, elevated: the objective never rises with
    # the degree, and the rows are as good as independent fits (each of which refits the degrees
    # below it, quadratic work over 2-15)
    sweep = load_sweep(DEFAULT_PATH)
    rows = compare_models(sweep.x, sweep.y, list(range(2, 9)), ["bcm"])
    norms = [r["norm2"] for r in rows]
    assert all(b <= a * (1 + 1e-9) for a, b in zip(norms, norms[1:])), norms
    alone = fit_model("bcm", sweep.x, sweep.y, 8)
    assert rows[-1]["rms"] <= alone.rms * (1 + 1e-6)


def test_bcm_fits_each_degree_once(monkeypatch):
    import host.fitting.rational_bezier as rb

    calls, real = [], rb.fit_bcm

    def spy(x, y, order, *args, **kw):
        warm = kw.get("warm")
        calls.append((order, warm.order if warm is not None else None))
        return real(x, y, order, *args, **kw)

    monkeypatch.setattr(rb, "fit_bcm", spy)  # the fitter's own degree chain calls it by this name too
    x = np.linspace(0, 4095, 300)
    compare_models(x, 60 * x / 4095 + 2 * np.tanh((x - 3700) / 80), [2, 3, 4, 5, 6], ["bcm"])
    assert calls == [(2, None), (3, 2), (4, 3), (5, 4), (6, 5)]


def test_worker_processes_give_the_same_rows():
    x = np.linspace(0, 4095, 400)
    y = 60 * x / 4095 + 2 * np.tanh((x - 3700) / 80)
    one = compare_models(x, y, [2, 3, 4, 5], ["bcm", "pcm", "pwl"], noise=0.01)
    two = compare_models(x, y, [2, 3, 4, 5], ["bcm", "pcm", "pwl"], noise=0.01, jobs=2)
    strip = [[(r["model"], r["order"], r["n_params"], r["norm2"]) for r in rows] for rows in (one, two)]
    assert strip[0] == strip[1]
