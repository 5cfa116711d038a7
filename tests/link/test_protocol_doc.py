"""docs/protocol.md is exactly what host/link/protocol_doc.py renders from firmware/protocol.py."""

from firmware import protocol as P
from host.link.protocol_doc import DOC, render


def test_protocol_doc_is_current():
    assert DOC.read_text() == render(), "run: python -m host.link.protocol_doc"


def test_protocol_doc_lists_every_command_and_frame_type():
    text = render()
    for name in P.COMMAND_NAMES:
        assert "| `%s` |" % name in text
    for _, name in P.FRAME_TYPES:
        assert "| `%s` |" % name in text
