"""Companion-computer side: MAVLink telemetry in, filtered state and policy setpoints out."""
