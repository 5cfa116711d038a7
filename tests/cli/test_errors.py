"""User-caused failures are one line and a non-zero exit, never a traceback: a header-only or
garbage telemetry CSV for `host plot`, and a board that disappears mid-command (pyserial's
SerialException)."""

import pytest

from host import cli


@pytest.mark.parametrize("content,words", [
    ("t_us,raw1,raw2\n", "no records"),
    ("hello\nworld\n", "not a telemetry log"),
    ("t_us,raw1\n1,2\n3\n", "not a telemetry log"),
])
def test_plot_of_a_bad_csv_is_one_line(tmp_path, capsys, content, words):
    path = tmp_path / "run.csv"
    path.write_text(content)
    code = cli.main(["plot", str(path)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error: ") and words in err[0], err


def test_a_board_that_disappears_is_one_line(monkeypatch, capsys):
    import serial

    import host.commands.status as status

    def gone(args):
        raise serial.SerialException("device reports readiness to read but returned no data")

    monkeypatch.setattr(status, "run", gone)
    code = cli.main(["status", "--port", "/dev/null"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "stopped answering" in err[0], err
