"""Draws docs/figures/articulated_model.png: the hinged two-box model of the articulated estimator
(docs/pipeline.md), from the catalogue's MAN TGX at a 30 deg hitch angle.

    python scripts/figure_articulated_model.py [OUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from i2v_loc.geometry import box_corners  # noqa: E402
from i2v_loc.params import Params  # noqa: E402
from i2v_loc.stages.vehicle_model import VehicleModel  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "docs" / "figures" / "articulated_model.png"


def main(out: Path) -> None:
    model = VehicleModel.from_config("man_tgx", Params().vehicles["man_tgx"])
    yaw1, hitch = np.radians(20.0), np.radians(-30.0)
    axle = np.zeros(2)
    tractor_c, trailer_c = model.box_centers(0.0, 0.0, yaw1, hitch)
    kingpin = model.kingpin_xy(0.0, 0.0, yaw1)
    e1, e2 = np.array([np.cos(yaw1), np.sin(yaw1)]), np.array([np.cos(yaw1 + hitch), np.sin(yaw1 + hitch)])
    trailer_axle = kingpin - model.trailer_axle_m * e2
    fig, ax = plt.subplots(figsize=(10, 5.5))
    for c, yaw, box, name in (
        (tractor_c, yaw1, model.tractor, "tractor (cab) box"),
        (trailer_c, yaw1 + hitch, model.trailer, "trailer box"),
    ):
        p = box_corners(c, box.length_m, box.width_m, yaw)[[0, 1, 2, 3, 0]]
        ax.fill(p[:, 0], p[:, 1], alpha=0.15)
        ax.plot(p[:, 0], p[:, 1], lw=1.5, label=name)
    ax.plot(*axle, "ko")
    ax.annotate("P: rear axle (x, y)", axle, (axle[0] - 1.0, axle[1] + 2.4), arrowprops={"arrowstyle": "->"})
    ax.plot(*kingpin, "rs")
    ax.annotate(
        "K: kingpin, M behind P", kingpin, (kingpin[0] - 5.0, kingpin[1] + 3.2), arrowprops={"arrowstyle": "->"}
    )
    ax.plot(*trailer_axle, "k^")
    ax.annotate(
        "trailer axle, L2 behind K",
        trailer_axle,
        (trailer_axle[0] - 2.0, trailer_axle[1] - 3.0),
        arrowprops={"arrowstyle": "->"},
    )
    ax.annotate("", axle + 4.0 * e1, axle, arrowprops={"arrowstyle": "->", "lw": 2})
    ax.text(*(axle + 4.2 * e1), "ψ1 (tractor yaw), v, κ", va="center")
    ax.annotate("", kingpin - 6.0 * e2, kingpin, arrowprops={"arrowstyle": "-", "ls": "--"})
    ax.annotate("", kingpin + 3.0 * e2, kingpin, arrowprops={"arrowstyle": "->", "lw": 2})
    ax.text(*(kingpin + 3.2 * e2 + [0.0, -0.6]), "ψ2 = ψ1 + γ", va="top")
    ax.text(
        -12.0,
        -8.5,
        "state [x, y, ψ1, v, κ, γ]; γ' = −(v sin γ + M v κ cos γ) / L2 − v κ\n"
        "measurement: the two boxes fitted to the points (faces, roof, undercarriage)",
        fontsize=9,
    )
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="upper left")
    ax.set_title("The hinged model: MAN TGX at γ = −30°")
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90, bbox_inches="tight")
    print(out)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
