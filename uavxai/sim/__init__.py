"""The episode engine: one loop flies every episode, whatever the dynamics and command path.

``clock`` (integrator ticks), ``judge`` (outcomes), ``command`` (MAVLink bytes through the
bridge, or direct), ``observers`` (files, recording, metrics, pacing, progress), ``episode``
(the phases decide -> advance -> judge -> finish), ``run`` (`uavxai run`).
"""
