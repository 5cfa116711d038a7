"""Host frame decoder throughput: frames/s through host.link.frames.FrameDecoder (target >= 200,000).

    .venv/bin/python bench/bench_decode.py [--frames N] [--records K]

Builds N telemetry frames of K records (as the firmware sends them) plus some REPL noise, then
feeds them to the decoder in 4 KiB chunks (what a serial read returns) and reports frames/s,
records/s and MB/s. Every frame must come out, or the figure is not printed.
"""

import argparse
import random
import struct
import sys
import time

from firmware import protocol as P
from host.link.frames import FrameDecoder


def build_stream(n_frames, records, noise_every=1000):
    rng = random.Random(1)
    parts = []
    for i in range(n_frames):
        rec = [rng.randint(-(2**30), 2**30) for _ in range(records * P.RECORD_WORDS)]
        payload = struct.pack("<i%di" % len(rec), 0, *rec)
        parts.append(P.encode_frame(P.T_TELEMETRY, i & P.SEQ_MASK, payload, count=records))
        if i % noise_every == 0:
            parts.append(b"MicroPython banner >>> \r\n")
    return b"".join(parts)


def run(n_frames, records, chunk=4096, repeats=3):
    stream = build_stream(n_frames, records)
    best = None
    for _ in range(repeats):
        dec = FrameDecoder()
        got = 0
        t0 = time.perf_counter()
        for i in range(0, len(stream), chunk):
            got += len(dec.feed(stream[i : i + chunk]))
        dt = time.perf_counter() - t0
        if got != n_frames or dec.lost_frames or dec.crc_errors:
            raise SystemExit("decoder lost frames: %d of %d" % (got, n_frames))
        best = dt if best is None else min(best, dt)
    return {
        "frames_per_s": n_frames / best,
        "records_per_s": n_frames * records / best,
        "mb_per_s": len(stream) / best / 1e6,
        "seconds": best,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200000)
    ap.add_argument("--records", type=int, nargs="*", default=[1, P.TELEMETRY_BATCH])
    args = ap.parse_args()
    print("python %s, %d frames per run, best of 3" % (sys.version.split()[0], args.frames))
    for k in args.records:
        r = run(args.frames, k)
        print("records/frame %2d: %9.0f frames/s  %10.0f records/s  %6.1f MB/s" % (k, r["frames_per_s"], r["records_per_s"], r["mb_per_s"]))


if __name__ == "__main__":
    main()
