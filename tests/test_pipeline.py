"""The Pipeline on constructed frames: faults never raise, parameter patches, end-to-end geometry."""

import json
import threading

import numpy as np
import pytest
from test_stage_classification import articulated_points, articulated_poses, box_surface, place

from i2v_loc.frame import Frame, SensorScan
from i2v_loc.geometry import wrap_deg
from i2v_loc.params import Extrinsics, Params, ParamsError, SensorConfig
from i2v_loc.pipeline import Pipeline, centre_to_hitch_m, method_params


def yard_params(vehicle=None, **sections):
    """One sensor at the yard origin (identity extrinsics) plus three that can be missing."""
    params = Params(
        sensors=[SensorConfig(name=n, extrinsics=Extrinsics()) for n in ("l1", "l2", "l3", "l4")], **sections
    )
    if vehicle:
        params = params.model_copy(update={"vehicles": {vehicle: params.vehicles[vehicle]}})
    return params


def ground(seed=0, half_m=25.0, n=20000):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-half_m, half_m, (n, 2)), rng.normal(0, 0.02, n)])


def frame_of(index, stamp_s, clouds: dict):
    return Frame(index, {name: SensorScan(name, stamp_s, pts, None) for name, pts in clouds.items()})


def test_missing_sensor_empty_cloud_and_nans_are_processed_and_counted():
    pipeline = Pipeline(yard_params())
    cloud = ground()
    nan_cloud = cloud.copy()
    nan_cloud[:5] = np.nan
    frame = frame_of(0, 1.0, {"l1": cloud, "l2": np.zeros((0, 3)), "l3": nan_cloud})
    result = pipeline.process(frame)
    line = result.to_json()
    assert line["faults"] == {"l2": "empty", "l3": "nan_points", "l4": "missing"}
    assert line["dropped"] == {"out_of_sync": 0, "empty": 1, "nan_points": 5}
    json.dumps(line)  # the state line is plain JSON
    assert pipeline.counters["missing"] == 1 and pipeline.counters["nan_points"] == 5
    empty = pipeline.process(Frame(1, {}))
    assert empty.to_json()["vehicles"] == [] and empty.to_json()["stamp_s"] is None
    assert pipeline.counters["missing"] == 5 and pipeline.counters["frames"] == 2


def test_update_params_applies_at_the_next_frame_and_rejects_bad_patches():
    pipeline = Pipeline(yard_params())
    box = np.array(np.meshgrid(np.arange(0, 2, 0.1), np.arange(0, 2, 0.1), np.arange(0.5, 2.5, 0.2))).reshape(3, -1).T
    cloud = np.vstack([ground(), box, box + [20.4 - 18.0, 0, 0]])  # two boxes 0.4 m apart
    frame = frame_of(0, 1.0, {"l1": cloud})
    assert len(pipeline.process(frame).clusters) == 1
    with pytest.raises(ParamsError):
        pipeline.update_params({"clustering": {"tolerance_m": -1}})
    done = threading.Event()
    threading.Thread(
        target=lambda: (pipeline.update_params({"clustering": {"tolerance_m": 0.3, "voxel_size_m": 0.0}}), done.set())
    ).start()
    done.wait(5)
    assert pipeline.params.clustering.tolerance_m == 0.3
    assert len(pipeline.process(frame).clusters) == 2


def test_unknown_method_is_refused():
    with pytest.raises(ValueError, match="paper"):
        Pipeline(Params(), method="magic")


def run_vehicle(name, n_frames, truck_yaw_deg, hitch_deg, speed_m_s):
    params = yard_params(name, tracking={"min_hits": 2})
    pipeline = Pipeline(params)
    v = params.vehicles[name]
    fwd = np.array([np.cos(np.radians(truck_yaw_deg)), np.sin(np.radians(truck_yaw_deg))])
    results = []
    for k in range(n_frames):
        axle = np.array([-4.0, -2.0]) + fwd * speed_m_s * 0.1 * k
        truck, trailer = articulated_points(v, axle, truck_yaw_deg, hitch_deg)
        results.append(pipeline.process(frame_of(k, 0.1 * k, {"l1": np.vstack([ground(k), truck, trailer])})))
    return results, articulated_poses(v, axle, truck_yaw_deg, hitch_deg)


def test_moving_volvo_is_localized_with_both_units_and_one_vehicle_id():
    results, ((tc, ty), (rc, ry)) = run_vehicle("volvo_fh", 12, 30.0, 0.0, 2.0)
    line = results[-1].to_json()
    assert len(line["vehicles"]) == 1
    veh = line["vehicles"][0]
    assert veh["vehicle"] == "volvo_fh"
    assert veh["truck"]["center"][:2] == pytest.approx(tc, abs=0.1)
    assert veh["trailer"]["center"][:2] == pytest.approx(rc, abs=0.1)
    assert veh["truck"]["yaw_deg"] == pytest.approx(30.0, abs=1.0)
    assert veh["trailer"]["yaw_deg"] == pytest.approx(30.0, abs=1.0)
    assert veh["hitch_deg"] == pytest.approx(0.0, abs=1.0)
    t = np.array(veh["tractor_to_trailer"])
    # the truck's origin seen from the trailer frame: straight ahead by the centre distance
    assert t[:2, 3] == pytest.approx([np.hypot(*(tc - rc)), 0.0], abs=0.15)
    assert [c["status"] for c in line["clusters"]].count("vehicle:volvo_fh") == 1
    assert set(line["latency_ms"]) >= {
        "concatenation",
        "region",
        "clustering",
        "classification",
        "centroid",
        "tracking",
        "orientation",
        "total",
    }


