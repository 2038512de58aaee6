"""rerun recordings of runs: 3-D scene, search trees, explanations, metrics."""

from uavxai.recording.blueprint import default_blueprint
from uavxai.recording.recorder import RunRecorder

__all__ = ["RunRecorder", "default_blueprint"]
