"""Service building blocks without a server: parameters store, auth, hub, sources, sensor stats."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from i2v_loc.params import Params, deep_merge, load_params
from i2v_loc.recording import SensorScans, write_recording
from i2v_loc.sources import ReplaySource, SourceError, open_source
from service.auth import HOW_TO_SET, AuthConfig, TokenError, bearer_from_header, load_token
from service.hub import Hub, Message
from service.params_store import ParamStore, PatchRejected, UnknownVersion, merge_patch_diff
from service.runner import SensorStats, foreground_xy


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
