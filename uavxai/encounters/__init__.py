"""Statistical airspace encounters: the MIT LL uncorrelated encounter model (docs/encounters.md).

``model`` reads a parameter file and samples its Bayesian networks, ``tracks`` turns a sample
into a trajectory in metres, ``pairing`` places that trajectory against the ownship as an
importance-weighted encounter.
"""

from uavxai.encounters.model import (
    EncounterModel,
    InitialSample,
    Network,
    Transitions,
    default_model,
    load_model,
    parse_model,
)
from uavxai.encounters.pairing import (
    NMAC_HMD,
    NMAC_VMD,
    Encounter,
    EncounterConfig,
    OwnshipAtTCA,
    draw_miss_distances,
    sample_encounter,
    sample_encounters,
    straight_ownship,
)
from uavxai.encounters.tracks import Trajectory, is_flyable, sample2track, sample_track

__all__ = [
    "NMAC_HMD", "NMAC_VMD", "Encounter", "EncounterConfig", "EncounterModel", "InitialSample",
    "Network", "OwnshipAtTCA", "Trajectory", "Transitions", "default_model",
    "draw_miss_distances", "is_flyable", "load_model", "parse_model", "sample2track",
    "sample_encounter", "sample_encounters", "sample_track", "straight_ownship",
]
