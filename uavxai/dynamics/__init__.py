"""Flight dynamics: the multi-aircraft JSBSim world and the local ENU frame."""
