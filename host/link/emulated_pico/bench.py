"""The emulated Pico's bench: the chip (pico.mjs under Node) in lockstep with the simulated actuator.

Run as its own process (`python -m host.link.emulated_pico.bench CONFIG`, started by
host/link/emulated_pico/board.py), because the lockstep exchange runs a thousand times a second
of emulated time and must not wait on a busy host's other threads. It

- holds the actuator (boards/sim/actuator.py, built from the simulated board file's "actuator")
  wired to the Pico's pins by boards/sim/harness.py from the board file (boards/pico.json): the
  pots, reference and gauge voltages as ADC codes, the H-bridge inputs' levels as motor volts;
- runs the chip in slices of SLICE_NS of emulated time: after each, the actuator is advanced by
  the same time at the mean voltage the bridge saw in it, and the next slice's ADC conversions
  read codes drawn from the actuator's own noise model at the new state. Emulated time never
  follows the wall clock; it is only held back so that it does not run ahead of it (a board
  that idles faster than real time would see a host's pauses as silence and stop the motor);
- carries the USB serial port to a pseudo-terminal, which clients open as they would
  /dev/ttyACM0 (output nobody reads is dropped, as a USB port without a host drops it);
- answers the bench rig on its stdin/stdout, one JSON object a line: what a person mounts and
  hooks (the reference sensor, the gauge, a load, a lifted wiper) goes straight to the actuator,
  and the gauge's display is read from it.

Requests (stdin) and answers (stdout):
  {"op": "rig", "rig": {...bench_rig.apply's dict}}  -> {"ok": true}
  {"op": "gauge"}  -> {"force_n": N, "t_s": emulated seconds}
  {"op": "state"}  -> {"t_s", "block_mm", "nut_mm", "deformation_mm", "volts", "gauge_tension_n",
                       "instructions", "cycles", "usb_configured", "dropped_bytes"}
  {"op": "quit"}
An "id" in a request comes back in its answer. The first line it prints is {"path": "/dev/pts/N",
"pid": ...} once the chip runs.
"""

import json
import os
import select
import struct
import subprocess
import sys
import time

from boards.sim import bench_rig
from boards.sim.actuator import CHANNELS, Actuator
from boards.sim.harness import Harness

SLICE_NS = 500_000  # the actuator's step in emulated time: half a period of the 1 kHz loop
ADC_INPUTS = 5  # GPIO26..29, the temperature sensor
ADC_GPIO = (26, 27, 28, 29)
MIN_CODES = 8  # codes sent per wired input per slice, at least; twice the last slice's reads
VSYS_CODE = 2068  # GPIO29 on a Pico reads VSYS/3 (5 V) of 3.3 V
TEMPERATURE_CODE = 876  # the sensor's 0.706 V at 27 C
AHEAD_NS = 20_000_000  # emulated time may lead the wall clock by this much, no more


def _write_all(fd, data):
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _pty():
    import termios
    import tty

    master, slave = os.openpty()
    tty.setraw(slave)
    attrs = termios.tcgetattr(slave)
    attrs[3] &= ~termios.ECHO
    termios.tcsetattr(slave, termios.TCSANOW, attrs)
    os.set_blocking(master, False)
    return master, slave


class Plant:
    """The actuator and the wires to the chip's pins."""

    def __init__(self, board, actuator, seed):
        params = dict(actuator)
        params["adc_bits"] = board["adc_bits"]
        self.world = Actuator(params, seed)
        self.harness = Harness(board, actuator)
        self.inputs = []  # per ADC input: actuator channel index and complement mask, or a constant code
        full = self.world.full_code
        for n in range(ADC_INPUTS):
            gpio = ADC_GPIO[n] if n < len(ADC_GPIO) else None
            if gpio in self.harness.adc:
                channel, reversed_track = self.harness.adc[gpio]
                self.inputs.append((CHANNELS.index(channel), full if reversed_track else 0))
            else:
                self.inputs.append((None, VSYS_CODE if gpio == 29 else TEMPERATURE_CODE))
        motor = board["motor_pins"]
        self.watched = sorted(set(motor.values()))
        self.rig_text = None

    def codes(self, input_index, n):
        """n noisy conversions of ADC input `input_index` at the actuator's present state."""
        index, flip = self.inputs[input_index]
        if index is None:
            return [flip] * n
        w = self.world
        shift = w._lshift
        return [(w.read_u16_index(index) >> shift) ^ flip for _ in range(n)]

    def advance(self, dt_s, levels):
        level = dict(zip(self.watched, levels))
        self.world.set_motor_voltage(self.harness.motor_volts(level.__getitem__))
        self.world.advance(dt_s)


