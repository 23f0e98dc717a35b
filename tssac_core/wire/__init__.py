"""The wire: what the SITL vehicles and the MAVLink bridge both speak, so that neither parses frames itself.

``framing`` (frames scanned, packed and decoded: one scanner, packer and decoder for both ends) · ``signing``
(MAVLink 2 signatures verified before their timestamps count) · ``mission_events`` (the events' names, values and
texts) · ``geodetic`` (the flat-earth frame between the world's metres and MAVLink's degrees) · ``units`` (MAVLink's
units and NED axes and signs, and the action's scale) · ``truth_log_schema``
(the SITL world's truth log) · ``mission_reset`` (the next-mission lines of a persistent campaign) · ``lockstep``
(the grant of lockstep ticks a setpoint answers for). Standard library
only: neither pymavlink nor anything else of the project (``tests/test_architecture.py``).
"""
