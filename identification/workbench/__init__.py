"""Model workbench: compare the actuator model with measurements, diagnose, add effects."""
