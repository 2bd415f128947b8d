"""Service building blocks without a server: parameters store, auth, hub, sources, sensor stats."""

from __future__ import annotations

import asyncio
import json

import numpy as np
import pytest

from i2v_loc.commands.serve import format_status
from i2v_loc.frame import Frame, SensorScan
from i2v_loc.params import Params, ParamsError, apply_patch, deep_merge, load_params
from i2v_loc.recording import SensorScans, write_recording
from i2v_loc.sources import ReplaySource, SourceError, open_source
from i2v_loc.stages.vehicle_start import Background
from service import params_store
from service.app import parse_flag
from service.auth import HOW_TO_SET, AuthConfig, TokenError, bearer_from_header, load_token
from service.core import build_service
from service.hub import Hub, Message
from service.metrics import ServiceMetrics
from service.params_store import ParamsNotSaved, ParamStore, PatchRejected, UnknownVersion, merge_patch_diff
from service.runner import PipelineRunner, SensorStats, foreground_xy


def _tiny_recording(path, frames=3, rate_hz=10):
    scans = {
        name: SensorScans(
            range_mm=np.full((frames, 2, 8), 5000, dtype=np.uint16),
            stamp_ns=np.arange(frames) * 1_000_000_000 // rate_hz + 7_000_000 * i,
            column_time_ns=np.arange(8) * 12_500_000,
            beam_altitude_deg=[1.0, -1.0],
            beam_azimuth_offset_deg=[0.0, 0.0],
        )
        for i, name in enumerate(["l1", "l2"])
    }
    gt = [{"frame": k, "stamp_s": k / rate_hz, "vehicles": [], "distractors": []} for k in range(frames)]
    meta = {"generator": "test", "rate_hz": rate_hz, "sensors": [{"name": "l1"}, {"name": "l2"}]}
    write_recording(path, meta, scans, gt, "sensors: []\n", "sensors: []\n")
    return path


# ------------------------------------------------------------------ parameters


def test_merge_patch_diff_round_trips_through_deep_merge():
    old = {"a": {"b": 1, "c": 2}, "d": [1, 2], "e": "x", "gone": {"k": 1}}
    new = {"a": {"b": 1, "c": 3, "n": 4}, "d": [1, 2, 3], "e": "x", "added": 5}
    patch = merge_patch_diff(old, new)
    assert patch == {"a": {"c": 3, "n": 4}, "d": [1, 2, 3], "gone": None, "added": 5}
    assert deep_merge(old, patch) == new


def test_store_versions_persists_and_rolls_back(tmp_path):
    file = tmp_path / "p.yaml"
    seen = []
    store = ParamStore(Params(), file, on_change=seen.append)
    v1 = store.patch({"clustering": {"tolerance_m": 0.3}})
    v2 = store.patch({"tracking": {"max_distance_m": 2.5}})
    assert (v1.version, v2.version) == (1, 2)
    assert load_params(file).tracking.max_distance_m == 2.5
    back = store.rollback(0)
    assert back.version == 3 and back.patch == {"clustering": {"tolerance_m": 0.7}, "tracking": {"max_distance_m": 1.0}}
    assert store.params == Params()
    assert load_params(file).clustering.tolerance_m == 0.7
    assert [v.version for v in seen] == [1, 2, 3]
    assert [h["source"] for h in store.history()] == ["start", "patch", "patch", "rollback to 0"]
    with pytest.raises(UnknownVersion, match="no parameter version 9"):
        store.rollback(9)


def test_store_rejects_invalid_patch_and_changes_nothing(tmp_path):
    file = tmp_path / "p.yaml"
    store = ParamStore(Params(), file)
    with pytest.raises(PatchRejected) as info:
        store.patch({"clustering": {"tolerance_m": 9.0, "min_points": 5}})
    (error,) = info.value.errors
    assert error["field"] == "clustering.tolerance_m" and error["value"] == 9.0 and "5" in error["allowed"]
    with pytest.raises(PatchRejected, match="JSON object"):
        store.patch([1, 2])
    assert store.version == 0 and store.params.clustering.min_points == 10 and not file.exists()


