#!/bin/bash
# The identity check's runs (fixed seeds) of the tree TREE into OUT (issue 31, speed33):
#   outputs.sh TREE OUT; then compare_outputs.py BASE_OUT NEW_OUT and compare_rrd.sh BASE_OUT NEW_OUT
TREE=$1; OUT=$2
export PYTHONPATH=$TREE JSBSIM_DEBUG=0 RAY_USAGE_STATS_ENABLED=0 MPLBACKEND=Agg
U=${UAVXAI:-/work/main/.venv/bin/uavxai}
cd "$TREE" || exit 1
rm -rf "$OUT"; mkdir -p "$OUT"
nice -n 5 $U run scenarios/manoeuvring.yaml --seed 11 --out "$OUT/run-manoeuvring" > "$OUT/run-manoeuvring.log" 2>&1
nice -n 5 $U run scenarios/head_on.yaml --seed 5 --out "$OUT/run-head_on" > "$OUT/run-head_on.log" 2>&1
nice -n 5 $U run scenarios/crossing_swarm.yaml --seed 3 --out "$OUT/run-crossing_swarm" > "$OUT/run-crossing_swarm.log" 2>&1
nice -n 5 $U evaluate scenarios/manoeuvring.yaml --methods mcts_vertical --intruders 20 --dynamics jsbsim --episodes 2 --workers 1 --seed 40 --out "$OUT/eval-jsbsim" > "$OUT/eval-jsbsim.log" 2>&1
nice -n 5 $U evaluate scenarios/manoeuvring.yaml --methods mcts,mcts_vertical --intruders 20 --dynamics kinematic --episodes 2 --workers 1 --seed 40 --out "$OUT/eval-kinematic" > "$OUT/eval-kinematic.log" 2>&1
