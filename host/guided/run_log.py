"""What a `host calibrate` run measured, kept beside the calibration file as each step finishes.

The calibration file only receives accepted sections. A person who stops a run, or whose board
disappears in the middle of the force step, still wants to see what the sweeps and fits said:
CALIBRATION.results.json (every step's check and fit lines, plots, whether it was accepted)
and CALIBRATION.report.md (the same for people) are rewritten atomically after every step, and
when the run stops they say in which step and why.
"""

import datetime
import json
import os
from pathlib import Path


def _atomic_write(path, text):
    tmp = path.with_name("." + path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


class RunLog:
    """Steps as they finish, saved after each; `stop(why)` records where the run ended early."""

    def __init__(self, calibration_path, command, board=None):
        path = Path(calibration_path)
        self.json_path = path.with_name(path.stem + ".results.json")
        self.report_path = path.with_name(path.stem + ".report.md")
        self.results = {"command": command, "calibration": str(path), "board": board,
                        "started": datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat(),
                        "steps": [], "phase": None, "stopped": None, "finished": None}

    @property
    def measured(self):
        return bool(self.results["steps"])

    def start(self, step):
        self.results["phase"] = step

    def done(self, outcome, accepted):
        self.results["steps"].append({"step": outcome.step, "ok": bool(outcome.ok), "accepted": bool(accepted),
                                      "sections": sorted(outcome.sections) if accepted else [],
                                      "lines": list(outcome.lines), "plots": [Path(p).name for p in outcome.plots]})
        self.save()

    def finish(self):
        self.results["phase"] = None
        self.results["finished"] = datetime.datetime.now(datetime.timezone.utc).replace(microsecond=0).isoformat()
        self.save()

    def stop(self, why):
        self.results["stopped"] = {"phase": self.results["phase"], "why": why}
        self.save()

    def save(self):
        self.json_path.parent.mkdir(parents=True, exist_ok=True)  # a run stopped before it made the folder
        _atomic_write(self.json_path, json.dumps(self.results, indent=1) + "\n")
        _atomic_write(self.report_path, self.report())

    def report(self):
        r = self.results
        lines = ["# Calibration run", "", "`%s`, started %s, board %s; calibration file %s." % (
            r["command"], r["started"], r["board"], r["calibration"]), ""]
        if r["stopped"]:
            phase = r["stopped"]["phase"]
            lines += ["**Stopped %s**: %s. The calibration file holds only the steps accepted before "
                      "(the previous file, if any, was kept under a dated name)." % (
                          "during %s" % phase if phase else "before its first step", r["stopped"]["why"]), ""]
        elif r["finished"]:
            lines += ["Finished %s." % r["finished"], ""]
        for s in r["steps"]:
            verdict = "accepted (%s written)" % ", ".join(s["sections"]) if s["accepted"] else "not accepted"
            lines += ["## %s: %s%s" % (s["step"], verdict, "" if s["ok"] else ", some checks FAILED"), ""]
            lines += ["- " + line for line in s["lines"]]
            lines += [""] + ["![%s](%s)" % (p, p) for p in s["plots"]] + [""]
        if not r["steps"]:
            lines += ["No step finished.", ""]
        return "\n".join(lines)