# ------------------------------------------------------------------ auth


def test_auth_decisions():
    open_reads = AuthConfig("s3cret")
    assert open_reads.check(None, write=False).allowed
    assert open_reads.check(None, write=True).status == 401
    assert open_reads.check("wrong", write=True).status == 403
    assert open_reads.check("s3cret", write=True).allowed
    closed = AuthConfig("s3cret", require_token_for_reads=True)
    assert closed.check(None, write=False).status == 401 and closed.check("s3cret", write=False).allowed
    no_token = AuthConfig(None).check("anything", write=True)
    assert no_token.status == 403 and no_token.message == HOW_TO_SET and "I2V_LOC_API_TOKEN" in HOW_TO_SET
    assert "s3cret" not in repr(open_reads)


def test_token_sources(tmp_path):
    file = tmp_path / "token"
    file.write_text("  abc  \n")
    assert load_token(file, environ={"I2V_LOC_API_TOKEN": "env"}) == "abc"
    assert load_token(None, environ={"I2V_LOC_API_TOKEN": "env"}) == "env"
    assert load_token(None, environ={}) is None
    with pytest.raises(TokenError, match="cannot read"):
        load_token(tmp_path / "missing")
    (tmp_path / "empty").write_text("\n")
    with pytest.raises(TokenError, match="empty"):
        load_token(tmp_path / "empty")
    assert bearer_from_header("Bearer  xyz ") == "xyz"
    assert bearer_from_header("Basic xyz") is None and bearer_from_header(None) is None


# ------------------------------------------------------------------ hub


def test_slow_client_slot_keeps_only_the_newest_state():
    async def scenario():
        drops = []
        hub = Hub(on_drop=lambda: drops.append(1))
        hub.bind(asyncio.get_running_loop())
        slow, fast = hub.add(want_points=False), hub.add(want_points=True)
        received = []
        for k in range(5):
            hub.publish(Message("state", f'{{"frame":{k}}}', f'{{"frame":{k},"foreground":1}}'))
            await asyncio.sleep(0)  # the loop delivers the message
            received.append(await fast.next_text())
        hub.publish(Message("params", '{"type":"params"}'))
        await asyncio.sleep(0)
        # the slow client took nothing: it gets the parameter message, then only the newest state
        return received, [await slow.next_text(), await slow.next_text()], slow.dropped, len(drops)

    received, slow_got, slow_dropped, drops = asyncio.run(scenario())
    assert received == [f'{{"frame":{k},"foreground":1}}' for k in range(5)]
    assert slow_got == ['{"type":"params"}', '{"frame":4}']
    assert slow_dropped == 4 and drops == 4


# ------------------------------------------------------------------ sources


def test_replay_loop_keeps_time_monotonic(tmp_path):
    source = ReplaySource(_tiny_recording(tmp_path / "rec"), loop=True)
    assert source.n_frames is None and source.rate_hz == 10 and source.duration_s == pytest.approx(0.3)
    first, wrapped = source.frame(1), source.frame(4)  # frame 4 = frame 1 of the second lap
    assert wrapped.index == 4
    for name in ("l1", "l2"):
        assert wrapped.scans[name].stamp_s == pytest.approx(first.scans[name].stamp_s + 0.3)
        np.testing.assert_array_equal(wrapped.scans[name].points, first.scans[name].points)
    once = ReplaySource(tmp_path / "rec", loop=False)
    assert once.n_frames == 3
    with pytest.raises(IndexError):
        once.frame(3)


