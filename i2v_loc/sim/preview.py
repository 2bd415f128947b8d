"""Bird's-eye-view preview of one recording frame: points coloured by sensor, true boxes with
headings, sensor positions."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from i2v_loc.geometry import box_corners, extrinsics_matrix, transform_points
from i2v_loc.params import load_params
from i2v_loc.recording import Recording


def _box_outline(center, length_m, width_m, yaw_deg) -> np.ndarray:
    """The closed ground-plane outline (5, 2) of a box."""
    corners = box_corners(center, length_m, width_m, math.radians(yaw_deg))
    return np.vstack([corners, corners[:1]])


def render_preview(recording: Recording, out: str | Path, frame: int | None = None, z_min_m: float = 0.2) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if frame is None:
        frame = len(recording) // 2
    params = load_params(recording.sensors_file)
    data = recording.frame(frame)
    gt = recording.ground_truth()[frame]
    fig, ax = plt.subplots(figsize=(11, 8), dpi=110)
    colours = plt.get_cmap("tab10")
    grade = math.tan(math.radians(recording.meta.get("slope_deg", 0.0)))  # the ground rises along +x
    for i, (name, scan) in enumerate(data.scans.items()):
        pose = extrinsics_matrix(params.sensor(name).extrinsics)
        pts = transform_points(pose, scan.points.astype(np.float64))
        above = pts[:, 2] - grade * pts[:, 0] > z_min_m  # leave the ground out so objects stand out
        ax.scatter(
            pts[above, 0],
            pts[above, 1],
            s=0.3,
            color=colours(i),
            label=f"{name} ({len(scan.points)} pts)",
            rasterized=True,
            zorder=3,
        )
        ax.scatter(pts[~above, 0][::4], pts[~above, 1][::4], s=0.1, color=colours(i), alpha=0.15, rasterized=True)
        ax.plot(pose[0, 3], pose[1, 3], marker="^", color=colours(i), markersize=11, markeredgecolor="black")
        ax.annotate(name, pose[:2, 3], textcoords="offset points", xytext=(6, 6), fontsize=10, weight="bold")
    for v in gt["vehicles"]:
        for unit, colour in (("truck", "red"), ("trailer", "blue")):
            u = v[unit]
            outline = _box_outline(u["center"], u["dimensions"][0], u["dimensions"][1], u["yaw_deg"])
            ax.plot(outline[:, 0], outline[:, 1], color=colour, lw=1.0, ls="--", zorder=2)
            a = math.radians(u["yaw_deg"])
            ax.arrow(
                u["center"][0], u["center"][1], 2.0 * math.cos(a), 2.0 * math.sin(a), width=0.12, color=colour, zorder=4
            )
        ax.annotate(
            f"{v['vehicle']} {v['maneuver']}\nhitch {v['hitch_deg']:.1f}°",
            v["trailer"]["center"][:2],
            textcoords="offset points",
            xytext=(10, -25),
            fontsize=9,
            color="navy",
        )
    for d in gt.get("distractors", []):
        outline = _box_outline(d["center"], d["dimensions"][0], d["dimensions"][1], d["yaw_deg"])
        ax.plot(outline[:, 0], outline[:, 1], color="darkorange", lw=1.2)
    ax.set_xlim(-35, 35)
    ax.set_ylim(-20, 32)
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    ax.set_xlabel("x east [m]")
    ax.set_ylabel("y north [m]")
    ax.set_title(
        f"{recording.path.name}: frame {frame}, t = {gt['stamp_s']:.1f} s (points {z_min_m} m above the ground bold)"
    )
    ax.legend(loc="upper right", markerscale=15, fontsize=8)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, bbox_inches="tight")
    plt.close(fig)
    return out
