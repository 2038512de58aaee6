"""Shipped scenario files, installed as `uavxai.scenarios`; see uavxai.paths.scenarios_dir()."""
