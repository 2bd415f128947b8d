"""What a yard's pole sensor (tests/car_mounted.py ``POLE``: an OS1-32 6 m up, ray-cast scenes on
flat ground) shows the service from its start, while the map is still learned: things that stand
there from the first sweep."""

from __future__ import annotations

import math

import car_mounted as cm
import pytest

from i2v_loc.params import Params
from i2v_loc.sim import meshes as m

X, Y, YAW = -6.33, -7.63, math.radians(142.5)  # 10 m from the pole, a pole of the yard's between


def _lamp_post() -> list:
    return [m.cylinder((-6.32, -8.75, 2.5), 0.12, 5.0, surface="pole")]


def test_a_container_before_a_parked_trailer_is_no_tractor_where_rays_pass_over_it():
    """A MAN's trailer parked 10 m from the pole, a 10-ft container (2.6 m high) 0.7 m off its rear:
    from 6 m up nothing below about 1 m shows within 15 m, so no face shows it reaching the ground,
    and the rays cross the 0.7 m between it and the trailer. A MAN's cab (3.3 m high) fitted on
    it had passed every check (13 of 60 such scenes, ``scripts/car_mounted_scenes.py
    yard-parked``); the rays that pass over the container cross that cab's box."""
    trailer = Params().vehicles["man_tgx"].trailer
    along = -(trailer.length_m / 2 + 0.71 + 2.99 / 2)
    container = cm.container(X + along * math.cos(YAW), Y + along * math.sin(YAW), YAW)
    assert not any(cm.yard_reports(cm.parked_trailer("man_tgx", X, Y, YAW) + container + _lamp_post(), 4))


@pytest.mark.parametrize("name", ["man_tgx", "volvo_fh"])
def test_a_tractor_and_trailer_standing_there_from_the_start_is_found(name):
    """The same place, a catalogue vehicle standing straight: its cab's roof is where its model's is,
    and it is reported from the third sweep."""
    reports = cm.yard_reports(cm.articulated(name, X, Y, YAW) + _lamp_post(), 4)
    assert [len(r) for r in reports] == [0, 0, 1, 1]
    assert reports[-1][0]["vehicle"] == name and abs(reports[-1][0]["hitch_deg"]) < 2.0
