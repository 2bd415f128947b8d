"""The live service over real HTTP and WebSocket clients (uvicorn on a free loopback port),
replaying the committed sample recording through the real pipeline."""

from __future__ import annotations

import asyncio
import base64
import json
import os
import re
import socket
import threading
import time

import httpx
import pytest
import websockets
import yaml
from test_service_support import TOKEN, next_state, sample_recording, serve, wait_for

from i2v_loc.params import json_schema, load_params

pytestmark = pytest.mark.timeout(60)

STATE_KEYS = {"type", "frame", "stamp_s", "latency_ms", "faults", "dropped", "clusters", "vehicles"}
AUTH = {"Authorization": f"Bearer {TOKEN}"}


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    params_file = tmp_path_factory.mktemp("params") / "params.yaml"
    # The published method: its clustering follows clustering.tolerance_m (the patch tests use it).
    server, service = serve(sample_recording(), params_file=params_file, send_buffer_bytes=32768, method="paper")
    with server:
        wait_for(lambda: service.runner.frames_processed >= 2, what="the first frames")
        yield server, service, params_file


@pytest.fixture
def client(live):
    server = live[0]
    with httpx.Client(base_url=server.url, timeout=10) as c:
        yield c


def _ws(server, points=False):
    return websockets.connect(server.ws_url + "/ws/states" + ("?points=true" if points else ""), max_size=2**24)


# ------------------------------------------------------------------ reads


def test_health_state_sensors_vehicles(client, live):
    _, service, _ = live
    sensors = service.runner.source.sensor_names
    health = client.get("/api/v1/health").json()
    assert health["live"] is True and health["ready"] is True and health["status"] in ("ok", "degraded")
    assert set(health["sensors"]) >= set(sensors) and health["frames_processed"] >= 2
    state = client.get("/api/v1/state").json()
    assert STATE_KEYS <= set(state) and state["type"] == "state" and state["params_version"] == 0
    listed = client.get("/api/v1/sensors").json()["sensors"]
    by_name = {s["name"]: s for s in listed}
    for name in sensors:  # the sample recording holds every sensor in every frame
        assert by_name[name]["last_stamp_s"] is not None and by_name[name]["drops"] == 0
        assert set(by_name[name]["position"]) == {"x_m", "y_m", "z_m", "yaw_deg"}

    # /vehicles is the vehicles of the latest state (asked until both answers are of one frame)
    def same_frame():
        state, vehicles = client.get("/api/v1/state").json(), client.get("/api/v1/vehicles").json()
        return (state, vehicles) if state["frame"] == vehicles["frame"] else None

    state, vehicles = wait_for(same_frame, what="state and vehicles of one frame")
    assert vehicles["vehicles"] == state["vehicles"] and vehicles["stamp_s"] == state["stamp_s"]
    missing = client.get("/api/v1/vehicles/987654")
    assert missing.status_code == 404 and "no vehicle with id 987654" in missing.json()["detail"]


def test_vehicle_found_by_id(client):
    state = wait_for(lambda: (s := client.get("/api/v1/state").json())["vehicles"] and s, what="a vehicle in the state")
    vid = state["vehicles"][0]["id"]
    found = wait_for(
        lambda: (r := client.get(f"/api/v1/vehicles/{vid}")).status_code == 200 and r.json(), what=f"vehicle {vid}"
    )
    assert found["id"] == vid and "hitch_deg" in found and {"truck", "trailer"} <= set(found)


def test_params_and_schema(client, live):
    _, service, _ = live
    body = client.get("/api/v1/params").json()
    assert body["params"] == service.store.params.model_dump(mode="json")
    assert client.get("/api/v1/params/schema").json() == json_schema()
    history = client.get("/api/v1/params/history").json()
    assert history["versions"][0]["source"] == "start"


def test_openapi_docs_and_dashboard(client):
    spec = client.get("/openapi.json").json()
    assert {"/api/v1/state", "/api/v1/params", "/api/v1/params/rollback/{version}"} <= set(spec["paths"])
    assert "text/html" in client.get("/docs").headers["content-type"]
    page = client.get("/")
    assert page.status_code == 200 and '<canvas id="yard"' in page.text
    assert client.get("/static/app.js").status_code == 200


# ------------------------------------------------------------------ stream


