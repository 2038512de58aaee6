"""JSBSim aircraft data (XML), installed as `uavxai.aircraft`; see uavxai.paths.aircraft_dir()."""
