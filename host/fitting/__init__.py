"""The fitting math: calibration curves (BCM, polynomials, splines, tables), their selection, noise
floors and sweeps, and the fits of the bench calibrations. Pure functions over arrays; no board."""
