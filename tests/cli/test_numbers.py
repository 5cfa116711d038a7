"""Every numeric option of every command refuses NaN, infinities, huge, empty and non-numbers
with one `error:` line and status 2, before anything runs (found from the parser itself, so a
new option is covered by being added)."""

import pytest

from host import cli
from host.commands._options import ranged


def _numeric_options():
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    out = []
    for name, p in sorted(sub.choices.items()):
        for action in p._actions:
            if action.type in (int, float):
                out.append((name, action.option_strings[0], "plain"))
            elif getattr(action.type, "range", None):
                out.append((name, action.option_strings[0] if action.option_strings else action.dest, "ranged"))
    return out


OPTIONS = _numeric_options()


def test_every_numeric_option_is_range_checked():
    assert OPTIONS, "no numeric options found"
    plain = [(c, o) for c, o, kind in OPTIONS if kind == "plain"]
    assert not plain, "use host.commands._options.ranged for: %s" % plain


@pytest.mark.parametrize("command,option", [(c, o) for c, o, _ in OPTIONS])
@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e308", "-1e308", "", "abc"])
def test_bad_numbers_are_one_error_line(command, option, value, capsys):
    code = cli.main([command, option, value])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error: ") and option in err[0], err


def test_a_range_says_what_it_takes():
    with pytest.raises(Exception) as info:
        ranged(float, 0, 60)("61")
    assert "outside 0..60" in str(info.value)
    assert ranged(int, 1, 16)("12") == 12


@pytest.mark.parametrize("command", ["calibrate", "experiment"])
def test_a_pot_model_the_fitter_does_not_know_is_refused_before_any_board_work(command, capsys):
    """`--model nan` ended, after the pots had been swept, in a KeyError traceback."""
    args = [command] + (["paper", "--out", "unused"] if command == "experiment" else []) + \
        ["--port", "/dev/no-such-port", "--model", "nan"]
    code = cli.main(args)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--model" in err[0] and "nan" in err[0], err


@pytest.mark.parametrize("argv,words", [
    (["calibrate", "--df-order", "13"], "neither auto nor an order 1..12"),
    (["experiment", "paper", "--out", "unused", "--force-order", "0"], "neither auto nor an order 1..5"),
    (["compare", "x.csv", "--orders", "9-3"], "bad order range"),
    (["compare", "x.csv", "--models", "bcm,nope"], "unknown model"),
    (["tune", "position", "--kp", "1,a"], "whole numbers separated by commas"),
    (["tune", "position", "--ki", "40000"], "within 0..32767"),
    (["tune", "force", "--step", "0"], "must not be 0"),
])
def test_options_beyond_numbers_are_checked_by_argparse_too(capsys, argv, words):
    """Orders, order lists, model lists and gain lists are argparse types: one error line, status 2,
    before a file is read or a board opened (they were checked after the port had opened)."""
    code = cli.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and words in err[0], err