def test_a_looping_replay_starts_the_scene_over_each_lap(tmp_path):
    """Each lap the vehicles jump back to their start: the service's pipeline forgets them then
    (a track left at the dock had folded onto the vehicle's next lap), and keeps its map."""
    source = ReplaySource(_tiny_recording(tmp_path / "rec"), loop=True)
    assert [k for k in range(10) if source.starts_lap(k)] == [3, 6, 9]
    assert not any(ReplaySource(tmp_path / "rec").starts_lap(k) for k in range(3))

    class Forgetful(FakePipeline):
        seen, forgotten = -1, []

        def forget_vehicles(self) -> None:
            self.forgotten.append(self.seen)

        def process(self, frame: Frame) -> FakeResult:
            self.seen = frame.index
            return super().process(frame)

    pipeline = Forgetful(Params())
    runner = PipelineRunner(source, pipeline, Hub(), ServiceMetrics(), [], realtime=False)
    for k in range(7):
        runner._step(k)
    assert pipeline.forgotten == [2, 5]  # before frames 3 and 6, after the lap's last frame


def test_forgetting_vehicles_keeps_the_map_and_the_ids_counting():
    from hinged_points import vehicle_points
    from test_articulated_pipeline import SENSORS, volvo

    from i2v_loc.pipelines import build_pipeline

    pipeline = build_pipeline(Params(), "default")
    tracker = pipeline.tracker
    for k in range(4):
        points = vehicle_points(volvo(), 2.0, 3.0, 0.3, np.radians(20.0), sensors=SENSORS, seed=k)
        reports = tracker.process(points, lambda x, y: 0.0, 0.1 * k, background=Background.LEARNING)
    assert [r.id for r in reports] == [1] and tracker.tracks
    background = pipeline.background
    pipeline.forget_vehicles()
    assert tracker.tracks == [] and tracker.starts.seeds == [] and pipeline.background is background
    for k in range(4):
        points = vehicle_points(volvo(), -6.0, -3.0, 1.0, np.radians(-15.0), sensors=SENSORS, seed=k)
        reports = tracker.process(points, lambda x, y: 0.0, 1.0 + 0.1 * k, background=Background.LEARNING)
    assert [r.id for r in reports] == [2]
    paper = build_pipeline(Params(), "paper")
    old = paper.tracker
    paper.forget_vehicles()
    assert paper.tracker is not old and paper.tracker.tracks == []


def test_open_source_errors(tmp_path):
    with pytest.raises(SourceError, match="unknown source"):
        open_source("camera:1")
    with pytest.raises(SourceError, match="needs a recording directory"):
        open_source("replay:")
    with pytest.raises(SourceError, match="no such recording"):
        open_source(f"replay:{tmp_path / 'nope'}")
    assert open_source(f"replay:{_tiny_recording(tmp_path / 'rec')}", loop=True).n_frames is None


def test_sensor_stats_rate_stamp_and_drops():
    stats = SensorStats(["l1", "l2"])
    for k in range(11):
        present = {"l1": 0.1 * k} if k % 2 else {"l1": 0.1 * k, "l2": 0.1 * k}
        faults = {"l1": "empty"} if k == 10 else {}
        stats.observe(present, faults, ["l1", "l2"], now_s=100.0 + 0.1 * k)
    snap = stats.snapshot(now_s=101.0)
    assert snap["l1"]["rate_hz"] == pytest.approx(10.0)
    assert snap["l2"]["rate_hz"] == pytest.approx(5.0)  # every other frame
    assert snap["l1"]["last_stamp_s"] == pytest.approx(1.0) and snap["l2"]["last_stamp_s"] == pytest.approx(1.0)
    assert snap["l2"]["drops"] == 5 and snap["l1"]["drops"] == 1 and snap["l1"]["status"] == "fault:empty"
    assert stats.snapshot(now_s=110.0)["l2"]["status"] == "stale"


def test_foreground_points_are_decimated_to_the_cap():
    class Result:
        foreground = np.arange(3000 * 3, dtype=float).reshape(-1, 3)

    xy = foreground_xy(Result(), cap=1000)
    assert xy.shape == (1000, 2) and xy[1, 0] == 9.0  # every third point, x and y only
    assert foreground_xy(object(), cap=1000) is None


# ------------------------------------------------------------------ the pipeline thread (fakes, no server)


