"""MAVLink side of the co-simulation, installed as `uavxai.bridges`."""
