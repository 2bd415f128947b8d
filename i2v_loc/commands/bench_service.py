"""``i2v-loc bench --service``: the real service replaying a recording in real time, WebSocket
clients reading every state; latency from the frame entering the pipeline (``frame_in_unix_s``,
stamped by the service) to the message leaving it (``sent_unix_s``, stamped at the send) and to
the client's receipt, all on this machine's wall clock."""

from __future__ import annotations

import asyncio
import json
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

STARTUP_TIMEOUT_S = 120.0
WARMUP_S = 6.0  # the default background map is used after 25 samples, one every 2 frames at 10 Hz


def bench_service(rec_path: Path, method: str, n_clients: int, seconds: float, warmup_s: float = WARMUP_S) -> dict:
    import numpy as np

    proc, url = _start(rec_path, method)
    try:
        wait_for_state(url)
        late_before = _late_frames(url)
        to_send, to_client, received = asyncio.run(_listen(url, n_clients, seconds, warmup_s))
        late = _late_frames(url) - late_before
    finally:
        proc.terminate()
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
    if not to_send:
        raise RuntimeError("the service sent no state in the time given")
    return {
        "clients": n_clients,
        "seconds": seconds,
        "warmup_s": warmup_s,
        "messages": len(to_send),
        "messages_per_client_min": int(min(received)),
        "frames_dropped_late": int(late),
        "frame_to_send_ms_p50": float(np.percentile(to_send, 50)),
        "frame_to_send_ms_p99": float(np.percentile(to_send, 99)),
        "frame_to_client_ms_p50": float(np.percentile(to_client, 50)),
        "frame_to_client_ms_p99": float(np.percentile(to_client, 99)),
    }


def _start(rec_path: Path, method: str) -> tuple[subprocess.Popen, str]:
    root = str(Path(__file__).resolve().parents[2])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))}
    cmd = [sys.executable, "-m", "i2v_loc", "serve", "--source", f"replay:{rec_path}", "--loop", "--port", "0"]
    proc = subprocess.Popen(
        [*cmd, "--quiet", "--method", method], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, env=env
    )
    lines: list[str] = []
    threading.Thread(target=lambda: lines.extend(proc.stderr), daemon=True).start()
    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    while time.monotonic() < deadline and proc.poll() is None:
        found = re.search(r"dashboard\s+(http://\S+/)", "".join(lines))
        if found:
            return proc, found.group(1)
        time.sleep(0.1)
    proc.kill()
    raise RuntimeError("the service did not start:\n" + "".join(lines[-20:]))


def wait_for_state(url: str) -> None:
    """Until the service at ``url`` serves a state (it processes frames); RuntimeError after the start-up timeout."""
    import httpx

    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    while time.monotonic() < deadline:
        try:
            if httpx.get(url + "api/v1/state", timeout=5).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    raise RuntimeError("the service produced no state")


def _late_frames(url: str) -> float:
    import httpx

    text = httpx.get(url + "metrics", timeout=30).text
    found = re.search(r'i2v_loc_frames_dropped_total\{reason="late"\} ([0-9.e+]+)', text)
    return float(found.group(1)) if found else 0.0


async def _listen(url: str, n_clients: int, seconds: float, warmup_s: float):
    """(frame in to send ms, frame in to receipt ms, messages per client) over ``seconds``."""
    import websockets

    ws_url = url.replace("http://", "ws://") + "ws/states"
    to_send: list[float] = []
    to_client: list[float] = []
    received = [0] * n_clients
    stop = asyncio.Event()

    async def client(i: int) -> None:
        async with websockets.connect(ws_url, max_size=2**24, compression=None) as ws:
            while not stop.is_set():
                try:
                    text = await asyncio.wait_for(ws.recv(), 1.0)
                except TimeoutError:
                    continue
                now = time.time()
                message = json.loads(text)
                if message.get("type") != "state" or message.get("frame_in_unix_s") is None:
                    continue
                if measuring.is_set():
                    to_send.append((message["sent_unix_s"] - message["frame_in_unix_s"]) * 1e3)
                    to_client.append((now - message["frame_in_unix_s"]) * 1e3)
                    received[i] += 1

    measuring = asyncio.Event()
    tasks = [asyncio.create_task(client(i)) for i in range(n_clients)]
    await asyncio.sleep(warmup_s)  # every client connected, the background map learned
    measuring.set()
    await asyncio.sleep(seconds)
    stop.set()
    await asyncio.gather(*tasks, return_exceptions=True)
    return to_send, to_client, received