class FakeSource:
    rate_hz = 10.0
    sensor_names: list = []

    def __init__(self, n_frames: int):
        self.n_frames = n_frames

    def frame(self, k: int) -> Frame:
        return Frame(index=k, scans={})

    def starts_lap(self, k: int) -> bool:
        return False


class FakeResult:
    def __init__(self, state: dict):
        self.state = state

    def to_json(self) -> dict:
        return dict(self.state)


class FakePipeline:
    """Returns ``states[k]`` for frame k; refuses parameters with tracking.max_age_frames == 13
    (standing in for a check only the pipeline makes, like the background grid size)."""

    method = "fake"

    def __init__(self, params: Params, states: dict | None = None):
        self.params = params
        self.states = states or {}
        self.patches: list[dict] = []

    def update_params(self, patch: dict) -> Params:
        new = apply_patch(self.params, patch)
        if new.tracking.max_age_frames == 13:
            raise ParamsError("tracking.max_age_frames = 13: refused by the pipeline")
        self.patches.append(patch)
        self.params = new
        return new

    def process(self, frame: Frame) -> FakeResult:
        return FakeResult({"type": "state", "frame": frame.index, **self.states.get(frame.index, {})})


def _runner(pipeline, n_frames: int) -> PipelineRunner:
    return PipelineRunner(FakeSource(n_frames), pipeline, Hub(), ServiceMetrics(), [], realtime=False)


def test_a_frame_failing_after_the_pipeline_is_skipped_and_the_thread_goes_on():
    states = {
        2: {"vehicles": [{"id": 1, "note": object()}]},  # not JSON: fails when serialised
        3: {"vehicles": [{"id": 1, "hitch_deg": np.array([np.nan, 2.5])}]},
    }  # numpy NaN: becomes null
    runner = _runner(FakePipeline(Params(), states), n_frames=6)
    runner.start()
    try:
        for _ in range(200):
            if runner.finished:
                break
            runner._stop.wait(0.01)
    finally:
        runner.stop()
    assert runner.finished and runner.error is None
    assert runner.frames_processed == 5 and runner.frames_dropped["pipeline_error"] == 1
    assert runner.last_frame_error["frame"] == 2 and runner.last_frame_error["reason"] == "pipeline_error"
    assert "TypeError" in runner.last_frame_error["error"]
    assert runner.latest["frame"] == 5 and runner.status()["last_frame_error"]["frame"] == 2
    metrics = runner.metrics.render().decode()
    assert 'i2v_loc_frames_dropped_total{reason="pipeline_error"} 1.0' in metrics


def test_numpy_nan_in_a_state_is_sent_as_null():
    runner = _runner(FakePipeline(Params(), {0: {"hitch_deg": np.array([np.nan, 2.5]), "yaw": np.float32("inf")}}), 1)
    runner._step(0)
    assert runner.frames_dropped["pipeline_error"] == 0
    assert runner.latest["hitch_deg"] == [None, 2.5] and runner.latest["yaw"] is None


def test_the_pipeline_gets_the_stores_whole_parameters_or_nothing_changes(tmp_path):
    file = tmp_path / "p.yaml"
    pipeline = FakePipeline(Params())
    runner = _runner(pipeline, n_frames=1)
    store = ParamStore(Params(), file, on_change=runner.submit)
    store.patch({"vehicles": {"twizy": None}, "clustering": {"tolerance_m": 0.4}})
    assert pipeline.params == store.params and "twizy" not in pipeline.params.vehicles
    with pytest.raises(PatchRejected, match="the pipeline refused") as info:
        store.patch({"tracking": {"max_age_frames": 13}})
    assert info.value.errors[0]["message"].startswith("tracking.max_age_frames = 13")
    assert store.version == 1 and len(store.history()) == 2 and load_params(file).tracking.max_age_frames != 13
    assert pipeline.params == store.params
    # Even if the pipeline's copy had drifted, the next version brings it back to the store's exactly.
    pipeline.params = apply_patch(pipeline.params, {"region": {"z_max_m": 3.0}})
    store.patch({"tracking": {"max_age_frames": 7}})
    assert pipeline.params == store.params
    runner._step(0)
    assert runner.params_version == 2 and runner.latest["params_version"] == 2


