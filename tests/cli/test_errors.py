"""User-caused failures are one line and a non-zero exit, never a traceback: a header-only or
garbage telemetry CSV for `host plot`, and a board that disappears mid-command (pyserial's
SerialException)."""

import pytest

from host import cli


@pytest.mark.parametrize("content,words", [
    ("t_us,raw1,raw2\n", "no records"),
    ("hello\nworld\n", "not a telemetry log"),
    ("t_us,raw1\n1,2\n3\n", "not a telemetry log"),
    ("raw,reference\n100,0.00\n", "not a telemetry log"),  # a pot sweep: was "could not convert string '0.00'"
    ('{"crc32": 1}', "not a telemetry log"),  # was "no records (only a header)"
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


def test_a_full_disk_names_the_file_and_blames_no_board(tmp_path, capsys):
    """A log written to a full disk (Linux's /dev/full) is one line naming the file, not "the board
    stopped answering" (what every OSError used to be called)."""
    import os

    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full on this system")
    code = cli.main(["log", "--port", "sim", "--out", "/dev/full", "--seconds", "0.3"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1] == "error: /dev/full: No space left on device", err


def test_os_errors_are_said_by_what_they_are():
    import errno

    import serial

    from host.errors import os_error_line

    assert os_error_line(OSError(errno.EISDIR, "Is a directory", "/tmp/out")) == "/tmp/out: Is a directory"
    full = os_error_line(OSError(errno.ENOSPC, "No space left on device"))
    assert "No space left" in full and "board" not in full, full
    for gone in (serial.SerialException("write failed"), OSError(errno.EIO, "Input/output error")):
        assert os_error_line(gone).endswith("(the board stopped answering or was unplugged?)"), gone


@pytest.mark.parametrize("argv,words", [
    # a float literal with an exponent is a value, not an unknown option (argparse's own rule
    # knows only -5 and -0.5), so its range check answers, not "expected one argument"
    (["move", "--port", "sim", "--to", "-1e300"], "-1e300 is outside"),
    (["force", "--port", "sim", "--target", "-1e3"], "-1e3 is outside"),
    # an empty gain list is a mistake, not "use the defaults"
    (["tune", "position", "--port", "sim", "--kp", ""], "is empty"),
])
def test_odd_numbers_are_read_as_the_user_wrote_them(capsys, argv, words):
    code = cli.main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("error: ") and words in err[0], err


def test_help_shows_percent_signs_once(capsys):
    assert cli.main(["tune", "--help"]) == 0
    out = capsys.readouterr().out
    assert "10-90 %)" in out and "%%" not in out


def test_show_of_two_files_names_missing_values_in_words(tmp_path, capsys):
    from host.calibration.file import read_calibration, write_calibration
    from testkit import model

    a, b = tmp_path / "a.json", tmp_path / "b.json"
    model.write_model_calibration(a)
    doc = read_calibration(a)
    doc["board"] = None
    doc["pots"] = {}
    write_calibration(b, doc)
    assert cli.main(["show", str(a), str(b)]) == 0
    out = capsys.readouterr().out
    assert "board: sim | not given" in out and "None" not in out and "{}" not in out, out


@pytest.mark.parametrize("argv,words", [
    (["fit", "SWEEP", "--out", "/dev/full"], "/dev/full is not a regular file"),  # hung, memory growing 1 GB/s
    (["fit", "SWEEP", "--out", "/dev/zero"], "/dev/zero is not a regular file"),  # MemoryError traceback
    (["fit", "/dev/zero"], "/dev/zero is not a regular file"),
    (["fit", "DIR"], "is a directory, not a sweep file"),  # was "not found"
    (["show", "DIR"], "is a directory, not a calibration file"),
    (["plot", "FIFO"], "is not a regular file"),  # was "no such file"; reading it would wait forever
    (["show", "BIG"], "larger than any calibration file"),
    # where a calibration is to go, checked before the work (a review lost 42 s of measuring to it)
    (["calibrate", "--port", "sim", "--yes", "--out", "DIR"], "is a directory, not a calibration file"),
    (["calibrate", "--port", "sim", "--yes", "--out", "UNDER_A_FILE"], "is a file, not a folder"),
    (["fit", "SWEEP", "--out", "DIR"], "is a directory, not a calibration file"),
    (["fit", "SWEEP", "--out", "NO_FOLDER"], "no folder"),  # was an Errno naming a temporary file
    # a virtual board given a calibration it cannot use: named now, not "calibration.json unusable" later
    (["status", "--port", "sim", "--calibration", "TRUNCATED"], "TRUNCATED: not valid JSON"),
    (["show", "EMPTY"], "EMPTY is empty"),  # was "not valid JSON"
])
def test_user_files_are_checked_before_they_are_read(tmp_path, argv, words):
    """Each in a fresh process with a deadline: a regression hangs or eats the memory instead."""
    import os
    import subprocess
    import sys

    sweep = tmp_path / "sweep.csv"
    sweep.write_text("raw,reference\n" + "".join("%d,%.4f\n" % (c, c * 0.016) for c in range(100, 4000, 10)))
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    big = tmp_path / "big.json"
    with open(big, "wb") as f:
        f.truncate((1 << 20) + 1)  # sparse: a size, no disk
    names = {"SWEEP": str(sweep), "DIR": str(tmp_path), "FIFO": str(fifo), "BIG": str(big),
             "UNDER_A_FILE": str(sweep / "cal.json"), "NO_FOLDER": str(tmp_path / "nowhere" / "cal.json"),
             "TRUNCATED": str(tmp_path / "truncated.json"), "EMPTY": str(tmp_path / "empty.json")}
    (tmp_path / "truncated.json").write_text('{"crc32": 1, "payl')
    (tmp_path / "empty.json").write_text("")
    for name in ("TRUNCATED", "EMPTY"):
        words = words.replace(name, names[name])
    r = subprocess.run([sys.executable, "-m", "host", "-q"] + [names.get(a, a) for a in argv],
                       capture_output=True, text=True, timeout=120)
    err = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(err) == 1 and words in err[0], (r.returncode, err)


def test_a_log_cut_mid_line_is_plotted_without_its_last_line(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    from firmware.protocol import FIELDS

    path = tmp_path / "run.csv"
    rows = "".join(",".join(str(1000 * i if k == 0 else 100 + i + k) for k in range(len(FIELDS))) + "\n" for i in range(50))
    path.write_text(",".join(FIELDS) + "\n" + rows + "50000,20")  # the logger killed mid-write
    code = cli.main(["plot", str(path), "--out", str(tmp_path / "run.png")])
    err = capsys.readouterr().err
    assert code == 0 and (tmp_path / "run.png").exists() and "cut short" in err, err


def test_a_truncated_calibration_is_called_truncated(tmp_path, capsys):
    from testkit import model

    path = tmp_path / "cal.json"
    model.write_model_calibration(path)
    text = path.read_text()
    path.write_text(text[: len(text) // 2])  # a copy that stopped half way
    assert cli.main(["show", str(path)]) == 2
    err = capsys.readouterr().err
    assert "truncated" in err and "laid out" not in err, err


def test_a_link_that_vanishes_is_a_link_error_in_one_line():
    """The board's end of a real pseudo-terminal closes while the client waits for a reply (a
    board unplugged mid-command): BoardClient raises LinkError, a UserError (the CLI's one line,
    exit 2) and a TimeoutError (an OSError: code that waits can tell it from a refusal)."""
    import os
    import pty
    import threading

    from host.errors import LinkError, UserError
    from host.link.board_client import BoardClient

    board_end, host_end = pty.openpty()
    name = os.ttyname(host_end)
    client = BoardClient(name, check=False, retries=50, timeout=0.1)
    try:
        threading.Timer(0.3, os.close, (board_end,)).start()  # unplugged while status waits
        with pytest.raises(LinkError) as caught:
            client.request("status")
        assert isinstance(caught.value, UserError) and isinstance(caught.value, TimeoutError)
        assert str(caught.value).startswith("lost the board on %s" % name), caught.value
    finally:
        client.close()
        os.close(host_end)


def test_a_log_whose_board_stops_streaming_ends_with_a_link_error(monkeypatch):
    """`host log --seconds` counts the board's time; a board that sends nothing more would never
    reach it, so after NO_DATA_S of wall time without a record the recording ends with LinkError."""
    from types import SimpleNamespace

    import host.link.stream as stream
    from host.errors import LinkError

    monkeypatch.setattr(stream, "NO_DATA_S", 0.3)
    silent = SimpleNamespace(port="/dev/ttyACM9", heartbeat_if_due=lambda: None, frames=lambda timeout: [])
    tee = stream.Tee(silent, sinks=[lambda rows: None])
    with pytest.raises(LinkError, match="no telemetry from /dev/ttyACM9"):
        tee.pump(seconds=5.0)
