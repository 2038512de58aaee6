"""uavxai: interpretable, collision-safe UAV-assisted communication in a JSBSim co-simulation."""

__version__ = "0.1.0"