def test_the_real_pipeline_refusal_is_a_422_not_a_stuck_version(tmp_path):
    from test_service_support import sample_recording

    source = ReplaySource(sample_recording(), loop=True)
    service = build_service(source, load_params(source.sensors_file), tmp_path / "p.yaml", method="default")
    assert service.runner.method == "default" and service.health()["method"] == "default"
    assert service.store.params == service.runner.pipeline.params  # version 0 = what the method runs with
    with pytest.raises(PatchRejected, match="background"):
        service.store.patch({"background": {"enabled": True, "voxel_size_m": 0.05, "max_voxels": 1000}})
    assert service.store.version == 0 and service.runner.pipeline.params == service.store.params
    accepted = service.store.patch({"vehicles": {"twizy": None}})
    assert service.runner.pipeline.params == accepted.params and "twizy" not in accepted.params.vehicles


def test_history_always_keeps_version_0(monkeypatch):
    monkeypatch.setattr(params_store, "HISTORY_LIMIT", 4)
    store = ParamStore(Params())
    for k in range(10):
        store.patch({"tracking": {"max_age_frames": 20 + k}})
    versions = [h["version"] for h in store.history()]
    assert versions == [0, 8, 9, 10]
    assert store.rollback(0).params == Params()
    with pytest.raises(UnknownVersion):
        store.get(3)


def test_a_failing_save_keeps_the_change_in_force_and_says_so(tmp_path):
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("x")
    seen = []
    store = ParamStore(Params(), blocker / "p.yaml", on_change=seen.append)
    with pytest.raises(ParamsNotSaved, match="version 1 is in force but could not be written") as info:
        store.patch({"tracking": {"max_age_frames": 9}})
    assert info.value.version.version == 1 and store.version == 1 and [v.version for v in seen] == [1]
    assert store.params.tracking.max_age_frames == 9


def test_null_for_a_whole_section_is_refused_null_inside_one_is_not():
    store = ParamStore(Params())
    for section in ("sensors", "vehicles", "clustering"):
        with pytest.raises(PatchRejected, match="whole section") as info:
            store.patch({section: None})
        assert info.value.errors[0]["field"] == section
    assert store.version == 0
    store.patch({"vehicles": {"twizy": None}, "clustering": {"tolerance_m": None}})
    assert "twizy" not in store.params.vehicles and len(store.params.sensors) == len(Params().sensors)
    assert store.params.clustering.tolerance_m == Params().clustering.tolerance_m  # null inside: the default


def test_newest_params_message_replaces_an_untaken_one():
    async def scenario():
        drops = []
        hub = Hub(on_drop=lambda: drops.append(1))
        hub.bind(asyncio.get_running_loop())
        client = hub.add(want_points=False)
        for version in (1, 2, 3):
            hub.publish(Message("params", json.dumps({"type": "params", "version": version})))
        hub.publish(Message("state", '{"frame":7}'))
        await asyncio.sleep(0)
        got = [json.loads(await client.next_text()) for _ in range(2)]
        return got, client.params_dropped, client.dropped, len(drops), hub.stats()

    got, params_dropped, dropped, drops, stats = asyncio.run(scenario())
    assert got == [{"type": "params", "version": 3}, {"frame": 7}]
    assert params_dropped == 2 and dropped == 0 and drops == 2 and stats[0]["params_dropped"] == 2


def test_points_flag_parsing():
    assert [parse_flag(w) for w in ("true", "1", "Yes", "on")] == [True] * 4
    assert [parse_flag(w) for w in (None, "", "false", "0", "off")] == [False] * 5
    assert parse_flag("maybe") is None


