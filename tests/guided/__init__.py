"""The guided calibration, bringup, the experiments' math and report, and gain tuning."""
