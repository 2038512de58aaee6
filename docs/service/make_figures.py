"""Regenerate the figures of docs/service/README.md.

.venv/bin/python docs/service/make_figures.py            # objective_map.png (~1 min)
.venv/bin/uavxai train scenarios/demo.yaml --algo d3qn --out runs/train-demo
cp runs/train-demo/learning_curve.png docs/service/learning_curve_demo.png
.venv/bin/python benchmarks/studies/bench_service_seeds.py \
    --plot docs/service/d3qn_vs_dqn_shared.png
.venv/bin/python benchmarks/studies/bench_service_seeds.py --access ofdma \
    --plot docs/service/d3qn_vs_dqn_ofdma.png
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from uavxai.paths import scenarios_dir  # noqa: E402
from uavxai.scenario import load_scenario  # noqa: E402
from uavxai.service.grid import optimal_objective, solve_grid  # noqa: E402
from uavxai.service.service_env import ServiceEnv, naive_placement  # noqa: E402
from uavxai.service.stage import plan_service  # noqa: E402

HERE = Path(__file__).parent


def objective_map() -> None:
    demo = load_scenario(scenarios_dir() / "demo.yaml")
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.2), constrained_layout=True)
    for ax, access in zip(axes, ("shared", "ofdma"), strict=True):
        comms = demo.comms.model_copy(update={"access": access, "fading": "none"})
        sc = demo.model_copy(update={"comms": comms})
        env = ServiceEnv.from_scenario(sc)
        best = solve_grid(env.channel, env.space, env.power_levels)
        xs, ys, _ = env.space.axes()
        mesh = np.stack(np.meshgrid(xs, ys, [best.position[2]], indexing="ij"), -1)[:, :, 0]
        values = optimal_objective(
            env.channel, env.channel.mean_gain(mesh.reshape(-1, 3)), env.power_levels
        ).reshape(len(xs), len(ys))
        image = ax.imshow(
            (values / best.objective).T,
            origin="lower",
            extent=(xs[0], xs[-1], ys[0], ys[-1]),
            cmap="viridis",
        )
        fig.colorbar(image, ax=ax, shrink=0.8, label="objective / optimum (best power)")
        users = env.channel.users
        ax.scatter(users[:, 0], users[:, 1], c="white", edgecolors="k", s=40, label="users")
        d3qn = plan_service(sc, "d3qn")
        naive = naive_placement(env.space, users)
        marks = (  # drawn in this order: the optimum on top
            (naive, "s", "cyan", 220, "naive (centroid, 100 m)"),
            (d3qn.service_point, "X", "orange", 160, f"D3QN, h = {d3qn.service_point[2]:.0f} m"),
            (best.position, "*", "red", 200, f"grid optimum, h = {best.position[2]:.0f} m"),
        )
        for z, (point, marker, colour, size, label) in enumerate(marks):
            style = {"marker": marker, "c": colour, "edgecolors": "k", "s": size, "zorder": 3 + z}
            ax.scatter(*point[:2], label=label, **style)
        ax.set(
            xlabel="x [m]",
            ylabel="y [m]",
            title=f"{access}: D3QN {d3qn.objective / best.objective:.3f}, naive "
            f"{env.naive_objective / best.objective:.3f} of the optimum",
        )
        ax.legend(loc="lower left", fontsize=8)
    fig.suptitle(
        f"Demo layout (K = {demo.comms.users.k}, {demo.comms.environment}, fading-free): "
        "best objective at the optimum's altitude"
    )
    fig.savefig(HERE / "objective_map.png", dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    objective_map()
