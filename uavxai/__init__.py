"""uavxai: interpretable, collision-safe UAV-assisted communication in a JSBSim co-simulation."""

__version__ = "0.1.0"

# The words of every decision come from uavxai.xai, a layer above the planners, which
# registers itself as the narrator; importing it here makes `decision.explanation` work for
# library users of uavxai.avoidance (README, "Using the planner in another simulator") without
# the planners importing it.
from uavxai.xai import explain as _explain  # noqa: E402, F401
