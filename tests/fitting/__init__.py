"""The fitting math: calibration curves, their selection, noise floors, sweeps, comparisons."""
