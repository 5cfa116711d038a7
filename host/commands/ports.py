"""`host ports`: the serial ports on this machine, what is probably on each, and (--probe)
whether lsea-kit firmware answers there."""

import json

from host.errors import DONE
from host.link import ports as port_list
from host.link.port_advice import advice
from host.link.ports import label
from host.terminal import output


def add_parser(subparsers):
    p = subparsers.add_parser("ports", help="list serial ports and the boards on them (--port auto picks the only one)",
                              description="List the serial ports this computer sees, then the virtual boards `host sim` runs, "
                              "each with its USB ids and the board its ids say it is (or not one we know); --probe asks each "
                              "board-like port whether lsea-kit firmware answers. --port auto in the other commands picks "
                              "the only board.")
    p.add_argument("--probe", action="store_true", help="ask each board-like port whether lsea-kit firmware answers")
    p.add_argument("--json", action="store_true", help="print the ports as a JSON list")
    p.set_defaults(func=run)


def probe(device):
    """'lsea-kit VERSION on BOARD' or why not."""
    from host.errors import UserError
    from host.link.connect import ask_firmware

    try:
        hello, why_not = ask_firmware(device)
    except (UserError, OSError) as exc:  # the port would not open: said on its line, the others go on
        hello, why_not = None, str(exc)
    if hello is None:
        return "no lsea-kit firmware (%s)" % (why_not.split(":")[0],)
    return "lsea-kit %s on %s" % (hello.get("version"), hello.get("board"))


def run(args):
    ports = port_list.list_ports()
    if args.json:
        rows = [{"device": device, "vid": vid, "pid": pid, "description": desc, "board": label(vid, pid),
                 **({"probe": probe(device)} if args.probe and label(vid, pid) else {})}
                for device, vid, pid, desc in ports]
        output(json.dumps(rows, indent=1))
        return DONE
    if not ports:
        output(advice("no ports", None))
        return DONE
    for device, vid, pid, desc in ports:
        ids = "%04x:%04x" % (vid, pid) if isinstance(vid, int) and isinstance(pid, int) else "-"
        what = label(vid, pid) or "not a board we know"
        line = "%-20s %-10s %s (%s)" % (device, ids, what, desc)
        if args.probe and label(vid, pid):
            line += ": " + probe(device)
        output(line)
    return DONE
