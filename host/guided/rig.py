"""The bench rig: what a person mounts for each step, and, on a virtual board, doing it.

On a real board the rig prints the instruction and waits for Enter. On a virtual board it also
mounts it: the board object (host.link.virtual_board.VirtualBoard, the unix port, through rig.json
in its flash; host.link.emulated_pico.board.EmulatedPico, straight to the actuator beside the
chip) applies the rig's state with `rig(state)` and shows the gauge's display with `gauge()`.
The reference sensor's scale (its datasheet: the position at code 0 and the span over full
scale) comes from the simulated actuator on a virtual board ("actuator.reference") and from
--ref-zero-mm / --ref-span-mm on a real one.

The force gauge is read one of two ways (`--gauge`): from its display ("display": typed in by the
person on a real bench; the virtual rig's display on a simulated one), or ("adc") from its
analog output wired to the board's reference ADC input for the force step, through the firmware's
telemetry, with the gauge's scale (--gauge-zero-n / --gauge-span-n, or the simulated actuator's).
"""

from host.errors import UserError


class Rig:
    def __init__(self, prompter, board=None, gauge="display", gauge_scale=None, adc_bits=12):
        """`board`: the virtual board the rig mounts things on, None on a real bench."""
        self.prompter = prompter
        self.board = board
        # "load" None: not known yet (a gauge may still hang from the last session), so the first
        # no_load() asks; later ones ask only if a step hooked something since
        self.state = {"reference": None, "load": None, "fault": None}
        if gauge not in ("display", "adc"):
            raise UserError("--gauge must be display or adc")
        if gauge == "adc" and gauge_scale is None:
            raise UserError("--gauge adc needs the gauge's scale: --gauge-zero-n and --gauge-span-n")
        self.gauge = gauge
        self.gauge_scale = gauge_scale  # (N at code 0, N over full scale) for --gauge adc
        self.adc_bits = adc_bits
        self.ends = ("0 mm", "60 mm")  # how the instructions name the stroke's ends (run_steps sets them)

    @property
    def virtual(self):
        return self.board is not None

    def _do(self, instruction, **change):
        self.state.update(change)
        self.prompter.wait(instruction)
        if self.virtual:  # a virtual rig starts with nothing hooked
            self.board.rig(dict(self.state, load=self.state["load"] or {"kind": "none"}))

    def mount_reference(self, pot):
        which = "1 (nut, D1)" if pot == "pot1" else "2 (output block, D2)"
        self._do("Mount the reference sensor in parallel with potentiometer %s; unhook the force gauge." % which,
                 reference=pot, load={"kind": "none"})

    def no_load(self):
        if self.state["load"] == {"kind": "none"}:
            return  # unhooked at the last instruction: asking again only makes the person look twice
        self._do("Unhook the force gauge: the output block must run free end to end (no load).", load={"kind": "none"})

    def hook_gauge(self, anchor_mm, side="high", gap_mm=None):
        """side "high": the gauge sits toward 60 mm and the block pulls it toward 0 mm (negative
        actuator forces, the paper's rig); "low": toward 0 mm, the block pulls it toward 60 mm.
        With `gap_mm` the block is gap_mm on the slack side of the anchor now, and the person
        hooks the fibre to go taut after the block has moved that far (a person sees where the
        block is, not its true position in mm: on the virtual rig the anchor follows from the
        block's place)."""
        low, high = self.ends
        where = ("on the %s side (the block pulls it toward %s)" % (high, low) if side == "high"
                 else "on the %s side (the block pulls it toward %s)" % (low, high))
        change = {"load": {"kind": "gauge", "anchor_mm": float(anchor_mm), "side": side}}
        if gap_mm is not None:
            change["load"]["gap_mm"] = float(gap_mm)
        wire = ""
        if self.gauge == "adc":
            change["reference"] = "gauge"
            wire = " Wire the gauge's analog output to the board's reference input."
        taut = ("taut at D2 = %.1f mm" % anchor_mm if gap_mm is None else
                "taut once the block has moved %.1f mm from here toward %s (D2 = %.1f mm)"
                % (gap_mm, low if side == "high" else high, anchor_mm))
        self._do("Hook the force gauge to the output block through the fibre, %s, anchored so it goes "
                 "%s.%s" % (where, taut, wire), **change)

    def hang_weight(self, weight_n):
        """A weight on a fibre from the output block over a pulley at the high end: a force of
        about `weight_n` toward the high end wherever the block is (the gain step's steady load)."""
        low, high = self.ends
        self._do("Hang a weight of about %g N from the output block, on a fibre over a pulley at the %s end (it "
                 "pulls the block toward %s wherever it is); unhook the force gauge." % (weight_n, high, high),
                 load={"kind": "constant", "force_n": float(weight_n)})

    def read_gauge_n(self, client, records=None, seconds=0.3):
        """The gauge's reading in N: from its display, or (--gauge adc) the mean of the reference
        channel over `records` (telemetry just logged) or over `seconds` of new telemetry."""
        if self.gauge == "display":
            return self.gauge_reading_n()
        from host.guided import acquire

        if records is None or not len(records):
            records = acquire.collect(client, seconds)
        if not len(records):
            raise UserError("no telemetry from the board while reading the gauge channel")
        zero, span = self.gauge_scale
        code = float(records[:, acquire.COL["raw_ref"]].astype(float).mean())
        return zero + span * code / ((1 << self.adc_bits) - 1)

    def gauge_reading_n(self, question="Force gauge reading (N):", beat=None):
        """The force gauge's reading: from the virtual rig's display, else typed by the person.
        `beat` (e.g. client.heartbeat_if_due) is called while waiting for a fresh display: the
        motor may be running meanwhile, and the firmware stops it after 1 s without the host."""
        if not self.virtual:
            return self.prompter.number(question)
        return float(self.board.gauge(beat=beat)["force_n"])


def gauge_scale(actuator, zero_n=None, span_n=None):
    """(N at code 0, N over full scale) of the gauge's analog output: options first, else the
    simulated actuator's gauge (fraction = zero_fraction + N / n_per_fraction)."""
    g = (actuator or {}).get("gauge") or {}
    if zero_n is None and "zero_fraction" in g:
        zero_n = -float(g["zero_fraction"]) * float(g["n_per_fraction"])
    if span_n is None and "n_per_fraction" in g:
        span_n = float(g["n_per_fraction"])
    if zero_n is None or span_n is None:
        return None
    return float(zero_n), float(span_n)


def reference_scale(actuator, zero_mm=None, span_mm=None):
    """(zero_mm, span_mm) of the reference sensor: options first, else the simulated actuator's
    (`actuator`: its description, None on a real bench)."""
    ref = (actuator or {}).get("reference") or {}
    zero = zero_mm if zero_mm is not None else ref.get("zero_mm")
    span = span_mm if span_mm is not None else ref.get("span_mm")
    if zero is None or span is None:
        raise UserError("give the reference sensor's scale: --ref-zero-mm (position at code 0) and "
                        "--ref-span-mm (travel over full scale), or use --reference manual")
    return float(zero), float(span)


def reference_mm(raw_ref, adc_bits, scale):
    zero, span = scale
    return zero + span * (raw_ref.astype(float) / ((1 << adc_bits) - 1))
