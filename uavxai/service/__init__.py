"""Service-point and power planners: D3QN, DQN, random search and the exhaustive grid."""
