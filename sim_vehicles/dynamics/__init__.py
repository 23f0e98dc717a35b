"""Physics backends of the SITL vehicles."""
