"""The pipelines on constructed frames: faults never raise, parameter patches, end-to-end geometry
(the paper's pipeline; the articulated one also in test_articulated_pipeline.py)."""

import json
import threading

import numpy as np
import pytest
from conftest import REPO
from test_cli_run import hitch_errors
from test_stage_classification import articulated_points, articulated_poses

from i2v_loc.formats import open_recording
from i2v_loc.frame import Frame, SensorScan
from i2v_loc.geometry import wrap_deg
from i2v_loc.params import Extrinsics, Params, ParamsError, SensorConfig, load_params
from i2v_loc.pipelines import build_pipeline
from i2v_loc.pipelines.paper import PaperPipeline
from i2v_loc.pipelines.presets import with_preset
from i2v_loc.results import STAGES
from i2v_loc.stages.primitives import voxel_centroids


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
    """Points constructed in the yard frame, not as a sensor at its origin would see them: no rays."""
    return Frame(index, {name: SensorScan(name, stamp_s, pts, None, from_sensor=False) for name, pts in clouds.items()})


@pytest.mark.parametrize("method", ["paper", "default"])
def test_missing_sensor_empty_cloud_and_nans_are_processed_and_counted(method):
    pipeline = build_pipeline(yard_params(), method)
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
    pipeline = PaperPipeline(yard_params())
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
        build_pipeline(Params(), "magic")


def run_vehicle(name, n_frames, truck_yaw_deg, hitch_deg, speed_m_s):
    params = yard_params(name, tracking={"min_hits": 2})
    pipeline = PaperPipeline(params)
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
    assert set(line["latency_ms"]) == {"merge", "front_end", "candidates", "vehicles", "total"}


@pytest.mark.parametrize("hitch_deg", [30.0, -30.0])
def test_standing_twizy_hitch_angle_from_the_unit_shapes(hitch_deg):
    results, _ = run_vehicle("twizy", 4, -60.0, hitch_deg, 0.0)
    veh = results[-1].to_json()["vehicles"][0]
    assert veh["truck"]["yaw_deg"] == pytest.approx(-60.0, abs=1.0)
    assert veh["hitch_deg"] == pytest.approx(hitch_deg, abs=1.5)


def run_man(seen=range(6, 16), yaw_deg=30.0, speed_m_s=4.0):
    """A MAN driving straight at yaw_deg through the default pipeline, unseen (no points) in the frames
    outside ``seen``; the background map is learned on the empty yard in the first frames (ready
    after 5). With this short learning window (10 frames) the MAN must travel the 2 m that protect it
    (background.protect_min_travel_m) before its trailer's sides, which overlap themselves while it
    drives along its length, are occupied in 8 of 10 frames: 4 m/s."""
    name = "man_tgx"
    params = yard_params(name, background={"window_frames": 10, "min_samples": 5, "learn_every_frames": 1})
    pipeline = build_pipeline(params, "default")
    v = params.vehicles[name]
    fwd = np.array([np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))])
    results = []
    for k in range(max(seen) + 1):
        axle = np.array([-12.0, -8.0]) + fwd * speed_m_s * 0.1 * k
        clouds = [ground(k)]
        if k in seen:
            clouds += list(articulated_points(v, axle, yaw_deg, 0.0))
        results.append(pipeline.process(frame_of(k, 0.1 * k, {"l1": np.vstack(clouds)})))
    return results, articulated_poses(v, axle, yaw_deg, 0.0)


def test_foreground_points_are_exposed_but_not_in_the_state_line():
    results, ((tc, _), (rc, _)) = run_man(seen=[*range(0, 3), *range(6, 16)])
    for result in (results[0], results[-1]):  # before and after the background map is learned
        fg = result.foreground
        assert fg.ndim == 2 and fg.shape[1] == 3 and len(fg) > 500
        assert np.all(fg[:, 2] > 0.15)  # no ground points
        assert "foreground" not in result.to_json()
    # once learned, only the vehicle is left: every foreground point lies within its boxes' reach
    d = np.minimum(np.hypot(*(results[-1].foreground[:, :2] - tc).T), np.hypot(*(results[-1].foreground[:, :2] - rc).T))
    assert d.max() < 7.5
    paper = PaperPipeline(yard_params("man_tgx")).process(frame_of(0, 0.0, {"l1": ground()}))
    assert paper.foreground is not None and len(paper.foreground) < 50  # only ground noise above 0.15 m


