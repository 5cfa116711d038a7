"""Prompts: --yes answers Enter/accept itself and refuses typed readings; a person can abort."""

import pytest

from host.errors import UserError
from host.guided.prompts import Aborted, Prompter


def scripted(*answers):
    asked = []
    it = iter(answers)

    def ask(question):
        asked.append(question)
        try:
            return next(it)
        except StopIteration:
            raise EOFError
    return ask, asked


def test_yes_never_asks():
    ask, asked = scripted()
    said = []
    p = Prompter(yes=True, ask=ask, out=said.append)
    p.wait("Mount the reference.")
    assert p.accept("Accept?") is True
    assert asked == []
    assert any("--yes" in s for s in said)


def test_yes_refuses_typed_readings():
    p = Prompter(yes=True, ask=scripted()[0], out=lambda s: None)
    with pytest.raises(UserError, match="--yes"):
        p.number("Dial gauge (mm):")


def test_enter_continues_and_a_aborts():
    ask, asked = scripted("", "a")
    p = Prompter(ask=ask, out=lambda s: None)
    p.wait("Mount it.")
    with pytest.raises(Aborted):
        p.wait("Mount the next.")
    assert len(asked) == 2


def test_accept_reject_abort_and_reask():
    ask, asked = scripted("maybe", "y", "n", "a")
    said = []
    p = Prompter(ask=ask, out=said.append)
    assert p.accept("Accept?") is True
    assert len(asked) == 2 and "y, n or a" in said[-1]
    assert p.accept("Accept?") is False
    with pytest.raises(Aborted):
        p.accept("Accept?")


def test_end_of_input_aborts():
    p = Prompter(ask=scripted()[0], out=lambda s: None)
    with pytest.raises(Aborted):
        p.accept("Accept?")


def test_numbers_are_parsed_and_bad_ones_asked_again():
    ask, asked = scripted("twelve", "12,5", "-3.25")
    p = Prompter(ask=ask, out=lambda s: None)
    assert p.number("mm:") == 12.5
    assert p.number("mm:") == -3.25
    assert len(asked) == 3
