"""`uavxai evaluate`: Monte Carlo campaigns of the avoidance stage (the paper's figures).

A campaign flies every method against every intruder count for ``episodes`` seeded episodes.
Episode ``i`` uses seed ``scenario.seed + i`` for every method and every count, so methods
meet the same encounters (the same start, goal and intruders) and any row of
``episodes.csv`` can be flown again alone::

    python -c "from uavxai.campaign import rerun_row; print(rerun_row('scenarios/demo.yaml', \
'mcts', 20, 17))"

(scenario file, method, intruders, seed; ``dynamics='jsbsim'`` for a JSBSim row; and
``goal=(goal_x, goal_y, goal_h)`` of the row for a campaign run from Python on a scenario
without ``ownship.goal`` whose seed was changed; `uavxai evaluate --seed N` flies to the goal
of the file's own seed, so its rows need no goal given).

Every episode is flown by the one episode engine (:func:`uavxai.sim.build.fly`), on the
kinematic encounter model or in JSBSim, with the planner's commands going straight to the
autopilot (no MAVLink, no recording); the goal is the scenario's (``ownship.goal``, else the
service point of the campaign's scenario at the seed its file names, whatever ``--seed``
says), the same for every episode and as ``uavxai run``.

A scenario with an ``encounters`` section (docs/scenario.md "encounters") flies episode ``i`` as
encounter ``i`` (:func:`uavxai.sim.encounter.fly_encounter`, seed ``scenario.seed + i``, one
intruder: intruder counts are refused), weighted by its importance weight. Every campaign's
rows carry the detect-and-avoid record ``DAA_EPISODE_COLUMNS`` (weight 1 for random traffic)
and its results the weighted ``DAA_COLUMNS`` against ``none`` on the same seeds
(docs/daa-metrics.md).

A fleet (``fleet.size`` > 1, JSBSim only) flies episode ``i`` as the fleet mission `uavxai run
--seed` flies at ``scenario.seed + i``, by the run's own code, every member flying the method
(:mod:`uavxai.campaign.fleet`), into ``fleet_episodes.csv`` and ``fleet_results.csv`` instead
(docs/fleet.md, "Fleet campaigns").

Episodes run in this process (``workers=1``), in local worker processes (``workers>1``; the
``forkserver`` context, one torch thread each) or as Ray tasks (``ray_address``: ``local``
starts a private Ray instance on this machine, ``auto`` joins the cluster this machine belongs
to, ``ray://host:port`` a remote one whose nodes have uavxai installed). Wherever an episode
runs, its numbers are the same: only the ``decision_ms`` timings differ.

The package, one job a module (the layers, top first, are checked by import-linter):

- ``command``: `uavxai evaluate` (progress bar, journal, files of a finished or interrupted
  campaign, the terminal tables);
- ``runner``: the tasks flown in this process, a local worker pool or Ray; settings checked;
- ``merge``: `uavxai merge`, campaigns of one scenario pooled into one (one-ownship campaigns,
  or fleet campaigns with their run folders);
- ``episode``: one campaign episode flown on the engine -> its ``episodes.csv`` row;
- ``fleet``: a fleet campaign's episode (the fleet mission `uavxai run` flies, by its code)
  -> its ``fleet_episodes.csv`` row, its ``fleet_results.csv`` rows, both files written;
- ``statistics``: the ``results.csv`` rows (rates and intervals, risk ratios, DAA estimates);
- ``plots``: the figures drawn from the results rows (a fleet's: and its episodes' rows);
- ``files``: the columns of both files, a CSV written whole, a source's rows read and checked.
"""

from uavxai.campaign.command import daa_table, evaluate_command, results_table
from uavxai.campaign.episode import campaign_spec, rerun_row, run_campaign_episode
from uavxai.campaign.files import (
    DAA_COLUMNS,
    DAA_EPISODE_COLUMNS,
    DAA_RATES,
    EPISODE_COLUMNS,
    FLEET_EPISODE_COLUMNS,
    FLEET_EPISODES,
    FLEET_RESULT_COLUMNS,
    FLEET_RESULTS,
    FLIGHT_COLUMNS,
    FLIGHT_RESULTS,
    GOAL_COLUMNS,
    RESULT_COLUMNS,
    TIMING_COLUMNS,
    columns_of,
    write_csv,
)
from uavxai.campaign.fleet import run_fleet_episode, summarise_fleet, write_fleet_campaign
from uavxai.campaign.merge import is_fleet_campaign, merge_campaigns, read_merge
from uavxai.campaign.plots import plot_campaign, plot_fleet
from uavxai.campaign.runner import DYNAMICS, Task, campaign_tasks, run_campaign
from uavxai.campaign.statistics import summarise

__all__ = [
    "DAA_COLUMNS",
    "DAA_RATES",
    "DYNAMICS",
    "DAA_EPISODE_COLUMNS",
    "EPISODE_COLUMNS",
    "FLEET_EPISODES",
    "FLEET_EPISODE_COLUMNS",
    "FLEET_RESULTS",
    "FLEET_RESULT_COLUMNS",
    "FLIGHT_COLUMNS",
    "FLIGHT_RESULTS",
    "GOAL_COLUMNS",
    "RESULT_COLUMNS",
    "TIMING_COLUMNS",
    "Task",
    "campaign_spec",
    "campaign_tasks",
    "columns_of",
    "daa_table",
    "evaluate_command",
    "is_fleet_campaign",
    "merge_campaigns",
    "plot_campaign",
    "plot_fleet",
    "read_merge",
    "rerun_row",
    "results_table",
    "run_campaign",
    "run_campaign_episode",
    "run_fleet_episode",
    "summarise",
    "summarise_fleet",
    "write_csv",
    "write_fleet_campaign",
]
