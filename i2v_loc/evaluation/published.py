"""Figures published in the papers, shown beside ours for reference only.

The paper's (Justo et al., "An Infrastructure-based Localization Method for Articulated Vehicles")
come from real recordings of its test field with four OS1-32, labelled with labelCloud; dCAP's
(Mind the Hitch, Table 2) are camera-based trailer-pose estimates on the CARLA STT4AT benchmark.
Neither is comparable one-to-one with figures measured on our simulated recordings.
"""

from __future__ import annotations

PAPER_NAMES = {"twizy": "Renault Twizy", "man_tgx": "Man TGX", "volvo_fh": "Volvo FH"}

# Table 2: frames, truck (pos m, yaw deg), trailer (pos m, yaw deg), HAE RMSE deg, inference ms
TABLE2 = {
    "twizy": {"frames": 518, "truck": (0.19, 1.68), "trailer": (0.16, 1.65), "hitch": 1.96, "ms": 36},
    "man_tgx": {"frames": 906, "truck": (0.15, 1.57), "trailer": (0.13, 1.46), "hitch": 1.82, "ms": 45},
    "volvo_fh": {"frames": 713, "truck": (0.14, 1.30), "trailer": (0.12, 1.26), "hitch": 1.77, "ms": 39},
}

# Tables 3-5, in the paper's row order: (sensors, truck pos/yaw, trailer pos/yaw, HAE, ms)
_SUBSETS = [
    ("l1",),
    ("l2",),
    ("l3",),
    ("l4",),
    ("l1", "l2"),
    ("l1", "l3"),
    ("l1", "l4"),
    ("l2", "l3"),
    ("l2", "l4"),
    ("l3", "l4"),
    ("l1", "l2", "l3"),
    ("l1", "l2", "l4"),
    ("l1", "l3", "l4"),
    ("l2", "l3", "l4"),
    ("l1", "l2", "l3", "l4"),
]
_ROWS = {
    "twizy": [
        (0.46, 2.75, 0.31, 2.42, 2.91, 20),
        (0.33, 2.38, 0.31, 2.53, 2.95, 20),
        (0.41, 2.54, 0.33, 2.56, 2.97, 20),
        (0.31, 2.64, 0.34, 2.45, 2.80, 20),
        (0.22, 2.10, 0.33, 2.36, 2.70, 25),
        (0.36, 2.16, 0.30, 2.55, 2.70, 25),
        (0.29, 2.11, 0.32, 2.79, 2.69, 25),
        (0.30, 2.54, 0.21, 2.11, 2.80, 25),
        (0.26, 2.32, 0.28, 2.09, 2.66, 25),
        (0.26, 2.35, 0.27, 2.27, 2.84, 25),
        (0.22, 1.90, 0.28, 2.52, 2.60, 30),
        (0.19, 2.14, 0.18, 2.10, 2.54, 30),
        (0.31, 2.27, 0.23, 2.19, 2.50, 30),
        (0.19, 2.00, 0.22, 2.22, 2.26, 30),
        (0.19, 1.68, 0.16, 1.65, 1.96, 36),
    ],
    "man_tgx": [
        (0.37, 2.82, 0.44, 2.35, 2.92, 24),
        (0.47, 2.55, 0.34, 2.72, 2.89, 24),
        (0.28, 2.51, 0.47, 2.50, 2.88, 24),
        (0.30, 2.62, 0.48, 2.50, 2.87, 24),
        (0.31, 2.05, 0.26, 2.30, 2.73, 30),
        (0.19, 2.12, 0.31, 2.45, 2.80, 30),
        (0.25, 2.09, 0.34, 2.70, 2.71, 30),
        (0.29, 2.60, 0.23, 2.25, 2.80, 30),
        (0.35, 2.24, 0.24, 2.13, 2.68, 30),
        (0.32, 2.45, 0.20, 2.14, 2.80, 30),
        (0.27, 2.05, 0.27, 2.64, 2.57, 37),
        (0.27, 2.13, 0.18, 1.99, 2.61, 37),
        (0.28, 2.22, 0.20, 2.17, 2.54, 37),
        (0.21, 2.12, 0.13, 2.26, 2.20, 37),
        (0.15, 1.57, 0.13, 1.46, 1.82, 45),
    ],
    "volvo_fh": [
        (0.32, 2.75, 0.49, 2.31, 2.87, 25),
        (0.42, 2.50, 0.41, 2.77, 2.95, 25),
        (0.31, 2.46, 0.53, 2.57, 2.84, 25),
        (0.23, 2.57, 0.44, 2.46, 2.91, 25),
        (0.24, 2.01, 0.19, 2.26, 2.67, 31),
        (0.26, 2.06, 0.24, 2.39, 2.86, 31),
        (0.20, 2.04, 0.27, 2.64, 2.64, 31),
        (0.36, 2.53, 0.28, 2.18, 2.74, 31),
        (0.31, 2.31, 0.17, 2.09, 2.62, 31),
        (0.27, 2.39, 0.16, 2.19, 2.75, 31),
        (0.34, 2.10, 0.20, 2.58, 2.53, 35),
        (0.34, 2.20, 0.25, 2.01, 2.56, 35),
        (0.22, 2.27, 0.22, 2.23, 2.48, 35),
        (0.28, 1.99, 0.20, 2.00, 2.27, 35),
        (0.14, 1.30, 0.12, 1.26, 1.77, 39),
    ],
}
SUBSET_TABLES = {
    vehicle: {
        subset: dict(zip(("truck_pos", "truck_yaw", "trailer_pos", "trailer_yaw", "hitch", "ms"), row))
        for subset, row in zip(_SUBSETS, rows)
    }
    for vehicle, rows in _ROWS.items()
}
SUBSET_TABLE_NUMBER = {"twizy": 3, "man_tgx": 4, "volvo_fh": 5}
PAPER_SUBSET_ORDER = _SUBSETS

# dCAP Table 2 (trailer rear-camera pose, metric scale): ΔT, Δx, Δy, Δz (m), RRA (rad)
DCAP_TABLE2 = {
    "Static Calibration": (1.284, 0.210, 1.120, 0.356, 0.148),
    "VGGT": (6.040, 2.761, 3.082, 3.634, 0.309),
    "DUSt3R": (8.625, 4.664, 5.080, 2.953, 0.578),
    "dCAP (w/o CCA, w/o CTA)": (0.632, 0.076, 0.600, 0.087, 0.073),
    "dCAP (w/ CCA)": (0.505, 0.069, 0.475, 0.074, 0.048),
    "dCAP (w/ CTA)": (0.452, 0.125, 0.395, 0.090, 0.058),
}
