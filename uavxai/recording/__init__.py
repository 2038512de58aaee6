"""rerun recordings of runs: 3-D scene, search trees, explanations, metrics."""
