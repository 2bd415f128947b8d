"""The single parameter model of i2v-loc.

Every parameter lives here: YAML files, the REST API, the JSON Schema and the docs derive from
these classes. Units are in the names (``_m``, ``_deg``, ``_s``, ``_m3``).

Files: a YAML file may hold any subset of the top-level sections; ``load_params`` merges the
files given, in order, over the built-in defaults and validates the result.
"""

from __future__ import annotations

import copy
import functools
import json
import math
import os
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

DEFAULT_METHOD = "default"  # the pipeline method run, eval, bench, sweep and serve use (i2v_loc.pipelines.METHODS)
YARD_EXTENT_M = 10_000.0  # positions and region bounds: a yard is never 10 km from its origin
MAST_HEIGHT_M = 200.0
MAX_POINTS_PER_FRAME = 10_000_000  # point counts: far above what four 128-beam sensors deliver
MAX_VOLUME_TOLERANCE_M3 = 2_000.0
MAX_SENSORS = 64
MAX_VEHICLES = 100


class Section(BaseModel):
    """Base of every parameter section: unknown keys are errors, assignments are validated, and
    values are not coerced across types (``true`` or ``"0.6"`` is no length; an integer is a float)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, strict=True)


# --------------------------------------------------------------------------- sensors


class Extrinsics(Section):
    """Pose of a sensor in the yard frame (x east, y north, z up; angles applied Z-Y-X)."""

    x_m: float = Field(0.0, ge=-YARD_EXTENT_M, le=YARD_EXTENT_M)
    y_m: float = Field(0.0, ge=-YARD_EXTENT_M, le=YARD_EXTENT_M)
    z_m: float = Field(0.0, ge=-MAST_HEIGHT_M, le=MAST_HEIGHT_M)
    roll_deg: float = Field(0.0, ge=-180, le=180)
    pitch_deg: float = Field(0.0, ge=-90, le=90)
    yaw_deg: float = Field(0.0, ge=-180, le=180)


class SensorConfig(Section):
    name: str = Field(..., min_length=1, max_length=32, pattern=r"^[A-Za-z0-9_\-]+$")
    model: Literal["OS1-32", "OS1-64", "OS1-128"] = "OS1-32"
    columns: Literal[512, 1024, 2048] = 1024
    rate_hz: Literal[10, 20] = 10
    min_range_m: float = Field(0.5, ge=0.0, le=10.0)
    max_range_m: float = Field(120.0, gt=1.0, le=300.0)
    time_offset_s: float = Field(
        0.0, ge=-1.0, le=1.0, description="Known offset added to this sensor's stamps to bring it onto the common clock"
    )
    beam_config: Literal["uniform", "gradient", "below_horizon", "above_horizon"] = Field(
        "uniform", description="Which of the OS1's 128 channels a 32/64-beam model reads (Ouster's beam configurations)"
    )
    metadata: str | None = Field(
        None,
        max_length=4096,
        description="Ouster sensor metadata JSON (as ouster-cli records it); its beam table overrides the model's",
    )
    extrinsics: Extrinsics = Field(default_factory=Extrinsics)
    enabled: bool = Field(
        True,
        description="Fused into the frames; `calibrate` writes false for a sensor whose calibration it refused "
        "(at its guess, tens of cm and degrees off, its points bend and widen the vehicles they fall on), "
        "true for one it accepted",
    )

    @property
    def beams(self) -> int:
        return int(self.model.split("-")[1])


def _paper_field_sensors() -> list[SensorConfig]:
    """Four OS1-32 of the paper's test field, counter-clockwise, looking at the field centre.

    d12 = 19.2 m, d23 = 40.5 m, d34 = 19.2 m, d14 = 15 m: an isosceles trapezoid.
    """
    height_m = 4.0
    corners = {"l1": (-7.5, 14.36), "l2": (-20.25, 0.0), "l3": (20.25, 0.0), "l4": (7.5, 14.36)}
    centre = (0.0, 6.0)
    return [
        SensorConfig(
            name=name,
            extrinsics=Extrinsics(
                x_m=x,
                y_m=y,
                z_m=height_m,
                yaw_deg=round(math.degrees(math.atan2(centre[1] - y, centre[0] - x)), 3),
            ),
        )
        for name, (x, y) in corners.items()
    ]


# --------------------------------------------------------------------------- vehicles


class UnitDimensions(Section):
    length_m: float = Field(..., gt=0.2, le=25.0)
    width_m: float = Field(..., gt=0.2, le=4.0)
    height_m: float = Field(..., gt=0.2, le=5.0)
    floor_m: float = Field(0.0, ge=0.0, le=2.0, description="Height of the bottom of the unit's box above the ground")

    @property
    def volume_m3(self) -> float:
        return self.length_m * self.width_m * self.height_m


class TruckGeometry(UnitDimensions):
    """The towing unit. Its reference point is the rear axle centre on the ground."""

    wheelbase_m: float = Field(..., gt=0.5, le=8.0)
    front_overhang_m: float = Field(..., ge=0.0, le=3.0, description="Front axle to front face")
    hitch_behind_rear_axle_m: float = Field(
        ...,
        ge=-2.0,
        le=3.0,
        description="Hitch (fifth wheel or drawbar coupling) behind the rear axle; negative when ahead of it",
    )


class TrailerGeometry(UnitDimensions):
    """The towed unit. Its reference point is the (effective) axle centre on the ground."""

    hitch_to_axle_m: float = Field(
        ..., gt=0.5, le=15.0, description="Kingpin or drawbar eye to the trailer's effective axle"
    )
    hitch_to_front_m: float = Field(
        ...,
        ge=-3.0,
        le=3.0,
        description="Kingpin to the trailer's front face, positive when the face is ahead of the kingpin",
    )


class VehicleConfig(Section):
    description: str = ""
    truck: TruckGeometry
    trailer: TrailerGeometry
    vehicle_volume_tolerance_m3: float = Field(
        ..., gt=0.0, le=MAX_VOLUME_TOLERANCE_M3, description="δV of the whole-vehicle volume gate (paper Eq. 5)"
    )
    trailer_volume_tolerance_m3: float = Field(
        ..., gt=0.0, le=MAX_VOLUME_TOLERANCE_M3, description="δV of the trailer volume gate (paper section 3.4)"
    )

    @property
    def vehicle_volume_m3(self) -> float:
        return self.truck.volume_m3 + self.trailer.volume_m3


def _paper_vehicles() -> dict[str, VehicleConfig]:
    """The three vehicles of the paper's Table 1 (H x W x L) with documented kinematic figures.

    Volume gates: the whole-vehicle gate holds the oriented box of the articulated vehicle, which
    grows with the hitch angle (MAN at 30 deg: about 16 x 7 x 3.6 m = 400 m3), so its tolerance is
    wide; the trailer gate and the truck remainder do the discriminating.

    Kinematic figures are typical values, not measured on the paper's vehicles: Twizy wheelbase
    1.69 m (Renault data sheet); MAN TGX 4x2 tractor 3.60 m, Volvo FH 4x2 tractor 3.70 m; fifth
    wheel about 0.3 m ahead of the rear axle; semitrailer kingpin set back 1.2 m from the front.
    """
    return {
        "twizy": VehicleConfig(
            description="Renault Twizy with a box trailer on a drawbar",
            truck=TruckGeometry(
                length_m=2.00,
                width_m=1.57,
                height_m=1.50,
                floor_m=0.10,
                wheelbase_m=1.69,
                front_overhang_m=0.25,
                hitch_behind_rear_axle_m=0.45,
            ),
            trailer=TrailerGeometry(
                length_m=2.50, width_m=1.75, height_m=2.50, floor_m=0.35, hitch_to_axle_m=2.40, hitch_to_front_m=-0.60
            ),
            vehicle_volume_tolerance_m3=20.0,
            trailer_volume_tolerance_m3=7.0,
        ),
        "man_tgx": VehicleConfig(
            description="MAN TGX 4x2 tractor with a 13.68 m semitrailer",
            truck=TruckGeometry(
                length_m=2.77,
                width_m=2.77,
                height_m=2.86,
                floor_m=0.45,
                wheelbase_m=3.60,
                front_overhang_m=1.40,
                hitch_behind_rear_axle_m=-0.35,
            ),
            trailer=TrailerGeometry(
                length_m=13.68, width_m=2.77, height_m=2.55, floor_m=1.20, hitch_to_axle_m=7.90, hitch_to_front_m=1.20
            ),
            vehicle_volume_tolerance_m3=300.0,
            trailer_volume_tolerance_m3=70.0,
        ),
        "volvo_fh": VehicleConfig(
            description="Volvo FH 4x2 tractor with a 6.30 m semitrailer",
            truck=TruckGeometry(
                length_m=2.55,
                width_m=2.50,
                height_m=2.50,
                floor_m=0.50,
                wheelbase_m=3.70,
                front_overhang_m=1.40,
                hitch_behind_rear_axle_m=-0.30,
            ),
            trailer=TrailerGeometry(
                length_m=6.30, width_m=2.50, height_m=2.50, floor_m=1.20, hitch_to_axle_m=4.20, hitch_to_front_m=0.90
            ),
            vehicle_volume_tolerance_m3=100.0,
            trailer_volume_tolerance_m3=30.0,
        ),
    }


# --------------------------------------------------------------------------- pipeline stages


class CalibrationParams(Section):
    reference_sensor: str | None = Field(
        None, description="Sensor whose extrinsics are kept fixed; none: the first sensor"
    )
    windows: int = Field(
        30,
        ge=1,
        le=200,
        description="Short windows spread over the recording; each keeps what stood still in it (scene, standing or slow vehicles)",
    )
    window_gap_frames: int = Field(
        2,
        ge=1,
        le=20,
        description="Frames between the three sweeps of a window: what moved more than 0.2 m is left out",
    )
    voxel_size_m: float = Field(
        0.1,
        gt=0.01,
        le=2.0,
        description="Voxel of the registered clouds; 0.2 m leaves 6 cm errors with a slow vehicle in view",
    )
    normal_radius_m: float = Field(
        2.0, ge=0.5, le=10.0, description="Normals from >= 2 m: 1 m diverges on sparse 32-beam rings"
    )
    max_correspondence_m: float = Field(1.0, gt=0.01, le=10.0)
    max_iterations: int = Field(60, ge=1, le=1000)
    fitness_distance_m: float = Field(
        0.1,
        gt=0.0,
        le=2.0,
        description="Fitness: share of the sensor's overlapping structure (walls, vehicles, not the ground) this close to the target's surface",
    )
    min_fitness: float = Field(
        0.3,
        ge=0.0,
        le=1.0,
        description="Results below this fitness are refused unless better than the guess's with every horizontal direction determined (measured: 0.26-0.91 at the true extrinsics, 0.07-0.23 at 25 cm off)",
    )
    min_constraint_points: float = Field(
        100.0,
        ge=0.0,
        le=1e6,
        description="Warn when a sensor's weakest horizontal direction is constrained by fewer overlapping structure points (measured: 5-31 on sensors 10-42 cm off, >= 376 within 2 cm)",
    )


class ConcatenationParams(Section):
    voxel_size_m: float = Field(
        0.1, ge=0.0, le=2.0, description="Voxel edge of the centroid grid (Eq. 1-2); 0 disables it"
    )
    sync_tolerance_s: float = Field(
        0.1,
        gt=0.0,
        le=1.0,
        description="Sensor frames further than this from the reference time are dropped; one sweep period, as sensor phases are unsynchronised",
    )
    reference: Literal["earliest", "latest", "mean"] = Field(
        "earliest", description="Which sensor stamp is the frame's reference time"
    )
    motion_interpolation: bool = Field(True, description="Interpolate each point to the reference time (Eq. 3)")


class RegionParams(Section):
    x_min_m: float = Field(-40.0, ge=-YARD_EXTENT_M, le=YARD_EXTENT_M)
    x_max_m: float = Field(40.0, ge=-YARD_EXTENT_M, le=YARD_EXTENT_M)
    y_min_m: float = Field(-25.0, ge=-YARD_EXTENT_M, le=YARD_EXTENT_M)
    y_max_m: float = Field(40.0, ge=-YARD_EXTENT_M, le=YARD_EXTENT_M)
    z_min_m: float = Field(-1.0, ge=-MAST_HEIGHT_M, le=MAST_HEIGHT_M)
    z_max_m: float = Field(5.0, ge=-MAST_HEIGHT_M, le=MAST_HEIGHT_M)
    ground_distance_threshold_m: float = Field(0.15, gt=0.0, le=2.0)
    ransac_iterations: int = Field(100, ge=1, le=10000)
    ransac_sample_voxel_m: float = Field(
        0.5, ge=0.0, le=5.0, description="Voxel size of the cloud RANSAC samples from; 0 uses every point"
    )
    max_ground_tilt_deg: float = Field(
        10.0, ge=0.0, le=45.0, description="Planes tilted more than this from horizontal are not ground"
    )
    min_ground_fraction: float = Field(
        0.1, ge=0.0, le=1.0, description="A plane supported by fewer sampled points than this fraction is not ground"
    )
    ground_refit_frames: int = Field(
        10,
        ge=1,
        le=1000,
        description="Fit the ground plane every this many frames and keep it in between (1 = every frame; the ground is static); a refit samples the region on one frame and fits the sample on the next",
    )

    @model_validator(mode="after")
    def _check_bounds(self) -> RegionParams:
        for axis in "xyz":
            low, high = getattr(self, f"{axis}_min_m"), getattr(self, f"{axis}_max_m")
            if not low < high:
                raise ValueError(f"{axis}_min_m ({low}) must be below {axis}_max_m ({high})")
        return self


class ClusteringParams(Section):
    tolerance_m: float = Field(0.7, gt=0.0, le=5.0, description="ε of Eq. 4")
    voxel_size_m: float = Field(
        0.2, ge=0.0, le=2.0, description="Neighbour search on voxel centroids of this size (0 = every point)"
    )
    min_points: int = Field(10, ge=1, le=MAX_POINTS_PER_FRAME)
    max_points: int = Field(200000, ge=1, le=MAX_POINTS_PER_FRAME)

    @model_validator(mode="after")
    def _check_points(self) -> ClusteringParams:
        if self.min_points > self.max_points:
            raise ValueError(f"min_points ({self.min_points}) must not exceed max_points ({self.max_points})")
        return self


class ClassificationParams(Section):
    trailer_tolerance_m: float = Field(
        0.35, gt=0.0, le=5.0, description="ε of the second clustering inside a vehicle cluster"
    )
    min_trailer_points: int = Field(30, ge=1, le=MAX_POINTS_PER_FRAME)
    min_truck_points: int = Field(
        10,
        ge=1,
        le=MAX_POINTS_PER_FRAME,
        description="Fewer points left after removing the trailer: the truck is not seen",
    )
    max_length_excess_m: float = Field(
        1.0, ge=0.0, le=20.0, description="A trailer candidate longer than the trailer plus this is rejected"
    )
    floor_margin_m: float = Field(
        0.1,
        ge=-1.0,
        le=2.0,
        description="The second clustering uses points higher than the trailer floor plus this above the ground",
    )
    xy_grid_m: float = Field(
        0.05,
        gt=0.0,
        le=0.3,
        description="The xy projection is thinned to one point per cell of this size before the second clustering (neighbour pairs fall with its square)",
    )


class CentroidParams(Section):
    enabled: bool = True


class TrackingParams(Section):
    max_distance_m: float = Field(1.0, gt=0.0, le=20.0, description="Association gate (paper: 1 m)")
    max_age_frames: int = Field(3, ge=1, le=100)
    min_hits: int = Field(3, ge=1, le=100)
    process_noise: float = Field(
        1.0, ge=1e-4, le=1e4, description="Variance of the white-noise acceleration of the Kalman filter"
    )
    measurement_noise_m: float = Field(
        0.15, ge=0.001, le=10.0, description="Standard deviation of a measured unit centre"
    )


class OrientationParams(Section):
    history_frames: int = Field(10, ge=2, le=200, description="Corrected centroids in the PCA history (Eq. 11-12)")
    min_travel_m: float = Field(0.3, ge=0.0, le=20.0, description="Below this travel over the history the yaw is held")
    max_yaw_rate_deg_s: float = Field(
        22.5,
        gt=0.0,
        le=720.0,
        description="Bound on the smoothed yaw's change per second",
    )
    smoothing: float = Field(0.5, ge=0.0, lt=1.0, description="Weight of the previous yaw in the smoothed yaw")
    history_gap_s: float = Field(
        1.0, gt=0.0, le=60.0, description="A unit unseen for longer restarts its centroid history (its yaw is kept)"
    )


class BackgroundParams(Section):
    """Static background (yard, parked objects) learned online as a voxel occupancy map over the region."""

    enabled: bool = Field(True, description="Remove the learned background (the paper's preset turns it off)")
    voxel_size_m: float = Field(0.2, ge=0.05, le=2.0, description="Edge of the occupancy voxels")
    dilation_voxels: int = Field(1, ge=0, le=3, description="Background grown by this many voxels (range noise)")
    window_frames: int = Field(30, ge=2, le=255, description="Learning samples in the sliding window (N)")
    learn_every_frames: int = Field(2, ge=1, le=100, description="One learning sample every this many frames")
    occupied_fraction: float = Field(
        0.8, gt=0.0, le=1.0, description="A voxel occupied in at least this share of the window's samples is background"
    )
    forget_fraction: float = Field(
        0.0,
        ge=0.0,
        lt=1.0,
        description="A background voxel occupied in at most this share of the window's samples is background no more",
    )
    min_samples: int = Field(
        25,
        ge=1,
        le=255,
        description="Learning samples before the map is used (the frames before fall back to no background); a vehicle standing still from the start longer than this becomes background",
    )
    protect_margin_m: float = Field(
        1.0, ge=0.0, le=10.0, description="Voxels within this of a protected track's box are never learned"
    )
    keep_margin_m: float = Field(
        0.3,
        ge=0.0,
        le=5.0,
        description="Points within this of a protected track's box are never background (small: a docked trailer's rear is 0.3 m from the wall)",
    )
    protect_min_travel_m: float = Field(
        2.0,
        ge=0.0,
        le=100.0,
        description="A confirmed track is protected once its filtered position has moved this far from its first one (0: every confirmed track), so a parked object becomes background but a vehicle that stops does not",
    )
    max_voxels: int = Field(
        20_000_000, ge=1000, le=200_000_000, description="Refuse a region / voxel size giving a larger grid"
    )

    @model_validator(mode="after")
    def _check_samples(self) -> BackgroundParams:
        if self.min_samples > self.window_frames:
            raise ValueError(f"min_samples ({self.min_samples}) must not exceed window_frames ({self.window_frames})")
        if self.forget_fraction >= self.occupied_fraction:
            raise ValueError(
                f"forget_fraction ({self.forget_fraction}) must be below occupied_fraction ({self.occupied_fraction})"
            )
        return self


class ArticulatedParams(Section):
    """The articulated estimator (method ``articulated``): hinged-model fit, kinematic UKF, vehicle tracks."""

    fit_max_points: int = Field(
        200,
        ge=20,
        le=5000,
        description="A vehicle's points (voxel centroids of the front end) are thinned evenly to at most this many for the fit",
    )
    fit_min_points: int = Field(15, ge=3, le=1000, description="Fewer thinned points: no measurement this frame")
    fit_loss_scale_m: float = Field(
        0.1,
        gt=0.0,
        le=2.0,
        description="Scale of the Cauchy loss of the point-to-face distances (range noise plus mirrors and panel gaps)",
    )
    fit_start_scale_m: float = Field(
        0.2,
        gt=0.0,
        le=5.0,
        description="The loss scale of the first step, halved at each step down to fit_loss_scale_m",
    )
    fit_iterations: int = Field(
        5, ge=1, le=100, description="At most this many reweighted Gauss-Newton steps per fit (warm-started)"
    )
    fit_top_band_m: float = Field(
        0.25,
        ge=0.0,
        le=2.0,
        description="Points this close to a unit's roof height inside its footprint are roof points",
    )
    fit_inlier_m: float = Field(
        0.3, gt=0.0, le=2.0, description="Points this close to a face are explained by the vehicle"
    )
    fit_noise_floor_m: float = Field(
        0.02, gt=0.0, le=1.0, description="Lower bound of the point noise in the fit's covariance"
    )
    fit_position_floor_m: float = Field(
        0.03, ge=0.0, le=2.0, description="Added to the fit's position sigma (model error, correlated points)"
    )
    fit_angle_floor_deg: float = Field(0.3, ge=0.0, le=20.0, description="Added to the fit's yaw and hitch sigma")
    gate_margin_m: float = Field(
        1.0, gt=0.0, le=5.0, description="Points within this of a vehicle's predicted boxes are its points"
    )
    innovation_gate: float = Field(
        25.0,
        gt=0.0,
        le=1e4,
        description="A fit whose Mahalanobis distance squared from the prediction exceeds this is not used",
    )
    reset_after_rejections: int = Field(
        3,
        ge=1,
        le=100,
        description="After this many gated-out fits in a row that see the tractor the filter restarts its pose "
        "and hitch from the fit",
    )
    accel_sigma_m_s2: float = Field(0.5, gt=0.0, le=20.0, description="Process noise: longitudinal acceleration")
    curvature_rate_sigma_1_m_s: float = Field(
        0.03, gt=0.0, le=5.0, description="Process noise: rate of change of the path curvature"
    )
    reverse_curvature_rate_sigma_1_m_s: float = Field(
        0.09,
        gt=0.0,
        le=5.0,
        description="Process noise: rate of change of the path curvature while reversing (a driver steers "
        "to set the hitch angle: full lock, about 0.18 1/m, within 2 s)",
    )
    reverse_hold_m: float = Field(
        1.5,
        gt=0.0,
        le=1000.0,
        description="Process model: reversing, the path curvature relaxes to the one that holds the hitch angle "
        "still over this distance travelled (a driver keeps a reversing trailer from folding)",
    )
    position_sigma_m_s: float = Field(0.05, ge=0.0, le=5.0, description="Process noise: position (slip, model error)")
    yaw_sigma_deg_s: float = Field(
        0.2, ge=0.0, le=90.0, description="Process noise: tractor yaw beyond the curvature model"
    )
    hitch_sigma_deg_s: float = Field(
        0.5, ge=0.0, le=90.0, description="Process noise: hitch angle beyond the trailer kinematics"
    )
    jackknife_hitch_deg: float = Field(60.0, gt=0.0, le=180.0, description="Jackknife warning above this |hitch angle|")
    jackknife_rate_deg_s: float = Field(15.0, gt=0.0, le=360.0, description="or above this |hitch angle rate|")
    start_frames: int = Field(
        3, ge=1, le=100, description="A new vehicle is reported after its cluster persisted this many frames"
    )
    start_voxel_m: float = Field(
        0.8,
        ge=0.1,
        le=3.0,
        description="Voxel of the connected components that seed new vehicles (bridges the gap between cab and trailer)",
    )
    start_join_m: float = Field(
        2.0, ge=0.0, le=10.0, description="Seed components closer than this are one seed (a cab and its trailer)"
    )
    start_max_step_m: float = Field(
        1.5,
        gt=0.0,
        le=10.0,
        description="A seed cluster persists when its centre moved at most this since the last frame",
    )
    start_min_length_m: float = Field(
        3.0, gt=0.0, le=30.0, description="Seed clusters shorter than this are not vehicles"
    )
    start_max_length_m: float = Field(25.0, gt=0.0, le=60.0, description="nor longer than this")
    start_min_width_m: float = Field(
        1.0,
        ge=0.0,
        le=5.0,
        description="nor narrower than this (a wall is a plane; a vehicle starts once an end, its roof or both sides are seen)",
    )
    start_min_height_m: float = Field(1.2, gt=0.0, le=5.0, description="nor lower than this above the ground")
    rigid_min_length_m: float = Field(
        5.5,
        gt=0.0,
        le=30.0,
        description="A rigid vehicle (bus, rigid truck, van) is at least this long (cars are not reported)",
    )
    start_max_hitch_deg: float = Field(
        75.0,
        gt=0.0,
        le=180.0,
        description="No vehicle starts folded further (a parked trailer beside a container looks jack-knifed); a tracked one may fold on",
    )
    start_travel_m: float = Field(
        1.5,
        ge=0.0,
        le=50.0,
        description="A rigid vehicle starts once its seed moved this far (a container or a parked trailer never does)",
    )
    start_min_explained: float = Field(
        0.8, gt=0.0, le=1.0, description="A seed is a vehicle when the best model explains this share of its points"
    )
    leave_frames: int = Field(10, ge=1, le=1000, description="A vehicle without points for this many frames has left")
    learn_dimensions: bool = Field(
        True, description="Estimate the units' lengths and widths from their points (the catalogue is the prior)"
    )
    dimension_window: int = Field(50, ge=3, le=1000, description="Per-frame extent observations kept per dimension")
    type_max_error_m: float = Field(
        1.0,
        gt=0.0,
        le=10.0,
        description="The type is the catalogue vehicle whose lengths are nearest, if within this; else unknown",
    )


class Params(Section):
    """All parameters of i2v-loc."""

    sensors: list[SensorConfig] = Field(default_factory=_paper_field_sensors, min_length=1, max_length=MAX_SENSORS)
    vehicles: dict[str, VehicleConfig] = Field(
        default_factory=_paper_vehicles,
        min_length=1,
        max_length=MAX_VEHICLES,
        description="The vehicle catalogue: at least one vehicle, or nothing is ever detected",
    )
    calibration: CalibrationParams = Field(default_factory=CalibrationParams)
    concatenation: ConcatenationParams = Field(default_factory=ConcatenationParams)
    region: RegionParams = Field(default_factory=RegionParams)
    background: BackgroundParams = Field(default_factory=BackgroundParams)
    clustering: ClusteringParams = Field(default_factory=ClusteringParams)
    classification: ClassificationParams = Field(default_factory=ClassificationParams)
    centroid: CentroidParams = Field(default_factory=CentroidParams)
    tracking: TrackingParams = Field(default_factory=TrackingParams)
    orientation: OrientationParams = Field(default_factory=OrientationParams)
    articulated: ArticulatedParams = Field(default_factory=ArticulatedParams)

    @model_validator(mode="after")
    def _check_names(self) -> Params:
        names = [s.name for s in self.sensors]
        if len(set(names)) != len(names):
            raise ValueError(f"sensor names must be unique, got {', '.join(names)}")
        if self.calibration.reference_sensor is not None and self.calibration.reference_sensor not in names:
            raise ValueError(
                f"calibration.reference_sensor {self.calibration.reference_sensor!r} is not a configured sensor "
                f"(known: {', '.join(names)})"
            )
        return self

    def sensor(self, name: str) -> SensorConfig:
        for s in self.sensors:
            if s.name == name:
                return s
        raise KeyError(f"no sensor named {name!r}; known: {[s.name for s in self.sensors]}")


# --------------------------------------------------------------------------- loading and saving


class ParamsError(ValueError):
    """A parameter file or patch is invalid; the message names the file, key and allowed range."""


def deep_merge(base: dict, patch: dict) -> dict:
    """JSON merge patch (RFC 7396): dicts merge, ``None`` deletes, anything else replaces."""
    out = copy.deepcopy(base)
    for key, value in patch.items():
        if value is None:
            out.pop(key, None)
        elif isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def _constraint_text(model: type[BaseModel], loc: tuple) -> str:
    """The allowed range of the field at ``loc``, from the schema, e.g. '>= 0, <= 5'."""
    schema = _cached_schema(model)
    node: dict[str, Any] = schema
    defs = schema.get("$defs", {})
    for part in loc:
        if "$ref" in node:
            node = defs[node["$ref"].split("/")[-1]]
        props = node.get("properties")
        if props and part in props:
            node = props[part]
        elif isinstance(part, int) and "items" in node:
            node = node["items"]
        elif "additionalProperties" in node and isinstance(node["additionalProperties"], dict):
            node = node["additionalProperties"]
        else:
            return ""
    if "$ref" in node:
        node = defs[node["$ref"].split("/")[-1]]
    words = {"minimum": ">=", "maximum": "<=", "exclusiveMinimum": ">", "exclusiveMaximum": "<"}
    parts = [f"{sym} {node[k]}" for k, sym in words.items() if k in node]
    if "enum" in node:
        parts.append("one of " + ", ".join(map(str, node["enum"])))
    if "anyOf" in node:
        enums = [str(c["const"]) for c in node["anyOf"] if "const" in c]
        if enums:
            parts.append("one of " + ", ".join(enums))
    return ", ".join(parts)


@functools.cache
def _cached_schema(model: type[BaseModel]) -> dict:
    """Built once: building it takes tens of ms, far too long to repeat per error of a patch."""
    return model.model_json_schema()


MAX_ERRORS_REPORTED = 20


def describe_validation_error(err: ValidationError, source: str = "parameters") -> list[dict[str, Any]]:
    """Turn a pydantic error into records with field, value, message and allowed range (the
    first ``MAX_ERRORS_REPORTED``, then one record saying how many more there are)."""
    out = []
    errors = err.errors(include_url=False)
    if len(errors) > MAX_ERRORS_REPORTED:
        more = len(errors) - MAX_ERRORS_REPORTED
        out.append(
            {
                "source": source,
                "field": "",
                "value": None,
                "allowed": "",
                "message": f"{len(errors)} errors; the first {MAX_ERRORS_REPORTED} follow, {more} more not listed",
            }
        )
        errors = errors[:MAX_ERRORS_REPORTED]
    for e in errors:
        loc = tuple(e["loc"])
        out.append(
            {
                "source": source,
                "field": ".".join(str(p) for p in loc),
                "value": e.get("input"),
                "message": e["msg"],
                "allowed": _constraint_text(Params, loc),
            }
        )
    return out


def format_errors(records: list[dict[str, Any]]) -> str:
    lines = []
    for r in records:
        allowed = f" (allowed: {r['allowed']})" if r["allowed"] else ""
        if not r["field"]:
            lines.append(f"{r['source']}: {r['message']}{allowed}")
            continue
        value = json.dumps(r["value"], default=str) if not isinstance(r["value"], dict) else "{...}"
        lines.append(f"{r['source']}: {r['field']} = {value}: {r['message']}{allowed}")
    return "\n".join(lines)


def validate_params(data: dict, source: str = "parameters") -> Params:
    try:
        return Params.model_validate(data)
    except ValidationError as err:
        raise ParamsError(format_errors(describe_validation_error(err, source))) from err


def read_yaml(path: str | Path) -> dict:
    path = Path(path)
    if not path.is_file():
        raise ParamsError(f"{path}: no such parameter file")
    try:
        text = path.read_text()
        data = yaml.safe_load(text) or {}
    except yaml.YAMLError as err:
        _check_complete(path, text, None)
        mark = getattr(err, "problem_mark", None)
        where = f":{mark.line + 1}:{mark.column + 1}" if mark else ""
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        raise ParamsError(f"{path}{where}: not valid YAML: {problem}") from err
    if not isinstance(data, dict):
        raise ParamsError(f"{path}: expected a mapping of sections at the top level, got {type(data).__name__}")
    _check_complete(path, text, data)
    return data


# A file the service writes names its sections in its first line and ends with END_MARK: a file
# cut short (disk full, a crash while copying) is refused instead of falling back to defaults.
# Hand-written files carry neither line and may hold any subset of the sections.
HEADER_PREFIX = "# i2v-loc parameters; sections: "
END_MARK = "# end of i2v-loc parameters"


def _check_complete(path: Path, text: str, data: dict | None) -> None:
    """ParamsError if a file the service wrote lost its end or sections (``data`` None: unparsable)."""
    first = text.split("\n", 1)[0].strip()
    if not first.startswith(HEADER_PREFIX):
        return
    listed = [name.strip() for name in first[len(HEADER_PREFIX) :].split(",") if name.strip()]
    lost = [name for name in listed if data is not None and name not in data]
    ended = text.rstrip().endswith(END_MARK)
    if lost or not ended:
        what = f"sections lost: {', '.join(lost)}" if lost else "the last section is cut short"
        previous = path.with_name(path.name + PREVIOUS_SUFFIX)
        hint = f"; the previous version is {previous}" if previous.is_file() else ""
        raise ParamsError(
            f"{path}: the file is incomplete (it does not end with '{END_MARK}'; {what}); "
            f"refusing to start from it{hint}"
        )


def load_params(*paths: str | Path | None) -> Params:
    """Defaults, then each file in order (later files win), validated once per file."""
    merged = Params().model_dump(mode="json")
    for path in paths:
        if path is None:
            continue
        data = read_yaml(path)
        merged = deep_merge(merged, data)
        validate_params(merged, source=str(path))
    return validate_params(merged)


def apply_patch(params: Params, patch: dict, source: str = "patch") -> Params:
    """A new validated ``Params`` with a JSON merge patch applied; ``params`` is left unchanged."""
    if not isinstance(patch, dict):
        raise ParamsError(f"{source}: a patch must be a JSON object of sections")
    return validate_params(deep_merge(params.model_dump(mode="json"), patch), source)


def dump_yaml(params: Params | dict, sections: list[str] | None = None) -> str:
    data = params.model_dump(mode="json") if isinstance(params, BaseModel) else params
    if sections:
        data = {k: data[k] for k in sections}
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True)


PREVIOUS_SUFFIX = ".prev"


def save_params(params: Params, path: str | Path) -> None:
    """Write atomically and durably: a temporary file in the same folder, flushed to disk, then
    renamed over ``path``; the version it replaces is kept as ``<path>.prev``. The file names its
    sections and ends with END_MARK (see ``_check_complete``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = params.model_dump(mode="json")
    text = f"{HEADER_PREFIX}{', '.join(data)}\n{dump_yaml(data)}{END_MARK}\n"
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    if path.is_file():
        _keep_previous(path)
    tmp.replace(path)
    _fsync_dir(path.parent)


def _keep_previous(path: Path) -> None:
    """``path`` stays in place (a crash now loses nothing); a hard link of it becomes ``.prev``."""
    previous = path.with_name(path.name + PREVIOUS_SUFFIX)
    staging = path.with_name(path.name + PREVIOUS_SUFFIX + ".tmp")
    staging.unlink(missing_ok=True)
    try:
        os.link(path, staging)
    except OSError:  # no hard links on this file system
        staging.write_bytes(path.read_bytes())
    staging.replace(previous)


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:  # some file systems refuse fsync on a directory
        pass
    finally:
        os.close(fd)


def json_schema() -> dict:
    return copy.deepcopy(_cached_schema(Params))
