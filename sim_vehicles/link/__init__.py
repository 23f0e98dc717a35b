"""The vehicles' links: the UDP endpoint (mavlink_io), the pseudo-terminal serial line (serial_port), MAVLink 2
signing (signing) and the model of GPS and datalink (link_model). Imports nothing else of sim_vehicles."""