def test_sim_source_rejects_unknown_scenario_and_vehicle_before_simulating(tmp_path):
    cache = tmp_path / "cache"
    with pytest.raises(SourceError, match=r"unknown scenario 'nope' .*known: .*docking"):
        open_source("sim:nope", cache_dir=cache)
    with pytest.raises(SourceError, match=r"unknown vehicle 'vw_golf'.*man_tgx"):
        open_source("sim:docking", vehicle="vw_golf", cache_dir=cache)
    assert not cache.exists()  # the simulator never started


def test_status_line_names_the_method():
    line = format_status(
        {"method": "default", "frame_rate_hz": 9.8, "frame": 12, "frames_dropped": {"late": 2}, "params_version": 1},
        ws_clients=3,
    )
    assert line.startswith("default |") and "9.8 fps" in line and "dropped 2" in line


def test_metrics_have_no_created_series():
    metrics = ServiceMetrics()
    metrics.frames_processed.inc()
    metrics.stage_latency.labels("total").observe(0.01)
    text = metrics.render().decode()
    assert "i2v_loc_frames_processed_total 1.0" in text and "_created" not in text


# ------------------------------------------------------------------ change log, body limits, origins, health


def test_every_change_is_logged_with_source_old_and_new_values(tmp_path, caplog):
    store = ParamStore(Params(), tmp_path / "p.yaml")
    token = AuthConfig("s3cret-token")
    with caplog.at_level("INFO", logger="i2v_loc.service"):
        store.patch({"clustering": {"tolerance_m": 0.3}}, source=f"token {token.token_id}")
        store.rollback(0, source=f"token {token.token_id}")
    lines = [r.getMessage() for r in caplog.records]
    assert lines == [
        f"parameter version 1 (token {token.token_id}): clustering.tolerance_m: 0.7 -> 0.3",
        f"parameter version 2 (rollback to 0 by token {token.token_id}): clustering.tolerance_m: 0.3 -> 0.7",
    ]
    assert len(token.token_id) == 8 and "s3cret" not in "".join(lines)
    assert store.history()[1]["source"] == f"token {token.token_id}"


def test_body_reading_stops_at_the_limit():
    from fastapi import HTTPException
    from starlette.requests import Request

    from service.app import _read_limited

    sent = []

    async def endless_body():  # a client that never stops sending, with no Content-Length
        sent.append(1)
        return {"type": "http.request", "body": b"x" * 65536, "more_body": True}

    request = Request({"type": "http", "method": "PATCH", "headers": []}, endless_body)
    with pytest.raises(HTTPException) as err:
        asyncio.run(_read_limited(request, 1_000_000))
    assert err.value.status_code == 413 and len(sent) == 1_000_000 // 65536 + 1


def test_nesting_depth():
    from service.app import nesting_depth

    assert [nesting_depth(v) for v in (1, {}, {"a": [1, {"b": 2}]}, [[[]]])] == [0, 1, 3, 3]
    deep: dict = {}
    node = deep
    for _ in range(5000):  # no recursion: deeper than Python's stack
        node["a"] = {}
        node = node["a"]
    assert nesting_depth(deep) == 5001


def test_websocket_origins():
    auth = AuthConfig(allowed_origins=("https://ops.example.com/",))
    assert auth.origin_allowed(None, "yard:8000")  # not a browser
    assert auth.origin_allowed("http://yard:8000", "yard:8000")
    assert auth.origin_allowed("https://yard:8000", "yard:8000", "wss")
    assert not auth.origin_allowed("https://yard:8000", "yard:8000", "ws")
    assert auth.origin_allowed("https://OPS.example.com", "yard:8000")
    assert not auth.origin_allowed("http://evil.example", "yard:8000")


