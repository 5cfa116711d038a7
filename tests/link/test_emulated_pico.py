"""The firmware on an emulated Raspberry Pi Pico: MicroPython's own rp2 port (v1.28.0 for RPI_PICO, the
UF2 a user downloads, from ../shared/mcu/rp2) on rp2040js, the simulated actuator on the pins of
boards/pico.json (host/link/emulated_pico/). Installed by `host flash` over the emulated USB serial,
as on a real Pico; then `host status`, a closed-loop move and a force hold against the plant, and
every counter of the step across its wrap on the real port with its hard timer.

Without ../shared these skip with the reason; under CI (CI=true) that is a failure.
"""

import json
import subprocess
import sys

import pytest

from testkit.interpreters import REPO
from testkit.processes import run as host
from testkit.model import sim_board, write_model_calibration
from tests.conftest import SHARED, shared_dir
from tests.link.emulated_moves import move_and_hold

UF2 = SHARED / "mcu" / "rp2" / "micropython-v1.28.0-RPI_PICO.uf2"




@pytest.fixture(scope="module")
def calibration(tmp_path_factory):
    """The simulated actuator's own calibration (pot tables, Df, force, friction), made for the pico."""
    path = tmp_path_factory.mktemp("cal") / "pico-model.json"
    crc = write_model_calibration(path, board=dict(sim_board(), name="pico"))
    return path, crc


@pytest.fixture(scope="module")
def pico(calibration):
    """An emulated Pico out of its box (MicroPython, an empty filesystem), then `host flash`."""
    shared_dir(UF2.parent, "the MicroPython firmware for the emulated Pico")
    from host.link.emulated_pico.board import EmulatedPico

    with EmulatedPico(uf2=str(UF2)) as board:
        code, out, err = host("flash", "--port", board.path, "--board", "pico", "--calibration", str(calibration[0]))
        assert code == 0, out + err
        assert "flashed: firmware" in out and "on pico" in out, out
        yield board


def test_host_status_on_the_flashed_pico(pico, calibration):
    code, out, err = host("status", "--port", pico.path, "--json")
    assert code == 0, err
    status = json.loads(out)
    assert status["board"] == "pico"
    assert status["interpreter"].startswith("micropython 1.28")
    assert status["timer"] == "hard"  # rp2's Timer(hard=True): the step runs in the alarm interrupt
    assert status["period_us"] == 1000
    assert status["overruns"] == 0 and status["faults"] == []
    assert status["calibration_crc"] == "%08x" % calibration[1] and status["calibration_error"] is None


def test_a_move_and_a_force_hold_against_the_plant(pico):
    status = move_and_hold(pico, timeout_s=20)
    assert status["overruns"] == 0, status



def test_every_counter_wraps_on_the_real_port(pico):
    """tests/firmware/wrap_on_board.py on the Pico: the installed firmware, rp2's ADC, PWM and hard
    timer, every counter started just below its limit, 31-bit small ints."""
    from host.link.board_client import BoardClient
    from host.link.flashing import mpremote

    out = mpremote(pico.path, ["run", str(REPO / "tests" / "firmware" / "wrap_on_board.py")], timeout=240)
    lines = [line for line in out.splitlines() if line.startswith("RESULT ")]
    assert lines, out[-2000:]
    r = json.loads(lines[-1][len("RESULT "):])
    assert r["faults"] == [] and r["timer"] == "hard", r  # no step_exception: nothing left 31 bits
    assert r["crossed"] and r["gaps"] == [r["period"]], r  # t_us crossed 2**30, no step lost or doubled
    assert r["records"] >= 40, r
    assert r["steps_after"] < 200, r  # steps wrapped from 2**30 - 3 to a small count
    assert r["head"] < 200 and r["dropped"] == 0, r  # the ring's indices wrapped, nothing dropped
    assert r["silence"] == r["silence_cap"], r  # the silence count stopped at its cap
    assert r["overruns"] == r["mask"], r  # the overrun count saturated, never wrapped
    with BoardClient(pico.path, check=False) as client:  # the firmware boots again afterwards
        assert client.soft_reset(wait=30)
        assert client.handshake()["board"] == "pico"


def test_the_command_line_forms_start_an_emulated_pico_with_the_firmware(tmp_path):
    """`--port sim:rp2040` (a Pico for one command, installed by host flash) and `host sim --chip
    rp2040` (one that runs until stopped, its serial device on the first line)."""
    import signal

    shared_dir(UF2.parent, "the MicroPython firmware for the emulated Pico")
    code, out, err = host("status", "--port", "sim:rp2040", "--uf2", str(UF2), "--json")
    assert code == 0, err
    status = json.loads(out)
    assert status["board"] == "pico" and status["timer"] == "hard" and status["calibration_crc"] is None
    assert "installing the firmware with host flash" in err  # how the firmware got there, said on stderr
    proc = subprocess.Popen([sys.executable, "-m", "host", "sim", "--chip", "rp2040", "--uf2", str(UF2)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)
    try:
        path = proc.stdout.readline().strip()
        assert path.startswith("/dev/"), (path, proc.stderr.read() if proc.poll() is not None else "")
        code, out, err = host("status", "--port", path, "--json")
        assert code == 0 and json.loads(out)["board"] == "pico", err
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 0


def test_the_emulator_is_pinned_to_one_version():
    """rp2040js's version is said once in package.json, locked with its integrity hash, and the
    installer's message names the same one (no ../shared needed)."""
    from host.link.emulated_pico import node

    package = json.loads((node.HERE / "package.json").read_text())
    lock = json.loads((node.HERE / "package-lock.json").read_text())
    assert package["dependencies"] == {"rp2040js": node.RP2040JS}
    locked = lock["packages"]["node_modules/rp2040js"]
    assert locked["version"] == node.RP2040JS and locked["integrity"].startswith("sha512-")
    assert set(node.FILES) <= {p.name for p in node.HERE.iterdir()}  # what an install copies is there