@pytest.mark.parametrize("hitch_deg", [30.0, -30.0])
def test_standing_twizy_hitch_angle_from_the_unit_shapes(hitch_deg):
    results, _ = run_vehicle("twizy", 4, -60.0, hitch_deg, 0.0)
    veh = results[-1].to_json()["vehicles"][0]
    assert veh["truck"]["yaw_deg"] == pytest.approx(-60.0, abs=1.0)
    assert veh["hitch_deg"] == pytest.approx(hitch_deg, abs=1.5)


def run_with_gap(reacquire_distance_m: float, seen=(range(6, 16), range(22, 28)), yaw_deg=30.0, speed_m_s=4.0):
    """A MAN driving straight at yaw_deg, unseen (no points) in the frames outside ``seen``; the
    background map is learned on the empty yard in the first frames (ready after 5).
    With this short learning window (10 frames) the MAN must travel the 2 m that protect it
    (background.protect_min_travel_m) before its trailer's sides, which overlap themselves while it
    drives along its length, are occupied in 8 of 10 frames: 4 m/s."""
    name = "man_tgx"
    params = yard_params(name, background={"window_frames": 10, "min_samples": 5, "learn_every_frames": 1})
    pipeline = Pipeline(params, method="default")
    pipeline.update_params({"tracking": {"reacquire_distance_m": reacquire_distance_m}})  # over the method's value
    v = params.vehicles[name]
    fwd = np.array([np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))])
    results = []
    for k in range(max(seen[-1]) + 1):
        axle = np.array([-12.0, -8.0]) + fwd * speed_m_s * 0.1 * k
        clouds = [ground(k)]
        if any(k in r for r in seen):
            clouds += list(articulated_points(v, axle, yaw_deg, 0.0))
        results.append(pipeline.process(frame_of(k, 0.1 * k, {"l1": np.vstack(clouds)})))
    return results, articulated_poses(v, axle, yaw_deg, 0.0)


def test_reacquired_vehicle_keeps_its_id_and_yaw():
    results, ((tc, ty), (rc, ry)) = run_with_gap(reacquire_distance_m=3.0)
    assert all(r.to_json()["vehicles"] == [] for r in results[:6])
    first = results[6].to_json()["vehicles"]
    assert len(first) == 1 and first[0]["truck"] and first[0]["trailer"]  # a truck + trailer pair: reported at once
    before = results[15].to_json()["vehicles"][0]
    assert all(r.to_json()["vehicles"] == [] for r in results[16:22])
    after = results[22].to_json()["vehicles"]
    assert len(after) == 1
    after = after[0]
    assert after["id"] == before["id"]
    assert after["truck"]["track_id"] == before["truck"]["track_id"]
    assert after["trailer"]["track_id"] == before["trailer"]["track_id"]
    for line in [r.to_json()["vehicles"][0] for r in results[22:]]:
        assert abs(wrap_deg(line["truck"]["yaw_deg"] - 30.0)) < 2.0  # no 90 deg (square cab) or 180 deg flip
        assert abs(wrap_deg(line["trailer"]["yaw_deg"] - 30.0)) < 2.0
        assert abs(line["hitch_deg"]) < 2.0
    last = results[-1].to_json()["vehicles"][0]
    assert last["truck"]["center"][:2] == pytest.approx(tc, abs=0.15)
    assert last["trailer"]["center"][:2] == pytest.approx(rc, abs=0.15)


def test_without_reacquisition_the_returning_vehicle_is_a_new_one():
    results, _ = run_with_gap(reacquire_distance_m=0.0)
    assert results[22].to_json()["vehicles"][0]["id"] != results[15].to_json()["vehicles"][0]["id"]


def test_foreground_points_are_exposed_but_not_in_the_state_line():
    results, ((tc, _), (rc, _)) = run_with_gap(reacquire_distance_m=3.0, seen=(range(0, 3), range(6, 16)))
    for result in (results[0], results[-1]):  # before and after the background map is learned
        fg = result.foreground
        assert fg.ndim == 2 and fg.shape[1] == 3 and len(fg) > 500
        assert np.all(fg[:, 2] > 0.15)  # no ground points
        assert "foreground" not in result.to_json()
    # once learned, only the vehicle is left: every foreground point lies within its boxes' reach
    d = np.minimum(np.hypot(*(results[-1].foreground[:, :2] - tc).T), np.hypot(*(results[-1].foreground[:, :2] - rc).T))
    assert d.max() < 7.5
    paper = Pipeline(yard_params("man_tgx")).process(frame_of(0, 0.0, {"l1": ground()}))
    assert paper.foreground is not None and len(paper.foreground) < 50  # only ground noise above 0.15 m