def test_states_stream_at_the_sensor_rate(live):
    server, service, _ = live
    rate_hz = service.runner.source.rate_hz

    async def collect():
        async with _ws(server) as ws:
            t0 = time.monotonic()
            got = [await next_state(ws) for _ in range(12)]
            return got, time.monotonic() - t0

    states, elapsed_s = asyncio.run(collect())
    frames = [s["frame"] for s in states]
    assert all(b > a for a, b in zip(frames, frames[1:])), frames
    for a, b in zip(states, states[1:]):  # stamps advance by one sensor period per frame
        assert b["stamp_s"] - a["stamp_s"] == pytest.approx((b["frame"] - a["frame"]) / rate_hz, abs=0.02)
    # Real-time pacing: never more frames than the sensors delivered in that time.
    assert len(states) - 1 <= elapsed_s * rate_hz + 2
    assert all(STATE_KEYS <= set(s) and "foreground" not in s for s in states)


def test_points_are_opt_in_and_capped(live):
    server, service, _ = live

    async def one():
        async with _ws(server, points=True) as ws:
            return await next_state(ws, where=lambda m: "foreground" in m)

    state = asyncio.run(one())
    xy = state["foreground"]["xy"]
    assert len(xy) % 2 == 0 and 0 < len(xy) // 2 <= service.runner.points_cap


# ------------------------------------------------------------------ writes


def test_writes_need_the_right_token(client):
    missing = client.patch("/api/v1/params", json={"clustering": {"tolerance_m": 0.5}})
    assert missing.status_code == 401 and missing.headers["www-authenticate"] == "Bearer"
    wrong = client.patch(
        "/api/v1/params", json={"clustering": {"tolerance_m": 0.5}}, headers={"Authorization": "Bearer nope"}
    )
    assert wrong.status_code == 403
    assert client.post("/api/v1/params/rollback/0").status_code == 401
    assert client.get("/api/v1/params").json()["version"] == 0


def test_invalid_patch_gives_422_and_changes_nothing(client, live):
    _, service, params_file = live
    before = client.get("/api/v1/params").json()
    file_before = params_file.read_text()
    bad = client.patch("/api/v1/params", json={"clustering": {"tolerance_m": 50, "min_points": 3}}, headers=AUTH)
    assert bad.status_code == 422
    (error,) = bad.json()["errors"]
    assert error["field"] == "clustering.tolerance_m" and error["value"] == 50
    assert "<= 5.0" in error["allowed"] and "> 0.0" in error["allowed"]
    unknown = client.patch("/api/v1/params", json={"clustering": {"tolerance": 0.5}}, headers=AUTH)
    assert unknown.status_code == 422 and unknown.json()["errors"][0]["field"] == "clustering.tolerance"
    assert client.get("/api/v1/params").json() == before
    assert params_file.read_text() == file_before
    assert service.runner.pipeline.params == service.store.params and service.store.version == before["version"]


def test_malformed_requests_get_4xx_with_a_message(client):
    cases = [
        (dict(content=b"{not json", headers={**AUTH, "Content-Type": "application/json"}), 400, "not valid JSON"),
        (
            dict(content=b'{"region": {"x_min_m": NaN}}', headers={**AUTH, "Content-Type": "application/json"}),
            400,
            "finite",
        ),
        (dict(content=b"x=1", headers={**AUTH, "Content-Type": "text/plain"}), 415, "Content-Type"),
        (dict(content=b"", headers={**AUTH, "Content-Type": "application/json"}), 400, "empty body"),
        (dict(json=[1, 2], headers=AUTH), 422, "JSON object"),
    ]
    for kwargs, status, words in cases:
        response = client.patch("/api/v1/params", **kwargs)
        assert response.status_code == status and words in response.json()["detail"], response.text
    assert client.get("/api/v1/vehicles/abc").status_code == 422
    assert client.post("/api/v1/params/rollback/12345", headers=AUTH).status_code == 404
    assert client.get("/api/v1/health").json()["live"] is True


