"""``bench --service`` drives the real service: every state it sends carries the time its frame
came in and the time it was sent (no timing assertions)."""

from __future__ import annotations

from conftest import SAMPLES

from i2v_loc.commands.bench_service import bench_service


def test_service_bench_measures_every_message_from_frame_in_to_send_and_receipt():
    figures = bench_service(SAMPLES / "twizy_single_turn", "default", n_clients=3, seconds=2.0, warmup_s=1.0)
    assert figures["clients"] == 3 and figures["messages_per_client_min"] >= 1
    assert figures["messages"] >= 3 * figures["messages_per_client_min"]
    # one wall clock: a message is sent after its frame came in and received after it was sent
    assert 0 < figures["frame_to_send_ms_p50"] <= figures["frame_to_client_ms_p50"]
