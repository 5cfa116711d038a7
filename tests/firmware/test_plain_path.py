"""The plain path: the firmware's viper and native functions run as bytecode, from the same source
with the emitter decorators blanked (host/link/plain_firmware.py), as CircuitPython must run them.
The real MicroPython unix port runs both builds on the simulated actuator; every telemetry word of
the run must agree, and the plain build must still allocate nothing in the control step."""

import pytest

from host.link.plain_firmware import EMITTERS, FIRMWARE, plain_source, write_plain_package
from testkit import interpreters, model

CASES = "tests.firmware.plain_cases"


@pytest.fixture(scope="module")
def plain_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("plain")
    write_plain_package(out)
    return out


@pytest.fixture(scope="module")
def cal_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("cal") / "cal.json"
    model.write_model_calibration(path)
    return str(path)


def test_plain_source_blanks_only_the_decorator_lines():
    text = "@micropython.viper\ndef f(x: int) -> int:\n    return x\n    # @micropython.viper here is a comment\n"
    plain = plain_source(text)
    assert plain == "\ndef f(x: int) -> int:\n    return x\n    # @micropython.viper here is a comment\n"
    assert plain.count("\n") == text.count("\n")  # tracebacks keep their line numbers
    cast = "    s = ptr32(self.st)\n    t = int(ptr16(self.t1)[raw1])\ndef ptr32(buf):\n    return ptr32(a.b) + f(ptr32(x))\n"
    assert plain_source(cast) == "    s = self.st\n    t = int(self.t1[raw1])\ndef ptr32(buf):\n    return a.b + f(x)\n"
    decorated = [p.name for p in FIRMWARE.glob("*.py") if any(d in p.read_text() for d in EMITTERS)]
    assert len(decorated) >= 8, decorated  # the firmware does use them, so this is not vacuous


def test_the_plain_build_computes_every_word_the_viper_build_does(plain_dir, cal_path):
    call = "case_run_records(%r)" % cal_path
    viper = interpreters.on_micropython(CASES, call, timeout=600)
    plain = interpreters.on_micropython(CASES, call, timeout=600, extra_paths=[plain_dir])
    assert plain["source"].startswith(str(plain_dir)) and not viper["source"].startswith(str(plain_dir))
    assert viper["faults"] == [] and viper["dropped"] == 0, viper["faults"]
    assert viper["count"] == 10 + 6 * 400
    # position and force both drove the motor (duty is word 9): the run is not idle noise
    assert any(r[9] != 0 for r in viper["sample"])
    assert (plain["count"], plain["crc"], plain["sample"]) == (viper["count"], viper["crc"], viper["sample"])
    here = interpreters.on_cpython(CASES, call)
    assert (here["count"], here["crc"]) == (viper["count"], viper["crc"])


@pytest.fixture(scope="module")
def data_path(tmp_path_factory):
    """ADC codes recorded from the simulated actuator, with its model calibration (as test_app's)."""
    return model.write_replay_data(tmp_path_factory.mktemp("fw"), steps=600, duty=3000)


@pytest.mark.parametrize("mode,target", [("open_loop", 2500), ("position", 20000), ("force", 3000)])
def test_the_plain_build_allocates_nothing_in_the_control_step(plain_dir, data_path, mode, target):
    out = interpreters.on_micropython("tests.firmware.app_cases", "case_heap_lock(%r, %r, %d)" % (
        data_path, mode, target), timeout=600, extra_paths=[plain_dir])
    assert out["locked"] is True and out["before"] == out["after"], out
