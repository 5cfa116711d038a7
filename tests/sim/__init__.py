"""The simulated actuator (boards/sim) on both interpreters, bit for bit, and the firmware running
against it."""