def test_valid_patch_changes_the_next_frame_and_rolls_back(client, live):
    server, service, params_file = live
    start_version = client.get("/api/v1/params").json()["version"]

    async def clusters_at(version, n=4):
        async with _ws(server) as ws:
            states = [await next_state(ws, where=lambda m: m["params_version"] == version) for _ in range(n)]
        return [len(s["clusters"]) for s in states]

    before = asyncio.run(clusters_at(start_version))
    response = client.patch(
        "/api/v1/params",
        headers={**AUTH, "Content-Type": "application/merge-patch+json"},
        content=json.dumps({"clustering": {"tolerance_m": 0.3}}),
    )
    assert response.status_code == 200, response.text
    version = response.json()["version"]
    assert version == start_version + 1
    after = asyncio.run(clusters_at(version))
    assert min(after) > max(before), (before, after)  # finer tolerance: objects fall apart
    assert service.runner.pipeline.params.clustering.tolerance_m == 0.3
    saved = yaml.safe_load(params_file.read_text())
    assert saved["clustering"]["tolerance_m"] == 0.3
    history = client.get("/api/v1/params/history").json()
    assert history["current"] == version and history["versions"][-1]["patch"] == {"clustering": {"tolerance_m": 0.3}}

    back = client.post(f"/api/v1/params/rollback/{start_version}", headers=AUTH)
    assert back.status_code == 200 and back.json()["version"] == version + 1
    default = service.store.get(start_version).params.clustering
    assert back.json()["params"]["clustering"] == default.model_dump(mode="json")
    assert load_params(params_file).clustering == default
    restored = asyncio.run(clusters_at(version + 1))
    assert max(restored) < min(after)


def test_a_sensor_disabled_over_rest_is_left_out_from_the_next_frame_and_said_so(client, live):
    server, service, _ = live
    start = client.get("/api/v1/params").json()
    sensors = [dict(s, enabled=s["name"] != "l2") for s in start["params"]["sensors"]]
    response = client.patch("/api/v1/params", json={"sensors": sensors}, headers=AUTH)
    assert response.status_code == 200, response.text
    version = response.json()["version"]

    async def state_at(v):
        async with _ws(server) as ws:
            return await next_state(ws, where=lambda m: m["params_version"] == v)

    state = asyncio.run(state_at(version))
    assert state["faults"] == {"l2": "disabled"}
    listed = {s["name"]: s for s in client.get("/api/v1/sensors").json()["sensors"]}
    assert listed["l2"]["enabled"] is False and listed["l2"]["status"] == "fault:disabled"
    assert all(listed[name]["enabled"] for name in ("l1", "l3", "l4"))
    assert "sensor l2: fault:disabled" in client.get("/api/v1/health").json()["reasons"]
    back = client.post(f"/api/v1/params/rollback/{start['version']}", headers=AUTH)
    assert back.status_code == 200
    assert asyncio.run(state_at(back.json()["version"]))["faults"] == {}


def test_params_message_on_the_websocket(client, live):
    server, _, _ = live

    async def run():
        async with _ws(server) as ws:
            await next_state(ws)
            response = await asyncio.to_thread(
                client.patch, "/api/v1/params", json={"tracking": {"max_distance_m": 1.5}}, headers=AUTH
            )

            async def params_message():
                while True:
                    message = json.loads(await ws.recv())
                    if message["type"] == "params":
                        return message

            return response.json(), await asyncio.wait_for(params_message(), 10)

    accepted, message = asyncio.run(run())
    assert message["version"] == accepted["version"] and message["patch"] == {"tracking": {"max_distance_m": 1.5}}
    assert message["params"]["tracking"]["max_distance_m"] == 1.5


# ------------------------------------------------------------------ slow clients, metrics


