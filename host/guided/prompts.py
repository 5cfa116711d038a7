"""Questions to the person at the bench: press Enter, accept or abort, type a reading.

`Prompter(yes=True)` answers every question itself (Enter, accept) and refuses questions only a
person can answer (typed readings) with a one-line UserError, so `--yes` never hangs.
Answering "a" (or end of input, Ctrl-D) to any question aborts the whole calibration.
"""


from host.terminal import end_progress, note, progress_line, tell  # noqa: F401  (the guided steps' progress)

from host.errors import UserError


class Aborted(UserError):
    """The person chose to abort: nothing more is written or flashed."""


class Prompter:
    def __init__(self, yes=False, ask=None, out=None):
        """`out` takes what is said (default: on stderr; under --quiet silenced with `yes`, where
        nobody answers, and kept without it, where a person judges what they are asked about)."""
        self.yes = yes
        self._ask = ask or input
        self._out = out or (note if yes else tell)

    def say(self, text):
        self._out(text)

    def _read(self, question):
        try:
            return self._ask(question).strip()
        except EOFError:
            raise Aborted("calibration aborted (end of input)") from None

    def wait(self, instruction):
        """Tell the person what to do and wait for Enter ('a' aborts)."""
        if self.yes:
            self.say(instruction + " [--yes: go on]")
            return
        answer = self._read(instruction + " Press Enter when done (a = abort): ")
        if answer.lower() in ("a", "abort", "q"):
            raise Aborted("calibration aborted")

    def accept(self, question):
        """True to accept, False to skip this result; 'a' aborts everything."""
        if self.yes:
            self.say(question + " [--yes: accepted]")
            return True
        while True:
            answer = self._read(question + " [y = accept / n = reject / a = abort]: ").lower()
            if answer in ("y", "yes"):
                return True
            if answer in ("n", "no"):
                return False
            if answer in ("a", "abort", "q"):
                raise Aborted("calibration aborted")
            self.say("please answer y, n or a")

    def direction(self, question):
        """+1 (toward the stroke's high end, 60 mm on 0-60 mm), -1 (toward its low end) or None (not seen,
        or --yes: nobody to ask)."""
        if self.yes:
            self.say(question + " [--yes: nobody watching]")
            return None
        while True:
            answer = self._read(question + " [+ = toward the high end / - = toward the low end / ? = did not see / a = abort]: ")
            if answer in ("+", "60"):
                return 1
            if answer in ("-", "0"):
                return -1
            if answer == "?":
                return None
            if answer.lower() in ("a", "abort", "q"):
                raise Aborted("calibration aborted")
            self.say("please answer +, -, ? or a")

    def number(self, question):
        """A number the person reads off an instrument (dial gauge, force gauge)."""
        if self.yes:
            raise UserError("--yes cannot type instrument readings: drop --yes, or use the rig's channel instead of 'manual'")
        while True:
            answer = self._read(question + " ")
            if answer.lower() in ("a", "abort", "q"):
                raise Aborted("calibration aborted")
            try:
                return float(answer.replace(",", "."))
            except ValueError:
                self.say("not a number: %r (a = abort)" % answer)



