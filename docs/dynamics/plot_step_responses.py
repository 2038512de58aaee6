"""Draw the step responses of the uav_fw autopilot, flown on the real JSBSim model, to PNGs
next to this script (the same manoeuvres and measures the tests use).

    .venv/bin/python docs/dynamics/plot_step_responses.py [--out DIR]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from uavxai.avoidance.types import PlannerConfig  # noqa: E402
from uavxai.sim import manoeuvres as m  # noqa: E402

SPEEDS = (12.0, 20.0, 30.0)
COLOURS = {12.0: "tab:orange", 20.0: "tab:blue", 30.0: "tab:green"}


def bank_step(out: Path) -> None:
    cmd = math.radians(20)
    limit = PlannerConfig().roll_rate_limit_deg_s
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    for v in SPEEDS:
        rec = m.fly(m.flight_test_scenario(v), duration_s=6, bank_cmd_rad=cmd)
        res = m.bank_step_measures(rec, cmd)
        label = (
            f"{v:g} m/s: 95 % at {res['rise_95_s']:.2f} s, overshoot {100 * res['overshoot']:.1f} %"
        )
        ax1.plot(rec.t, np.degrees(rec.bank), color=COLOURS[v], label=label)
        ax2.plot(rec.t, np.degrees(rec.bank_rate), color=COLOURS[v])
    ax1.axhline(20, color="k", ls="--", lw=0.8, label="command 20 deg")
    ax1.axvline(3, color="r", ls=":", lw=0.8, label="3 s requirement")
    ax1.set_ylabel("bank (deg)")
    ax1.legend(fontsize=8)
    ax2.axhline(limit, color="r", ls=":", lw=0.8, label=f"roll-rate limit {limit:g} deg/s")
    ax2.set_ylabel("roll rate (deg/s)")
    ax2.set_xlabel("time after command (s)")
    ax2.legend(fontsize=8)
    fig.suptitle("Bank-angle hold: 20 deg step")
    _save(fig, out / "bank_step.png")


def sustained_turn(out: Path) -> None:
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    for v in SPEEDS:
        rec = m.fly(m.flight_test_scenario(v), duration_s=60, bank_cmd_rad=math.radians(30))
        res = m.turn_measures(rec)
        rate = np.gradient(rec.heading, rec.t)
        ax1.plot(rec.t, rec.h - rec.h[0], color=COLOURS[v], label=f"{v:g} m/s")
        ax2.plot(
            rec.t,
            np.degrees(rate),
            color=COLOURS[v],
            label=f"{v:g} m/s: {100 * res['turn_rate_error']:+.2f} % vs g tan(phi)/V",
        )
        ax2.axhline(math.degrees(res["expected_rad_s"]), color=COLOURS[v], ls="--", lw=0.8)
    ax1.axhspan(-10, 10, color="0.9", label="+-10 m requirement")
    ax1.set_ylabel("height change (m)")
    ax1.legend(fontsize=8)
    ax2.set_ylabel("turn rate (deg/s)")
    ax2.set_xlabel("time after 30 deg bank command (s)")
    ax2.legend(fontsize=8)
    fig.suptitle("Sustained 30 deg turn: altitude hold and coordination (dashed: g tan(phi)/V)")
    _save(fig, out / "turn_30deg.png")


def speed_tracking(out: Path) -> None:
    fig, ax = plt.subplots(figsize=(7, 4))
    for start, accel, colour in ((16.0, 1.0, "tab:blue"), (28.0, -1.0, "tab:red")):
        rec = m.fly(m.flight_test_scenario(start), duration_s=10, accel_cmd_mps2=accel)
        error = m.speed_measures(rec)["speed_error_mps"]
        label = f"{accel:+g} m/s^2 from {start:g} m/s: max error {error:.2f} m/s"
        ax.plot(rec.t, rec.speed_target, color=colour, ls="--", lw=0.9)
        ax.plot(rec.t, rec.airspeed, color=colour, label=label)
    ax.set_xlabel("time after command (s)")
    ax.set_ylabel("airspeed (m/s); dashed: speed target")
    ax.legend(fontsize=8)
    ax.set_title("Airspeed hold following an acceleration command")
    _save(fig, out / "speed_accel.png")


def heading_hold(out: Path) -> None:
    fig, ax = plt.subplots(figsize=(7, 4))
    for v in SPEEDS:
        rec = m.fly(m.flight_test_scenario(v), duration_s=60, bank_cmd_rad=0.0)
        drift = math.degrees(m.heading_measures(rec)["heading_drift_rad"])
        ax.plot(
            rec.t,
            np.degrees(rec.heading - rec.heading[0]),
            color=COLOURS[v],
            label=f"{v:g} m/s: max {drift:.2f} deg",
        )
    ax.axhspan(-2, 2, color="0.9", label="+-2 deg requirement")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("heading change (deg)")
    ax.set_title("Wings level for 60 s (the slope is the Coriolis turn at 34 deg N)")
    ax.legend(fontsize=8)
    _save(fig, out / "heading_hold.png")


def height_change(out: Path) -> None:
    fig, ax = plt.subplots(figsize=(7, 4))
    sc = m.flight_test_scenario(20.0)
    for dh, colour in ((50.0, "tab:blue"), (-50.0, "tab:red")):
        target = sc.ownship.start.h + dh
        rec = m.fly(sc, duration_s=40, alt_target_m=target)
        res = m.climb_measures(rec, target)
        rate = res["peak_climb_rate_mps"] if dh > 0 else res["peak_sink_rate_mps"]
        ax.plot(rec.t, rec.h, color=colour, label=f"{dh:+g} m: peak {rate:.2f} m/s")
        ax.axhline(target, color=colour, ls="--", lw=0.8)
    ax.set_xlabel("time after command (s)")
    ax.set_ylabel("height (m)")
    ax.set_title("Altitude hold: height steps at 20 m/s (climb-rate limit 2.5 m/s)")
    ax.legend(fontsize=8)
    _save(fig, out / "height_step.png")


def _save(fig: plt.Figure, path: Path) -> None:
    for ax in fig.axes:
        ax.grid(True, lw=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent)
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for draw in (bank_step, sustained_turn, speed_tracking, heading_hold, height_change):
        draw(args.out)


if __name__ == "__main__":
    main()
