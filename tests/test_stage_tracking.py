"""Tracking stage: SORT with a constant-velocity Kalman filter and Hungarian assignment."""

import numpy as np
import pytest

from i2v_loc.params import TrackingParams
from i2v_loc.stages.tracking import Detection, Tracker


def det(kind, x, y, group=0):
    return Detection(kind, "man_tgx", group, np.array([x, y, 1.0]))


def test_crossing_tracks_keep_their_ids():
    tracker = Tracker(TrackingParams(min_hits=1))
    ids_a, ids_b = set(), set()
    for k in range(40):
        t = k * 0.1
        a = det("trailer", -4 + 2.0 * t, -4 + 2.0 * t, group=0)  # diagonal up-right
        b = det("trailer", -4 + 2.0 * t, 4 - 2.0 * t, group=1)  # diagonal down-right, crosses at t = 2 s
        result = tracker.process([a, b], t)
        by_y = sorted(result.tracks, key=lambda tr: tr.detection.center[1])
        if k < 19:
            ids_a.add(by_y[0].track_id), ids_b.add(by_y[1].track_id)
        elif k > 21:
            ids_a.add(by_y[1].track_id), ids_b.add(by_y[0].track_id)
    assert len(ids_a) == 1 and len(ids_b) == 1 and ids_a != ids_b


def test_gate_min_hits_and_death():
    tracker = Tracker(TrackingParams(min_hits=3, max_age_frames=2, max_distance_m=1.0))
    for k in range(3):
        result = tracker.process([det("truck", 0.5 * k, 0)], 0.1 * k)
    assert [t.track_id for t in result.tracks] == [1]  # confirmed at the third hit
    # a jump beyond the 1 m gate starts a new track instead of moving the old one
    result = tracker.process([det("truck", 10.0, 0)], 0.3)
    assert result.tracks == [] and len(tracker.tracks) == 2
    for k in range(3):
        tracker.process([], 0.4 + 0.1 * k)
    assert tracker.tracks == []


def test_truck_and_trailer_of_one_cluster_share_a_vehicle_id_and_kinds_do_not_mix():
    tracker = Tracker(TrackingParams(min_hits=1))
    result = tracker.process(
        [det("truck", 0, 0, group=0), det("trailer", -0.5, 0, group=0), det("truck", 20, 0, group=1)], 0.0
    )
    by_id = {t.track_id: t for t in result.tracks}
    assert by_id[1].vehicle_id == by_id[2].vehicle_id != by_id[3].vehicle_id
    # the truck detection is closer to the trailer track than to the truck track: kinds must not swap
    result = tracker.process([det("truck", -0.4, 0, group=0), det("trailer", -0.1, 0, group=0)], 0.1)
    kinds = {t.track_id: t.kind for t in result.tracks}
    assert kinds == {1: "truck", 2: "trailer"}
    assert tracker.tracks[0].position[0] == pytest.approx(-0.4, abs=0.35)