class _Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_health_degrades_with_the_reason_when_frames_or_messages_are_dropped(tmp_path):
    rec = _tiny_recording(tmp_path / "rec", frames=50)
    clock = _Clock()

    class Nothing:
        params = Params()
        method = "fake"

        def process(self, frame):
            raise AssertionError("not called")

    service = build_service(
        ReplaySource(rec, loop=True), Params(), pipeline_factory=lambda p, m: Nothing(), clock=clock
    )
    runner = service.runner
    names = runner.expected_sensors

    def processed(n):
        for _ in range(n):
            clock.t += 0.1
            scans = {
                name: SensorScan(name, clock.t, np.zeros((1, 3), np.float32), np.zeros(1, np.float32)) for name in names
            }
            runner._record(Frame(index=0, scans=scans), {"vehicles": []}, clock.t)

    processed(20)
    health = service.health()
    assert (health["status"], health["reasons"]) == ("ok", [])
    runner._drop("late", 5)  # 5 of the last 25 frames
    health = service.health()
    assert health["status"] == "degraded" and health["reasons"] == [
        "20% of the last frames dropped (late or unreadable)"
    ]
    processed(40)  # 5 of the last 65: below the threshold
    assert service.health()["status"] == "ok"

    slow = service.hub.add(want_points=False)  # a client that never takes its messages
    for k in range(4):
        service.hub._deliver(Message("state", f'{{"frame":{k}}}'))
    health = service.health()
    assert slow.dropped == 3
    assert health["status"] == "degraded" and health["reasons"] == [
        "75% of the recent WebSocket messages dropped for slow clients"
    ]


def test_unknown_keys_are_refused_before_the_model_is_validated(tmp_path, monkeypatch):
    store = ParamStore(Params(), tmp_path / "p.yaml")
    monkeypatch.setattr(params_store, "apply_patch", lambda *a: pytest.fail("the model was validated"))
    patch = {"clustering": {f"k{i}": 1 for i in range(100_000)}, "nonsense": {}, "tracking": {"min_hits": 2}}
    with pytest.raises(PatchRejected) as info:
        store.patch(patch)
    errors = info.value.errors
    assert len(errors) == 20 and [e["field"] for e in errors[:3]] == ["nonsense", "clustering.k0", "clustering.k1"]
    assert str(info.value).startswith("patch: 100001 unknown keys: nonsense, clustering.k0, clustering.k1, ")
    assert str(info.value).count("(and 99981 more)") == 1
    assert store.version == 0 and not (tmp_path / "p.yaml").exists()


def test_an_oversized_list_or_catalogue_is_refused_before_validation(tmp_path, monkeypatch):
    store = ParamStore(Params(), tmp_path / "p.yaml")
    monkeypatch.setattr(params_store, "apply_patch", lambda *a: pytest.fail("the model was validated"))
    with pytest.raises(PatchRejected, match="sensors holds 20000 entries, at most 64 are allowed"):
        store.patch({"sensors": [{"name": f"s{i}"} for i in range(20000)]})
    with pytest.raises(PatchRejected, match="vehicles holds 101 entries, at most 100 are allowed"):
        store.patch({"vehicles": {f"v{i}": {} for i in range(101)}})


def test_health_fails_with_the_reason_when_no_frame_can_be_read(tmp_path):
    rec = _tiny_recording(tmp_path / "rec", frames=5)
    service = build_service(ReplaySource(rec, loop=True), Params(), pipeline_factory=lambda p, m: None)
    runner = service.runner
    for k in range(19):
        runner._skip(k, "source_error", OSError("disk gone"))
    assert service.health()["status"] == "starting"
    runner._skip(19, "source_error", OSError("disk gone"))
    health = service.health()
    assert health["status"] == "failed" and health["ready"] is False
    assert health["reasons"] == ["no frame processed, 20 skipped; last error: OSError: disk gone"]


def test_every_client_gets_the_one_serialised_message():
    hub = Hub()
    plain, with_points = hub.add(want_points=False), hub.add(want_points=True)
    message = Message("state", '{"frame":1}', '{"frame":1,"foreground":{"xy":[1,2]}}')
    hub._deliver(message)

    async def take(client):
        return await client.next_text()

    assert asyncio.run(take(plain)) is message.plain
    assert asyncio.run(take(with_points)) is message.with_points
