"""``run.png``: a quick look at a run without the rerun viewer (README "What a run produces").

One figure of four panels, from what the episode flew, once per decision period: the track
seen from above with the intruders' tracks, the users and the service point; the separation
to the nearest intruder against d_min; the sum rate at the ownship's position (and, in a
mission, the rate delivered while serving); the battery's state of charge (a world whose
aircraft report power: JSBSim) or else the airspeed."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from uavxai.dynamics.state import TrafficState, is_member
from uavxai.outputs import write_output
from uavxai.sim.episode import DecisionEvent, Episode, Observer
from uavxai.sim.steps import Energy

PLOT = "run.png"


class QuickLook(Observer):
    """Collects the flight once per decision period and draws ``run.png`` at its end."""

    def __init__(self, path: Path, channel, power_w, energy: Energy, d_min_m: float) -> None:
        self.path = path
        self.channel, self.power_w = channel, np.asarray(power_w, dtype=float)
        self.energy = energy  # the Energy step: its battery, where the world has one
        self.d_min_m = d_min_m
        self.t: list[float] = []
        self.own: list[np.ndarray] = []
        self.others: dict[str, list[tuple[float, float]]] = {}  # intruder id -> (x, y)
        self.sep: list[float] = []
        self.delivered: list[float] = []  # nan: not serving
        self.soc: list[float] = []
        self.airspeed: list[float] = []
        self.users: np.ndarray | None = None
        self.own_id = "ownship"  # a fleet's member 0: "ownship-0"

    def on_start(self, ep: Episode) -> None:
        self.own_id = str(ep.state.ids[0])
        self._take(ep, ep.state)

    def on_period(self, ep: Episode, event: DecisionEvent, flown_min_m: float) -> None:
        self._take(ep, ep.state)

    def _take(self, ep: Episode, state: TrafficState) -> None:
        self.t.append(state.t)
        self.own.append(state.pos[0].copy())
        for i in range(1, state.n):
            self.others.setdefault(str(state.ids[i]), []).append(
                (float(state.pos[i, 0]), float(state.pos[i, 1]))
            )
        gaps = np.linalg.norm(state.pos[1:] - state.pos[0], axis=1)
        self.sep.append(float(gaps.min()) if len(gaps) else np.nan)
        serving = ep.mission is not None and ep.mission.serving
        rate = ep.sample_metrics.get("delivered_rate_bps") if serving else None
        self.delivered.append(np.nan if rate is None else float(rate))
        battery = self.energy.battery
        self.soc.append(np.nan if battery is None else float(battery.soc))
        self.airspeed.append(float(state.airspeed[0]))
        if "users_xyz" in ep.sample_metrics and self.users is None:
            self.users = np.asarray(ep.sample_metrics["users_xyz"], dtype=float).copy()

    def on_end(self, ep: Episode, summary: dict) -> None:
        if len(self.t) < 2:
            return
        goal = (ep.goal, "service point" if ep.mission is not None else "goal")
        write_output(self.path, self._draw(summary, goal))

    def _draw(self, summary: dict, goal: tuple) -> bytes:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        t, own = np.array(self.t), np.array(self.own)
        fig, axes = plt.subplots(2, 2, figsize=(11.0, 8.0), dpi=100)
        self._top_view(axes[0, 0], own, goal)
        if summary.get("fleet"):
            self._fleet_view(axes[0, 0], summary["fleet"])
        ax = axes[0, 1]
        ax.plot(t, self.sep, color="tab:blue", label="nearest intruder")
        ax.axhline(self.d_min_m, color="tab:red", linestyle="--", label=f"d_min {self.d_min_m:g} m")
        ax.set(xlabel="t (s)", ylabel="separation (m)", title="separation")
        ax.set_yscale("log")
        ax.legend(fontsize=8)
        ax = axes[1, 0]
        at_own = self.channel.sum_rate_bps(own, self.power_w) / 1e6
        ax.plot(t, at_own, color="tab:gray", label="sum rate at the ownship (service plan)")
        if np.isfinite(self.delivered).any():
            ax.plot(t, np.array(self.delivered) / 1e6, color="tab:green", label="delivered")
        ax.set(xlabel="t (s)", ylabel="Mbit/s", title="rates")
        ax.legend(fontsize=8)
        ax = axes[1, 1]
        if np.isfinite(self.soc).any():
            ax.plot(t, 100.0 * np.array(self.soc), color="tab:orange")
            ax.set(xlabel="t (s)", ylabel="state of charge (%)", title="battery")
        else:
            ax.plot(t, self.airspeed, color="tab:purple")
            ax.set(xlabel="t (s)", ylabel="airspeed (m/s)", title="airspeed")
        for a in axes.flat:
            a.grid(alpha=0.3)
        fig.suptitle(
            f"{summary.get('scenario')} seed {summary.get('seed')}: {summary.get('outcome')}, "
            f"min separation {summary.get('min_separation_m') or float('nan'):.0f} m"
        )
        fig.tight_layout()
        png = io.BytesIO()
        fig.savefig(png, format="png")
        plt.close(fig)
        return png.getvalue()

    def _top_view(self, ax, own: np.ndarray, goal: tuple) -> None:
        (gx, gy, _), where = goal
        intruders = [xy for i, xy in self.others.items() if not is_member(i)]
        for k, xy in enumerate(intruders):
            xy_a = np.array(xy)
            ax.plot(*xy_a.T, color="0.6", linewidth=0.5, alpha=0.6,
                    label="intruders" if k == 0 else None)  # fmt: skip
            ax.plot(*xy_a[-1], marker=".", color="0.4")
        ax.plot(own[:, 0], own[:, 1], color="tab:blue", linewidth=2.0, label=self.own_id)
        ax.plot(*own[0, :2], marker="o", color="tab:blue", label="start")
        ax.plot(gx, gy, marker="*", markersize=14, color="tab:red", label=where)
        if self.users is not None:
            ax.scatter(*self.users[:, :2].T, s=12, color="tab:green", label="users (start)")
        ax.set(xlabel="x east (m)", ylabel="y north (m)", title="track, top view")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=8, loc="best")

    def _fleet_view(self, ax, fleet: list[dict]) -> None:
        """A fleet's other members' tracks (member 0 is the ownship's), each in its colour,
        and every member's station (a cross in the member's colour)."""
        colors = ("tab:blue", "tab:orange", "tab:purple", "tab:brown", "tab:pink", "tab:olive",
                  "tab:cyan", "tab:gray")  # fmt: skip
        for n, entry in enumerate(fleet):
            color = colors[n % len(colors)]
            xy = np.array(self.others.get(entry["id"], []))
            if n > 0 and len(xy):
                ax.plot(*xy.T, color=color, linewidth=2.0, label=entry["id"])
                ax.plot(*xy[0], marker="o", color=color)
            ax.plot(*entry["station"][:2], marker="X", markersize=9, color=color,
                    label="stations" if n == 0 else None)  # fmt: skip
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=8, loc="best")
