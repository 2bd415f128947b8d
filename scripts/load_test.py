"""Load test of the live service (not run in CI): WebSocket clients with points + REST requests.

Starts ``i2v-loc serve`` on a free loopback port replaying the committed docking sample in a loop,
then for ``--duration`` seconds keeps ``--clients`` WebSocket clients (``?points=true``) reading
and sends ``--rest-rate`` REST requests per second (GET /state, /health, /vehicles in turn).
Then it sends one PATCH holding ``--unknown-keys`` unknown keys and times its rejection.

Prints, as JSON: messages per client (min / median / max), messages the server dropped for slow
clients, frames dropped, REST latency (p50 / p99) and requests served per second, the server's
RSS at the start and the end, and the PATCH's time to reject and the frames dropped meanwhile.

    PYTHONPATH=. python scripts/load_test.py --duration 60 --clients 100 --rest-rate 50
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import websockets

from i2v_loc.commands.bench_service import wait_for_state

REPO = Path(__file__).resolve().parents[1]
TOKEN = "load-test-token"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--duration", type=float, default=60.0, help="seconds of load (default %(default)s)")
    p.add_argument("--clients", type=int, default=100, help="WebSocket clients with points (default %(default)s)")
    p.add_argument("--rest-rate", type=float, default=50.0, help="REST requests per second (default %(default)s)")
    p.add_argument("--unknown-keys", type=int, default=200, help="unknown keys in the PATCH (default %(default)s)")
    p.add_argument("--method", default="default", help="pipeline method of the service (default %(default)s)")
    p.add_argument("--recording", default=str(REPO / "samples" / "man_tgx_docking"))
    p.add_argument(
        "--switch-interval", type=float, help="sys.setswitchinterval of the server (s; default Python's 0.005)"
    )
    args = p.parse_args()
    server = start_server(args)
    try:
        url = server.url
        try:
            wait_for_state(url)
        except RuntimeError as err:
            raise SystemExit(str(err)) from None
        rss_start = rss_mib(server.proc.pid)
        before = scrape(url)
        load = asyncio.run(run_load(url, args))
        after = scrape(url)
        rss_end = rss_mib(server.proc.pid)
        patch = time_bad_patch(url, args.unknown_keys)
    finally:
        server.proc.terminate()
        t0 = time.monotonic()
        server.proc.wait(30)
        stop_s = time.monotonic() - t0
    figures = {
        "duration_s": args.duration,
        "clients": args.clients,
        **load,
        "ws_messages_dropped": after["ws_dropped"] - before["ws_dropped"],
        "frames_processed": after["processed"] - before["processed"],
        "frames_dropped_late": after["late"] - before["late"],
        "rss_mib_start": rss_start,
        "rss_mib_end": rss_end,
        "patch": patch,
        "shutdown_s": round(stop_s, 2),
        "cpus": os.cpu_count(),
    }
    print(json.dumps(figures, indent=2))
    return 0


class Server:
    def __init__(self, proc: subprocess.Popen):
        self.proc = proc
        self.lines: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            found = re.search(r"dashboard\s+(http://\S+/)", "\n".join(self.lines))
            if found:
                self.url = found.group(1)
                return
            if proc.poll() is not None:
                break
            time.sleep(0.1)
        raise SystemExit("the server did not start:\n" + "\n".join(self.lines))

    def _read(self) -> None:
        for line in self.proc.stderr:
            self.lines.append(line.rstrip("\n"))


def start_server(args) -> Server:
    env = {**os.environ, "I2V_LOC_API_TOKEN": TOKEN, "PYTHONPATH": str(REPO)}
    prelude = f"sys.setswitchinterval({args.switch_interval}); " if args.switch_interval else ""
    cmd = [
        sys.executable,
        "-c",
        f"import sys; {prelude}from i2v_loc.cli import main; sys.exit(main())",
        "serve",
        "--source",
        f"replay:{args.recording}",
        "--loop",
        "--port",
        "0",
        "--quiet",
        "--method",
        args.method,
    ]
    return Server(subprocess.Popen(cmd, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, env=env))


def scrape(url: str) -> dict:
    text = httpx.get(url + "metrics", timeout=30).text

    def value(pattern: str) -> float:
        found = re.search(pattern + r" ([0-9.e+]+)", text)
        return float(found.group(1)) if found else 0.0

    return {
        "ws_dropped": value(r"i2v_loc_websocket_messages_dropped_total"),
        "processed": value(r"i2v_loc_frames_processed_total"),
        "late": value(r'i2v_loc_frames_dropped_total\{reason="late"\}'),
    }


def rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return round(int(line.split()[1]) / 1024, 1)
    return float("nan")


async def run_load(url: str, args) -> dict:
    ws_url = url.replace("http://", "ws://") + "ws/states?points=true"
    stop = asyncio.Event()
    counts = [0] * args.clients
    disconnects = [0]

    async def client(i: int) -> None:
        async with websockets.connect(ws_url, max_size=2**24, compression=None) as ws:
            while not stop.is_set():
                try:
                    await asyncio.wait_for(ws.recv(), 1.0)
                except TimeoutError:
                    continue
                except websockets.ConnectionClosed:
                    disconnects[0] += 1
                    return
                counts[i] += 1

    latencies: list[float] = []
    failures = [0]

    async def rest() -> None:
        paths = ["api/v1/state", "api/v1/health", "api/v1/vehicles"]
        period = 1.0 / args.rest_rate
        async with httpx.AsyncClient(base_url=url, timeout=30) as http:
            pending = set()
            k = 0
            t0 = time.monotonic()
            while not stop.is_set():
                due = t0 + k * period
                await asyncio.sleep(max(0.0, due - time.monotonic()))
                pending.add(asyncio.create_task(one(http, paths[k % len(paths)])))
                pending = {t for t in pending if not t.done()}
                k += 1
            await asyncio.gather(*pending, return_exceptions=True)

    async def one(http, path: str) -> None:
        t = time.monotonic()
        try:
            response = await http.get(path)
            if response.status_code not in (200, 503):
                failures[0] += 1
        except httpx.HTTPError:
            failures[0] += 1
            return
        latencies.append(time.monotonic() - t)

    clients = [asyncio.create_task(client(i)) for i in range(args.clients)]
    await asyncio.sleep(2.0)  # every client connected
    start = list(counts)
    rest_task = asyncio.create_task(rest())
    await asyncio.sleep(args.duration)
    got = [c - s for c, s in zip(counts, start)]
    stop.set()
    await asyncio.gather(rest_task, *clients, return_exceptions=True)
    latencies.sort()
    return {
        "messages_per_client": {"min": min(got), "median": statistics.median(got), "max": max(got)},
        "ws_disconnects": disconnects[0],
        "rest_requests_served_per_s": round(len(latencies) / args.duration, 1),
        "rest_failures": failures[0],
        "rest_p50_ms": round(1000 * latencies[len(latencies) // 2], 1) if latencies else None,
        "rest_p99_ms": round(1000 * latencies[int(len(latencies) * 0.99)], 1) if latencies else None,
    }


def time_bad_patch(url: str, n_keys: int, repeat: int = 5, window_s: float = 3.0) -> dict:
    """Time to reject the PATCH (first and median of ``repeat``), and the frames dropped as late in
    a ``window_s`` window starting with the PATCHes against a window without (the baseline: on a
    loaded machine the pipeline may not keep up with the sensors anyway)."""
    body = {"clustering": {f"unknown_{i}": 1 for i in range(n_keys)}}
    headers = {"Authorization": f"Bearer {TOKEN}"}
    baseline = _late_in_window(url, window_s, lambda: None)
    times, statuses = [], []

    http = httpx.Client(base_url=url, timeout=60)  # one connection: no set-up in the figures
    http.get("api/v1/health")

    def send() -> None:
        for _ in range(repeat):
            t = time.monotonic()
            response = http.patch("api/v1/params", json=body, headers=headers)
            times.append(1000 * (time.monotonic() - t))
            statuses.append(response.status_code)

    during = _late_in_window(url, window_s, send)
    health_ms = []
    for _ in range(repeat):  # the round trip of a trivial request, for comparison
        t = time.monotonic()
        http.get("api/v1/health")
        health_ms.append(1000 * (time.monotonic() - t))
    http.close()
    return {
        "statuses": sorted(set(statuses)),
        "body_bytes": len(json.dumps(body)),
        "first_reject_ms": round(times[0], 1),
        "median_reject_ms": round(statistics.median(times), 1),
        "median_get_health_ms": round(statistics.median(health_ms), 1),
        f"frames_late_in_{window_s:g}s_with_patches": during,
        f"frames_late_in_{window_s:g}s_baseline": baseline,
    }


def _late_in_window(url: str, window_s: float, action) -> float:
    before = scrape(url)
    t = time.monotonic()
    action()
    time.sleep(max(0.0, window_s - (time.monotonic() - t)))
    return scrape(url)["late"] - before["late"]


if __name__ == "__main__":
    sys.exit(main())