def test_a_vehicle_unseen_for_a_while_keeps_its_id_and_yaw():
    """The default pipeline: the MAN is unseen for 0.6 s (no points) and comes back where its motion
    puts it: the same vehicle, no 90 deg (square cab) or 180 deg flip, both units where they are."""
    results, ((tc, _), (rc, _)) = run_man(seen=[*range(6, 16), *range(22, 28)])
    assert all(r.to_json()["vehicles"] == [] for r in results[:6])
    before = results[15].to_json()["vehicles"]
    assert len(before) == 1 and before[0]["truck"] and before[0]["trailer"]
    after = [r.to_json()["vehicles"] for r in results[22:]]
    assert all(len(v) == 1 and v[0]["id"] == before[0]["id"] for v in after)
    for line in [v[0] for v in after]:
        assert abs(wrap_deg(line["truck"]["yaw_deg"] - 30.0)) < 2.0
        assert abs(wrap_deg(line["trailer"]["yaw_deg"] - 30.0)) < 2.0
        assert abs(line["hitch_deg"]) < 2.0
    last = after[-1][0]
    assert last["truck"]["center"][:2] == pytest.approx(tc, abs=0.15)
    assert last["trailer"]["center"][:2] == pytest.approx(rc, abs=0.15)


def test_a_trailer_that_moved_while_the_map_was_learned_is_not_background():
    """A MAN's trailer seen without its tractor, its front part hidden (beyond x = -8 m), drives 4 m
    along its length at 1 m/s while the background map is learned (the defaults: ready after 50
    frames), then stands: no vehicle starts. Its sides overlap themselves as it drives, were
    occupied in most samples and became background, before its seed's motion kept it out of the
    map; standing now, all that is seen of it is still foreground."""
    name = "man_tgx"
    params = yard_params(name)
    pipeline = build_pipeline(params, "default")
    v = params.vehicles[name]
    for k in range(80):
        axle = np.array([-4.0 + 0.1 * min(k, 40), -3.0])
        _, trailer = articulated_points(v, axle, 0.0, 0.0)
        trailer = trailer[trailer[:, 0] < -8.0]
        result = pipeline.process(frame_of(k, 0.1 * k, {"l1": np.vstack([ground(k), trailer])}))
    assert pipeline.background.ready and result.to_json()["vehicles"] == []
    near = np.hypot(*(result.foreground[:, :2] - trailer[:, :2].mean(axis=0)).T) < 8.0
    seen = voxel_centroids(trailer[trailer[:, 2] > 0.3], params.concatenation.voxel_size_m)[0]
    assert near.sum() > 0.8 * len(seen)  # all of it: 0.89 (the voxel grids differ); learned: 0.07


def test_paper_preset_fills_only_the_fields_left_at_the_model_default():
    user = yard_params(region={"ground_refit_frames": 3}, orientation={"history_frames": 20})
    params = PaperPipeline(user).params
    assert params.region.ground_refit_frames == 3  # the user's, not the preset's 1
    assert params.orientation.history_frames == 20
    assert not params.background.enabled  # left at the model default: the preset's
    assert PaperPipeline(yard_params()).params.region.ground_refit_frames == 1
    assert build_pipeline(user, "default").params == user  # the model's defaults are the default method's
    assert with_preset(user, "paper") == params
    assert user.background.enabled and user.region.ground_refit_frames == 3  # input unchanged


@pytest.mark.parametrize("method", ["paper", "default", "articulated"])
def test_every_pipeline_reports_the_same_stage_latencies(method):
    pipeline = build_pipeline(yard_params("volvo_fh"), method)
    line = pipeline.process(frame_of(0, 0.0, {"l1": ground()})).to_json()
    assert list(line["latency_ms"]) == [*STAGES, "total"] == ["merge", "front_end", "candidates", "vehicles", "total"]
    assert pipeline.method == ("paper" if method == "paper" else "default")


def test_a_patch_arriving_while_the_previous_one_is_applied_is_not_lost():
    """update_params from another thread between taking the pending patch and building the stages
    must build on the patch being applied, not on the parameters before it."""
    pipeline = PaperPipeline(yard_params())
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


def test_paper_on_a_committed_sample_is_as_measured_before_the_pipelines_were_split():
    """The paper's pipeline is kept faithful: on the Volvo U-turn sample its errors against the true
    geometry are the ones measured with the single Pipeline class it came from (commit ae41a28,
    ``i2v-loc run --method paper``): both units in 43 of 50 frames, hitch RMSE 6.65 deg, the trailer
    within 4 m of the truth in 46 frames (median error 0.108 m), and 23 reports of a false vehicle's
    trailer. Any change to a stage's paper behaviour moves these figures."""
    rec = open_recording(REPO / "samples" / "volvo_fh_u_turn")
    pipeline = build_pipeline(load_params(rec.sensors_file), "paper")
    states = [pipeline.process(frame).to_json() for frame in rec.frames()]
    truth = rec.ground_truth()
    both, errors = hitch_errors(states, truth)
    assert both == 43
    assert np.sqrt(np.mean(np.square(errors))) == pytest.approx(6.65, abs=0.01)
    trailer_errors = [
        np.hypot(*np.subtract(v["trailer"]["center"][:2], g["trailer"]["center"][:2]))
        for state, gt in zip(states, truth)
        for g in gt["vehicles"]
        for v in state["vehicles"]
        if v["trailer"]
    ]
    matched = [e for e in trailer_errors if e < 4.0]
    assert len(matched) == 46 and len(trailer_errors) - len(matched) == 23  # a false vehicle 25-31 m away
    assert np.median(matched) == pytest.approx(0.108, abs=0.002)