def test_method_preset_fills_only_the_fields_left_at_the_model_default():
    user = yard_params(
        tracking={"reacquire_distance_m": 5.0}, orientation={"shape_weight": 0.5}, region={"ground_refit_frames": 3}
    )
    params = Pipeline(user, method="default").params
    assert params.tracking.reacquire_distance_m == 5.0  # the user's, not the preset's 3.0
    assert params.orientation.shape_weight == 0.5
    assert params.region.ground_refit_frames == 3
    assert params.clustering.algorithm == "grid" and params.background.enabled  # left at default: preset
    assert params.tracking.confirm_paired and params.orientation.flip_confirm_frames == 5
    assert Pipeline(user, method="paper").params == user  # the paper adds nothing
    assert method_params(user, "default") == params
    assert user.tracking.reacquire_distance_m == 5.0 and not user.background.enabled  # input unchanged


def test_a_patch_arriving_while_the_previous_one_is_applied_is_not_lost():
    """update_params from another thread between taking the pending patch and building the stages
    must build on the patch being applied, not on the parameters before it."""
    pipeline = Pipeline(yard_params())
    frame = frame_of(0, 1.0, {"l1": ground()})
    pipeline.update_params({"clustering": {"tolerance_m": 0.3}})
    build = pipeline._build

    def build_with_a_patch_arriving(params):
        del pipeline._build  # once: back to the method
        pipeline.update_params({"clustering": {"min_points": 7}})
        build(params)

    pipeline._build = build_with_a_patch_arriving
    pipeline.process(frame)
    pipeline.process(frame)
    assert pipeline.params.clustering.tolerance_m == 0.3 and pipeline.params.clustering.min_points == 7
    assert pipeline.clustering.params.tolerance_m == 0.3 and pipeline.clustering.params.min_points == 7


@pytest.mark.parametrize("name", ["man_tgx", "volvo_fh", "twizy"])
@pytest.mark.parametrize("hitch_deg", [0.0, 35.0, -80.0])
def test_centre_to_hitch_distances_match_the_kinematic_figures(name, hitch_deg):
    v = Params().vehicles[name]
    (tc, _), (rc, ry) = articulated_poses(v, (2.0, -1.0), 25.0, hitch_deg)
    truck_ahead_m, hitch_ahead_m = centre_to_hitch_m(v)
    hitch = np.array([2.0, -1.0]) - v.truck.hitch_behind_rear_axle_m * np.array(
        [np.cos(np.radians(25.0)), np.sin(np.radians(25.0))]
    )
    assert np.hypot(*(tc - hitch)) == pytest.approx(truck_ahead_m, abs=1e-9)
    assert np.hypot(*(rc - hitch)) == pytest.approx(hitch_ahead_m, abs=1e-9)
    assert hitch - rc == pytest.approx(hitch_ahead_m * np.array([np.cos(np.radians(ry)), np.sin(np.radians(ry))]))
    assert {"man_tgx": 3.265, "volvo_fh": 3.525, "twizy": 1.39}[name] == pytest.approx(truck_ahead_m)


def test_a_truck_beside_the_trailer_middle_is_not_where_the_hitch_puts_it():
    """A cab-sized box 0.5 m beside the middle of a Volvo trailer, in one cluster with it: the
    classification takes it for the truck; the articulation check drops it (its centre is 4 m from
    where the hitch puts a truck) and counts it, the trailer is still reported."""
    v = Params().vehicles["volvo_fh"]
    trailer = place(
        box_surface(v.trailer.length_m, v.trailer.width_m, v.trailer.height_m), 0.0, 0.0, 0.0, v.trailer.floor_m
    )
    side_y = v.trailer.width_m / 2 + 0.5 + v.truck.width_m / 2
    cab = place(box_surface(v.truck.length_m, v.truck.width_m, v.truck.height_m), 0.0, side_y, 0.0, v.truck.floor_m)
    frame = frame_of(0, 0.0, {"l1": np.vstack([ground(), trailer, cab])})
    results = {}
    for gap in (0.0, 2.0):
        params = yard_params("volvo_fh", tracking={"min_hits": 1}, classification={"max_hitch_gap_m": gap})
        pipeline = Pipeline(params)
        results[gap] = pipeline.process(frame).to_json()["vehicles"]
        assert pipeline.counters["truck_off_hitch"] == (1 if gap else 0)
    assert results[0.0][0]["truck"]["center"][:2] == pytest.approx([0.0, side_y], abs=0.3)  # no check: a truck
    assert results[2.0][0]["truck"] is None and results[2.0][0]["trailer"]["center"][:2] == pytest.approx(
        [0, 0], abs=0.3
    )
