"""Helpers shared by the service and dashboard tests: a live server on a free loopback port.

No tests here; the other test_service_* files and test_dashboard.py import this module.
"""

from __future__ import annotations

import json
import socket
import tempfile
import threading
import time
from pathlib import Path

import uvicorn

from i2v_loc.params import load_params
from i2v_loc.sources import ReplaySource, SimSpec, simulated_recording
from service.app import create_app, server_config
from service.auth import AuthConfig
from service.core import build_service

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "samples"
TOKEN = "test-token-5f2c"


def sample_recording() -> Path:
    """A committed sample recording of the docking scenario if there is one, else a 4 s one
    simulated once into the temp folder (about 3 s)."""
    candidates = sorted(p.parent for p in SAMPLES.glob("**/meta.yaml") if "dock" in p.parent.name)
    if candidates:
        return candidates[0]
    spec = SimSpec(scenario="docking", vehicle="man_tgx", seed=1, duration_s=4.0)
    return simulated_recording(spec, Path(tempfile.gettempdir()) / "i2v-loc-test-sim", quiet=True)


class LiveServer:
    """uvicorn serving ``app`` in a thread on 127.0.0.1:<free port>."""

    def __init__(self, app, send_buffer_bytes: int | None = None):
        self.app = app
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        if send_buffer_bytes:
            # Accepted connections inherit it (Linux): a stalled client then backs up within a few
            # messages instead of after megabytes of kernel buffer.
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, send_buffer_bytes)
        self.sock.bind(("127.0.0.1", 0))
        self.port = self.sock.getsockname()[1]
        self.url = f"http://127.0.0.1:{self.port}"
        self.ws_url = f"ws://127.0.0.1:{self.port}"
        config = server_config(app, ws_ping_interval=None)
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self.sock]}, daemon=True)

    def __enter__(self) -> LiveServer:
        self.thread.start()
        deadline = time.monotonic() + 20
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise RuntimeError("the test server did not start")
            time.sleep(0.02)
        return self

    def __exit__(self, *exc) -> None:
        self.server.should_exit = True
        self.thread.join(15)
        self.sock.close()


def make_service(
    recording: Path,
    params_file: Path | None = None,
    token: str | None = TOKEN,
    require_token_for_reads: bool = False,
    loop: bool = True,
    allowed_origins: tuple = (),
    **kwargs,
):
    """A service with the real pipeline replaying ``recording``."""
    source = ReplaySource(recording, loop=loop)
    existing = params_file if params_file is not None and params_file.is_file() else None
    params = load_params(source.sensors_file, existing)
    auth = AuthConfig(token, require_token_for_reads, allowed_origins)
    return build_service(source, params, params_file, auth, **kwargs)


def serve(recording: Path, send_buffer_bytes: int | None = None, **kwargs) -> tuple[LiveServer, object]:
    service = make_service(recording, **kwargs)
    return LiveServer(create_app(service), send_buffer_bytes), service


async def next_state(ws, timeout_s: float = 10.0, where=lambda m: True) -> dict:
    """The next WebSocket state message satisfying ``where``."""
    import asyncio

    async def wait():
        while True:
            message = json.loads(await ws.recv())
            if message.get("type") == "state" and where(message):
                return message

    return await asyncio.wait_for(wait(), timeout_s)


def wait_for(predicate, timeout_s: float = 10.0, what: str = "condition"):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
