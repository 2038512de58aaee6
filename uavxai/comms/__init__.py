"""Air-to-ground channel model (paper eqs 1-7) and the service-point environment."""
