"""One SITL vehicle's autopilot: its state and flight modes (vehicle, modes, navigation: LOITER and RTL), the
setpoints it flies and how GUIDED slews to them (setpoints, guided_slew), its parameters (params), its clock and the
world's events (clock, events), and what its telemetry reports (telemetry). Below the protocol; above the link."""
