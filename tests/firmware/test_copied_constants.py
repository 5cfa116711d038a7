"""The constants viper code copies from other modules (an imported name is a run-time global,
which viper cannot use as a machine int; firmware/controller.py and firmware/motor.py say so):
each copy equals what it copies, so that changing one module without the other fails here."""

import importlib

import pytest

from firmware.protocol import FIELDS

# (module, copy) -> (module, original); the telemetry record's slots follow protocol.FIELDS
COPIES = {
    ("controller", "_DUTY_MAX"): ("pi_control", "DUTY_MAX"),
    ("motor", "_DUTY_MAX"): ("pi_control", "DUTY_MAX"),
    ("controller", "_S_RAW1"): ("sampler", "RAW1"),
    ("controller", "_S_RAW2"): ("sampler", "RAW2"),
    ("controller", "_S_RAW_REF"): ("sampler", "RAW_REF"),
    ("controller", "_S_RAIL"): ("sampler", "RAIL"),
    ("controller", "_S_RAIL_VALUE"): ("sampler", "RAIL_VALUE"),
    ("controller", "_NO_RAIL"): ("sampler", "NO_RAIL"),
    ("controller", "_RAIL_POT1"): ("sampler", "RAIL_POT1"),
    ("controller", "_F_FAULTS"): ("safety", "FAULTS"),
    ("controller", "_FAULT_RAIL_POT1"): ("safety", "FAULT_RAIL_POT1"),
    ("controller", "_FAULT_RAIL_POT2"): ("safety", "FAULT_RAIL_POT2"),
    ("controller", "_FAULT_HOST_TIMEOUT"): ("safety", "FAULT_HOST_TIMEOUT"),
    ("controller", "_M_D1"): ("measurement", "D1"),
    ("controller", "_M_D2"): ("measurement", "D2"),
    ("controller", "_M_DEFL"): ("measurement", "DEFL"),
    ("controller", "_M_FORCE"): ("measurement", "FORCE"),
    ("controller", "_M_FRIC"): ("measurement", "FRIC"),
    ("controller", "_M_FF_DUTY"): ("measurement", "FF_DUTY"),
    ("controller", "_M_FS_SHIFT"): ("measurement", "FS_SHIFT"),
    ("measurement", "STROKE_CLAMP_UM"): ("protocol", "POSITION_LIMIT_UM"),
    ("measurement", "_DF_PWL_OFFSET"): ("pwl_fixed", "DF_PWL_OFFSET"),
    ("calibration", "STROKE_MAX_UM"): ("protocol", "POSITION_LIMIT_UM"),  # not viper: keeps calibration.py light
}
RECORD = {"_R_T": "t_us", "_R_RAW1": "raw1", "_R_RAW2": "raw2", "_R_REF": "raw_ref", "_R_D1": "d1_um", "_R_D2": "d2_um",
          "_R_DEFL": "defl_um", "_R_FORCE": "force_mN", "_R_TARGET": "target", "_R_DUTY": "duty", "_R_MODE": "mode",
          "_R_FAULTS": "faults"}


def _value(module, name):
    return getattr(importlib.import_module("firmware." + module), name)


@pytest.mark.parametrize("copy,original", list(COPIES.items()), ids=lambda v: "%s.%s" % v)
def test_each_copy_equals_what_it_copies(copy, original):
    assert _value(*copy) == _value(*original)


def test_the_fault_bits_are_the_interface_tables():
    from firmware.protocol import FAULT_NAMES

    for bit, name in FAULT_NAMES:
        assert _value("safety", "FAULT_" + name.upper()) == bit, name


def test_the_wrap_and_the_record_size_are_the_interface_tables():
    from firmware.protocol import T_US_WRAP

    assert _value("controller", "_MASK") == T_US_WRAP - 1  # [wrap]: t_us, steps, tick differences
    assert _value("telemetry", "RECORD_WORDS") == len(FIELDS)  # the ring's record is the table's


def test_the_record_slots_follow_the_telemetry_fields():
    assert sorted(RECORD.values()) == sorted(FIELDS)  # every field has its slot
    for name, field in RECORD.items():
        assert _value("controller", name) == FIELDS.index(field), name
