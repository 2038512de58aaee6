"""Service-point and power planners (D3QN, DQN, random search, the exhaustive grid), their
placement environment (service_env) and the orbit-averaged rates (orbit_rate)."""