def _stalled_websocket(port: int, path: str) -> socket.socket:
    """A client that completes the handshake and then never reads (tiny receive buffer)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    sock.sendall(
        (
            f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
        ).encode()
    )
    reply = sock.recv(1024)
    assert b" 101 " in reply.split(b"\r\n", 1)[0], reply
    return sock


def test_stalled_client_does_not_slow_the_others(live):
    server, service, _ = live
    stalled = _stalled_websocket(server.port, "/ws/states?points=true")
    try:

        async def follow():
            async with _ws(server, points=True) as ws:
                frames = [(await next_state(ws))["frame"] for _ in range(25)]
                stats = service.hub.stats()
                return frames, stats

        frames, stats = asyncio.run(follow())
    finally:
        stalled.close()
    assert all(b > a for a, b in zip(frames, frames[1:]))
    stalled_stats = min(stats, key=lambda s: s["sent"])
    reader_stats = max(stats, key=lambda s: s["sent"])
    assert stalled_stats["dropped"] > 0, stats  # the stalled client lost states to newer ones...
    assert reader_stats["dropped"] == 0 and reader_stats["sent"] >= 25, stats  # ...the reader lost none


def test_metrics(client, live):
    _, service, _ = live
    text = client.get("/metrics").text
    assert "text/plain" in client.get("/metrics").headers["content-type"]
    processed = float(
        next(line.split()[-1] for line in text.splitlines() if line.startswith("i2v_loc_frames_processed_total"))
    )
    assert processed >= 2
    assert 'i2v_loc_frames_dropped_total{reason="source_error"}' in text
    assert 'i2v_loc_stage_latency_seconds_bucket{le="0.5",stage="total"}' in text
    for name in service.runner.source.sensor_names:
        assert f'i2v_loc_sensor_rate_hz{{sensor="{name}"}}' in text
    assert "i2v_loc_websocket_clients " in text


# ------------------------------------------------------------------ other configurations


def test_no_token_configured_refuses_writes_with_a_hint(tmp_path):
    server, _ = serve(sample_recording(), token=None)
    with server, httpx.Client(base_url=server.url) as c:
        response = c.patch("/api/v1/params", json={"clustering": {"tolerance_m": 0.5}}, headers=AUTH)
        assert response.status_code == 403 and "I2V_LOC_API_TOKEN" in response.json()["detail"]
        assert c.get("/api/v1/params").status_code == 200


def test_reads_can_require_the_token(tmp_path):
    server, _ = serve(sample_recording(), require_token_for_reads=True)
    with server, httpx.Client(base_url=server.url) as c:
        assert c.get("/api/v1/state").status_code == 401
        assert c.get("/metrics", headers={"Authorization": "Bearer nope"}).status_code == 403
        wait_for(lambda: c.get("/api/v1/state", headers=AUTH).status_code == 200, what="a state with the token")
        assert c.get("/").status_code == 200  # the page itself holds no data

        async def ws_attempts():
            async with websockets.connect(server.ws_url + "/ws/states") as ws:
                await ws.send(json.dumps({"token": "nope"}))
                refused = json.loads(await ws.recv())
                with pytest.raises(websockets.ConnectionClosed) as closed:
                    await ws.recv()
            async with websockets.connect(server.ws_url + "/ws/states", additional_headers=AUTH) as ws:
                state = await next_state(ws)
            return refused, closed.value.rcvd.code, state

        refused, code, state = asyncio.run(ws_attempts())
        assert refused["status"] == 403 and code == 1008 and state["type"] == "state"


def test_parameter_file_survives_a_restart(tmp_path):
    params_file = tmp_path / "params.yaml"
    server, _ = serve(sample_recording(), params_file=params_file)
    with server, httpx.Client(base_url=server.url) as c:
        assert c.patch("/api/v1/params", json={"tracking": {"max_age_frames": 7}}, headers=AUTH).status_code == 200
    server, service = serve(sample_recording(), params_file=params_file)
    with server, httpx.Client(base_url=server.url) as c:
        assert c.get("/api/v1/params").json()["params"]["tracking"]["max_age_frames"] == 7
        assert service.runner.pipeline.params.tracking.max_age_frames == 7


def test_a_failing_source_frame_is_counted_and_skipped(tmp_path):
    # Not real time: every frame is tried (in real time a slow frame can make the runner skip the
    # failing ones as late, and then there is nothing to count).
    server, service = serve(sample_recording(), realtime=False)
    source = service.runner.source
    real_frame = source.frame

    def flaky(k):
        if k % 3 == 1:
            raise OSError(f"simulated read error at frame {k}")
        return real_frame(k)

    source.frame = flaky
    with server, httpx.Client(base_url=server.url) as c:
        wait_for(lambda: service.runner.frames_processed >= 4, what="frames after read errors")
        health = c.get("/api/v1/health").json()
        assert health["frames_dropped"]["source_error"] >= 1 and health["live"] is True
        error = health["last_frame_error"]
        assert (
            error["reason"] == "source_error" and error["frame"] % 3 == 1 and "simulated read error" in error["error"]
        )
        frame = c.get("/api/v1/state").json()["frame"]
        assert frame % 3 != 1


# ------------------------------------------------------------------ review fixes


def test_binary_and_text_messages_from_a_client_are_ignored(live):
    server, _, _ = live

    async def chatty():
        async with _ws(server) as ws:
            first = await next_state(ws)
            await ws.send(b"\x00\xffbinary")
            await ws.send("hello")
            later = [await next_state(ws) for _ in range(3)]
            return first, later

    first, later = asyncio.run(chatty())
    assert all(s["frame"] > first["frame"] for s in later)


def test_a_bad_points_flag_is_refused_with_a_reason(live):
    server, _, _ = live

    async def attempt():
        async with websockets.connect(server.ws_url + "/ws/states?points=maybe") as ws:
            refused = json.loads(await ws.recv())
            with pytest.raises(websockets.ConnectionClosed) as closed:
                await ws.recv()
        async with websockets.connect(server.ws_url + "/ws/states?points=1", max_size=2**24) as ws:
            with_points = await next_state(ws, where=lambda m: "foreground" in m)
        return refused, closed.value.rcvd, with_points

    refused, close, with_points = asyncio.run(attempt())
    assert refused == {"type": "error", "status": 400, "detail": "points must be true or false, got 'maybe'"}
    assert close.code == 1008 and "points must be true or false" in close.reason
    assert with_points["foreground"]["xy"]


def test_null_section_patch_gives_422(client, live):
    _, service, _ = live
    version = service.store.version
    response = client.patch("/api/v1/params", json={"sensors": None}, headers=AUTH)
    assert response.status_code == 422 and "whole section" in response.json()["detail"]
    assert response.json()["errors"][0]["field"] == "sensors" and service.store.version == version


def test_health_and_metrics_show_the_method_and_no_created_series(client):
    assert client.get("/api/v1/health").json()["method"] == "paper"
    assert "_created" not in client.get("/metrics").text


def test_unwritable_parameter_file_gives_a_json_507(tmp_path):
    from test_service_support import make_service

    from service.app import create_app

    blocker = tmp_path / "not-a-folder"
    blocker.write_text("x")
    service = make_service(sample_recording(), params_file=blocker / "params.yaml", method="paper")

    async def requests():  # in-process ASGI, no lifespan: the pipeline thread is not needed here
        transport = httpx.ASGITransport(app=create_app(service))
        async with httpx.AsyncClient(transport=transport, base_url="http://service") as c:
            patched = await c.patch("/api/v1/params", json={"tracking": {"max_age_frames": 9}}, headers=AUTH)
            return patched, (await c.get("/api/v1/params")).json()

    response, params = asyncio.run(requests())
    assert response.status_code == 507, response.text
    body = response.json()
    assert body["in_force"] is True and body["saved"] is False and body["version"] == 1
    assert "is in force but could not be written" in body["detail"] and str(blocker) in body["detail"]
    assert params["version"] == 1 and params["params"]["tracking"]["max_age_frames"] == 9
    assert service.runner.pipeline.params.tracking.max_age_frames == 9
    service.stop()  # the save at shutdown fails too: kept for the exit message, no exception
    assert service.save_error and str(blocker) in service.save_error


# ------------------------------------------------------------------ abuse: size, depth, many errors


def test_a_patch_of_many_unknown_keys_is_refused_with_a_short_list(client, live):
    _, service, _ = live
    before = service.store.version
    response = client.patch("/api/v1/params", json={"clustering": {f"k{i}": 1 for i in range(200)}}, headers=AUTH)
    assert response.status_code == 422
    errors = response.json()["errors"]
    assert len(errors) == 20 and {e["message"] for e in errors} == {"unknown key"}
    assert response.json()["detail"].startswith("patch: 200 unknown keys: clustering.k0, clustering.k1, ")
    assert service.store.version == before


def test_a_deeply_nested_body_is_a_400(client):
    body = '{"clustering": ' + '{"a": ' * 600 + "1" + "}" * 601
    response = client.patch("/api/v1/params", content=body, headers={**AUTH, "Content-Type": "application/json"})
    assert response.status_code == 400 and "nested deeper than 16 levels" in response.json()["detail"]
    assert client.get("/api/v1/health").json()["live"] is True


def test_a_huge_declared_body_is_refused_before_it_is_sent(live):
    server, _, _ = live
    with socket.create_connection(("127.0.0.1", server.port), timeout=10) as sock:
        sock.sendall(
            (
                f"PATCH /api/v1/params HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer {TOKEN}\r\n"
                "Content-Type: application/json\r\nContent-Length: 400000000\r\n\r\n{"
            ).encode()
        )
        reply = sock.recv(4096)  # the server answers without waiting for the 400 MB
    assert reply.startswith(b"HTTP/1.1 413 "), reply[:200]
    assert b"larger than 1000000 bytes" in reply


def test_websocket_messages_are_not_compressed(live):
    server, _, _ = live

    async def extensions():
        async with _ws(server, points=True) as ws:  # the client offers permessage-deflate
            await next_state(ws)
            return ws.response.headers.get("Sec-WebSocket-Extensions")

    assert asyncio.run(extensions()) is None


def test_websocket_from_another_site_is_refused(live):
    server, _, _ = live

    async def attempt(origin):
        async with websockets.connect(server.ws_url + "/ws/states", origin=origin) as ws:
            return (await next_state(ws))["type"]

    assert asyncio.run(attempt(f"http://127.0.0.1:{server.port}")) == "state"  # the dashboard itself
    with pytest.raises(websockets.InvalidStatus) as refused:
        asyncio.run(attempt("http://evil.example"))
    assert refused.value.response.status_code == 403


def test_allowed_origins_may_open_the_websocket(tmp_path):
    source_server, _ = serve(sample_recording(), allowed_origins=("https://ops.example.com",))
    with source_server as server:

        async def attempt(origin):
            async with websockets.connect(server.ws_url + "/ws/states", origin=origin) as ws:
                return (await next_state(ws))["type"]

        assert asyncio.run(attempt("https://ops.example.com")) == "state"
        with pytest.raises(websockets.InvalidStatus):
            asyncio.run(attempt("https://other.example.com"))


def test_the_server_stops_while_a_change_is_still_in_flight(tmp_path):
    server, service = serve(sample_recording())
    release = threading.Event()
    pipeline = service.runner.pipeline
    real_update = pipeline.update_params
    pipeline.update_params = lambda patch: release.wait(60) or real_update(patch)  # a change that hangs
    try:
        with server:
            wait_for(lambda: service.runner.frames_processed >= 1, what="a frame")
            with httpx.Client(base_url=server.url, timeout=60) as c:
                sender = threading.Thread(
                    target=lambda: c.patch("/api/v1/params", headers=AUTH, json={"tracking": {"max_age_frames": 4}}),
                    daemon=True,
                )
                sender.start()
                wait_for(lambda: service.store._lock.locked(), what="the change in flight")
                server.server.should_exit = True
                server.thread.join(20)
                stopped = not server.thread.is_alive()
                assert not release.is_set()
    finally:
        release.set()
    assert stopped  # the server did not wait for the change that hangs


# ------------------------------------------------------------------ the API documentation


def test_api_docs_need_no_internet(client):
    for page in ("/docs", "/redoc"):
        html = client.get(page).text
        refs = re.findall(r'(?:src|href)="([^"]+)"', html)
        assert len(refs) >= 2 and [r for r in refs if "//" in r] == [], refs  # nothing from another host
        for ref in refs:
            assert client.get(ref).status_code == 200, ref
    assert "swagger-ui-bundle.js" in client.get("/docs").text


def test_openapi_marks_only_guarded_operations_and_types_every_answer(client):
    spec = client.get("/openapi.json").json()
    secured = {
        (path, method) for path, ops in spec["paths"].items() for method, op in ops.items() if op.get("security")
    }
    assert secured == {("/api/v1/params", "patch"), ("/api/v1/params/rollback/{version}", "post")}
    for path, ops in spec["paths"].items():
        for method, op in ops.items():
            if path in ("/metrics", "/api/v1/params/schema"):  # Prometheus text; a JSON Schema document
                continue
            schema = op["responses"]["200"]["content"]["application/json"]["schema"]
            assert "$ref" in schema, (method, path, schema)
    health = spec["components"]["schemas"]["Health"]["properties"]
    assert {"status", "reasons", "frame_drop_rate", "sensors"} <= set(health)


def test_openapi_marks_reads_secured_when_they_need_the_token(tmp_path):
    server, _ = serve(sample_recording(), require_token_for_reads=True)
    with server, httpx.Client(base_url=server.url) as c:
        spec = c.get("/openapi.json").json()
    assert spec["paths"]["/api/v1/state"]["get"]["security"] == [{"HTTPBearer": []}]
    assert "401" in spec["paths"]["/api/v1/state"]["get"]["responses"]
