"""State estimation: the Kalman filter of a vehicle's horizontal state (filterpy) and the motion model it predicts
with. Imports nothing else of ``mavlink_bridge``.
"""
