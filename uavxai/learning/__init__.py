"""Learning the avoidance baselines: the episode engine as a Gymnasium environment
(:mod:`uavxai.learning.env`) and the DQN / Safe-DQN training on it
(:mod:`uavxai.learning.train`). Above :mod:`uavxai.sim`, whose engine it flies; the trained
networks are used by :mod:`uavxai.avoidance.learned`."""
