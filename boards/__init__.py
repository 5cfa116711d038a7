"""Board descriptions (pin maps, ADC and PWM facts) and the simulated actuator board."""