class Bench:
    def __init__(self, config):
        from host.link.emulated_pico.node import node_command

        self.config = config
        board = config["board"]
        self.plant = Plant(board, config["actuator"], config.get("seed", 0))
        if config.get("rig"):
            bench_rig.apply(self.plant.world, config["rig"])
        self.master, self.slave = _pty()
        self.path = os.ttyname(self.slave)
        emulator = {"uf2": config["uf2"], "fs_image": config.get("fs_image"), "fs_offset": config["fs_offset"],
                    "fs_size": config["fs_size"], "watch_pins": self.plant.watched,
                    "bootsel_pullup": bool(config.get("bootsel_pullup"))}
        self.node = subprocess.Popen(node_command() + [json.dumps(emulator)], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=sys.stderr, bufsize=0)
        self.to_node = self.node.stdin.fileno()
        self.from_node = self.node.stdout.fileno()
        self.batch = [MIN_CODES] * ADC_INPUTS
        self.t_ns = 0.0
        self.instructions = 0.0
        self.cycles = 0.0
        self.configured = False
        self.wall0 = None
        self.dropped = 0
        self.client_absent = False
        self.to_device = b""
        self.quit = False
        self.control_text = b""
        # $LSEA_PICO_TRACE: every byte each way over the USB serial, with emulated and wall time
        trace = os.environ.get("LSEA_PICO_TRACE")
        self.trace = open(trace, "a") if trace else None
        self.t_ns = 0.0

    def _trace(self, direction, data):
        if self.trace is not None:
            self.trace.write("%.6f %.3f %s %r\n" % (self.t_ns / 1e9, time.monotonic() - (self.wall0 or 0), direction, data))
            self.trace.flush()

    # -- the chip ---------------------------------------------------------------------------
    def _read_exactly(self, n):
        out = bytearray()
        while len(out) < n:
            chunk = os.read(self.from_node, n - len(out))
            if not chunk:
                raise EOFError("the emulator ended")
            out += chunk
        return bytes(out)

    def _report(self):
        (length,) = struct.unpack("<I", self._read_exactly(4))
        msg = self._read_exactly(length)
        k = len(self.plant.watched)
        head = struct.Struct("<Bddd B %dH %dd" % (ADC_INPUTS, k))
        fields = head.unpack_from(msg)
        t_ns, self.instructions, self.cycles, flags = fields[1:5]
        reads = fields[5:5 + ADC_INPUTS]
        levels = fields[5 + ADC_INPUTS:]
        self.configured = bool(flags & 1)
        return t_ns, reads, levels, msg[head.size:]

    def _request(self, slice_ns, command=0):
        parts = [struct.pack("<IB", int(slice_ns), command)]
        for i in range(ADC_INPUTS):
            n = self.batch[i]
            codes = self.plant.codes(i, n)
            parts.append(struct.pack("<H%dH" % n, n, *codes))
        parts.append(self.to_device)
        self.to_device = b""
        payload = b"".join(parts)
        _write_all(self.to_node, struct.pack("<I", len(payload)) + payload)

    # -- the USB host side ----------------------------------------------------------------------
    def _to_client(self, data):
        view = memoryview(data)
        deadline = None
        while view:
            try:
                view = view[os.write(self.master, view):]
                continue
            except BlockingIOError:
                pass
            except OSError:
                break
            if self.client_absent:
                break
            now = time.monotonic()
            deadline = deadline or now + 0.1
            if now >= deadline:
                self.client_absent = True
                break
            readable, _, _ = select.select([self.master], [self.master], [], deadline - now)
            if readable:
                self._from_client()  # a client blocked writing to us would never read
        self.dropped += len(view)

    def _from_client(self):
        try:
            data = os.read(self.master, 4096)
        except (BlockingIOError, OSError):
            return
        if data:
            self.client_absent = False
            self.to_device += data
            self._trace("->", data)

    # -- the rig ------------------------------------------------------------------------------
    def _control(self, req):
        op = req.get("op")
        w = self.plant.world
        if op == "rig":
            bench_rig.apply(w, req["rig"])
            return {"ok": True}
        if op == "gauge":
            if w.load_kind != "gauge":
                return {"error": "the virtual rig shows no gauge reading (is the gauge hooked?)"}
            return {"force_n": bench_rig.gauge_reading_n(w), "t_s": w.time_s}
        if op == "state":
            return {"t_s": w.time_s, "block_mm": w.block_mm, "nut_mm": w.nut_mm, "deformation_mm": w.deformation_mm,
                    "volts": w.volts, "gauge_tension_n": w.gauge_tension_n, "instructions": self.instructions,
                    "cycles": self.cycles, "usb_configured": self.configured, "dropped_bytes": self.dropped}
        if op == "quit":
            self.quit = True
            return {"ok": True}
        return {"error": "unknown op %r" % (op,)}

    def _serve_control(self, ready):
        if 0 not in ready:
            return
        data = os.read(0, 65536)
        if not data:
            self.quit = True  # the host that started this bench is gone
            return
        self.control_text += data
        while b"\n" in self.control_text:
            line, self.control_text = self.control_text.split(b"\n", 1)
            try:
                req = json.loads(line)
                answer = self._control(req)
            except (ValueError, KeyError, TypeError) as exc:
                req, answer = {}, {"error": str(exc)}
            if isinstance(req, dict) and "id" in req:
                answer["id"] = req["id"]
            _write_all(1, (json.dumps(answer) + "\n").encode())

    # -- the loop -------------------------------------------------------------------------------
    def run(self):
        t_ns, reads, levels, out = self._report()
        _write_all(1, (json.dumps({"path": self.path, "pid": os.getpid()}) + "\n").encode())
        self.wall0 = time.monotonic()
        slice_ns = SLICE_NS
        fds = [self.master, 0]
        while not self.quit:
            self._request(slice_ns)
            t_new, reads, levels, out = self._report()
            self.plant.advance((t_new - t_ns) / 1e9, levels)
            t_ns = self.t_ns = t_new
            for i, n in enumerate(reads):
                self.batch[i] = max(MIN_CODES, 2 * n) if self.plant.inputs[i][0] is not None else 1
            if out:
                self._trace("<-", out)
                self._to_client(out)
            # Never ahead of the wall clock by more than AHEAD_NS: wait for it, serving the host
            ahead = t_ns - (time.monotonic() - self.wall0) * 1e9 - AHEAD_NS
            ready, _, _ = select.select(fds, [], [], max(0.0, ahead / 1e9))
            if self.master in ready:
                self._from_client()
            self._serve_control(ready)
        self._request(0, command=1)

    def close(self):
        try:
            self.node.stdin.close()  # the chip's end of the protocol: Node ends at its EOF
        except OSError:
            pass
        try:
            self.node.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.node.kill()
        if self.trace is not None:
            self.trace.close()
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    config = json.loads(open(argv[0]).read() if not argv[0].startswith("{") else argv[0])
    bench = Bench(config)
    try:
        bench.run()
    except (EOFError, BrokenPipeError) as exc:
        print("emulated Pico: %s" % exc, file=sys.stderr)
    except KeyboardInterrupt:
        pass
    finally:
        bench.close()


if __name__ == "__main__":
    main()
