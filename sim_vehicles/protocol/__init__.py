"""How a vehicle speaks MAVLink: its link both ways, telemetry streams and lockstep credit (vehicle_link), which
streams when (streams), and what clients send it (commands). Above the autopilot and the link."""
