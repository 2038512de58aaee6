"""The learning wing: every trainer of uavxai's learned planners, on Gymnasium envs.

- :mod:`uavxai.learning.env`: the episode engine as a Gymnasium env (what the avoidance
  networks see, the paper's eq 14 reward, start and goal through ``reset(options)``);
- :mod:`uavxai.learning.train`: DQN / Safe-DQN on it (`uavxai train --stage avoidance`);
- :mod:`uavxai.learning.branching`, :mod:`uavxai.learning.service`: the service point's D3QN /
  DQN on one layout (`--stage service`); :mod:`uavxai.learning.universal`: the universal
  placement network (`--stage universal`);
- :mod:`uavxai.learning.replay`: the one replay buffer;
  :mod:`uavxai.learning.checkpoint`: the one checkpoint reader and writer, which inference
  (:mod:`uavxai.avoidance.learned`, :mod:`uavxai.service`) reads models with, so it sits low
  in the layers (docs/architecture.md). This package imports nothing itself.
"""
