"""Plot a telemetry CSV (host log): positions, deformation, force, duty and targets against time.

A run logged from a board without a calibration has all-zero positions, deformation and force
(the firmware only sends raw ADC codes then): plot() says so through `warn` and draws the raw
codes (pots, reference sensor) in their place instead of flat zeros."""

import numpy as np

from host.link.telemetry_log import CALIBRATED_FIELDS, load, uncalibrated

MODE_TARGET_UNITS = {1: "duty", 2: "um", 3: "mN"}  # controller mode numbers: open_loop, position, force


def plot(csv_path, out_path, warn=None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = load(csv_path)
    if len(d["t_us"]) == 0:
        raise ValueError("no samples in %s" % csv_path)
    t = np.unwrap(d["t_us"].astype(float), period=2.0**30) / 1e6
    t -= t[0]
    raw = uncalibrated(d)
    if raw and warn:
        warn("%s: %s are all 0 (logged from a board without calibration?): plotting the raw ADC codes "
             "(raw1, raw2, raw_ref) instead" % (csv_path, ", ".join(CALIBRATED_FIELDS)))
    fig, ax = plt.subplots(4, 1, sharex=True, figsize=(10, 10))
    if raw:
        ax[0].plot(t, d["raw1"], label="raw1 (pot 1, nut)")
        ax[0].plot(t, d["raw2"], label="raw2 (pot 2, block)")
        ax[0].set_ylabel("pot ADC code")
        ax[1].plot(t, d["raw_ref"], label="raw_ref (reference sensor)")
        ax[1].set_ylabel("reference ADC code")
        ax[2].plot(t, d["raw1"] - d["raw2"], label="raw1 - raw2 (no calibration: no deformation or force)")
        ax[2].set_ylabel("code difference")
    else:
        ax[0].plot(t, d["d1_um"] / 1000, label="D1* nut")
        ax[0].plot(t, d["d2_um"] / 1000, label="D2 block")
        pos = d["mode"] == 2
        if pos.any():
            ax[0].plot(t[pos], d["target"][pos] / 1000, "k--", label="position target")
        ax[0].set_ylabel("position, mm")
        ax[1].plot(t, d["defl_um"] / 1000, label="deformation")
        ax[1].set_ylabel("deformation, mm")
        ax[2].plot(t, d["force_mN"] / 1000, label="F0(d)")
        force = d["mode"] == 3
        if force.any():
            ax[2].plot(t[force], d["target"][force] / 1000, "k--", label="force target")
        ax[2].set_ylabel("force, N")
    ax[3].plot(t, d["duty"], label="duty")
    ol = d["mode"] == 1
    if ol.any():
        ax[3].plot(t[ol], d["target"][ol], "k--", label="duty target")
    ax[3].set_ylabel("duty")
    ax[3].set_xlabel("time, s")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(loc="upper right", fontsize=8)
    fig.suptitle(str(csv_path))
    fig.tight_layout()
    fig.savefig(out_path, dpi=100)
    plt.close(fig)
    return out_path
