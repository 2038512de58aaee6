"""Air-to-ground channel model (paper eqs 1-7; one UAV or a fleet), users' mobility and the
delivered service."""
