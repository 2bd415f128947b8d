"""``i2v-loc serve`` as a user runs it: a subprocess, its terminal output, signals, errors."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
from pathlib import Path

import httpx
import pytest
import yaml
from test_service_support import sample_recording, wait_for

# The console script, not ``python -m i2v_loc.cli`` (there cli.py runs as __main__ and its
# UserError is a different class from the one the commands raise).
I2V_LOC = str(Path(sys.executable).with_name("i2v-loc"))

pytestmark = pytest.mark.timeout(90)


class ServeProcess:
    def __init__(self, *args: str, env_token: str | None = None):
        env = {k: v for k, v in os.environ.items() if k != "I2V_LOC_API_TOKEN"}
        if env_token:
            env["I2V_LOC_API_TOKEN"] = env_token
        self.proc = subprocess.Popen(
            [I2V_LOC, "serve", "--port", "0", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
        )
        self.lines: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stderr:
            self.lines.append(line.rstrip("\n"))

    @property
    def text(self) -> str:
        return "\n".join(self.lines)

    def url(self) -> str:
        found = wait_for(
            lambda: re.search(r"dashboard\s+(http://\S+/)", self.text) or self.proc.poll() is not None,
            timeout_s=60,
            what="the dashboard address",
        )
        assert found is not True and self.proc.poll() is None, self.text
        return found.group(1)

    def stop(self, sig=signal.SIGTERM) -> int:
        self.proc.send_signal(sig)
        return self.proc.wait(20)


def test_serve_replay_patch_then_sigterm_saves_params(tmp_path):
    params_file, token_file = tmp_path / "params.yaml", tmp_path / "token"
    token_file.write_text("cli-secret\n")
    serve = ServeProcess(
        "--source",
        f"replay:{sample_recording()}",
        "--loop",
        "--params",
        str(params_file),
        "--token-file",
        str(token_file),
    )
    try:
        url = serve.url()
        assert url.startswith("http://127.0.0.1:")  # loopback unless told otherwise
        with httpx.Client(base_url=url, timeout=10) as c:
            wait_for(lambda: c.get("api/v1/state").status_code == 200, what="the first state")
            response = c.patch(
                "api/v1/params",
                json={"orientation": {"history_frames": 12}},
                headers={"Authorization": "Bearer cli-secret"},
            )
            assert response.status_code == 200, response.text
    finally:
        code = serve.stop(signal.SIGTERM)
    assert code == 0, serve.text
    assert serve.proc.stdout.read() == ""  # everything the service says goes to stderr
    assert yaml.safe_load(params_file.read_text())["orientation"]["history_frames"] == 12
    assert "stopped after" in serve.text and f"parameters saved to {params_file}" in serve.text
    assert "cli-secret" not in serve.text  # the token is never printed
    assert "need the bearer token" in serve.text


def test_serve_sim_source_generates_once_and_stops_on_sigint(tmp_path):
    cache = tmp_path / "cache"
    serve = ServeProcess("--source", "sim:docking", "--sim-duration", "1", "--cache-dir", str(cache))
    try:
        url = serve.url()
        with httpx.Client(base_url=url, timeout=10) as c:
            state = wait_for(lambda: (r := c.get("api/v1/state")).status_code == 200 and r.json(), what="a state")
            health = c.get("api/v1/health").json()
            response = c.patch("api/v1/params", json={}, headers={"Authorization": "Bearer x"})
    finally:
        code = serve.stop(signal.SIGINT)
    assert code == 0, serve.text
    assert serve.proc.stdout.read() == ""  # the simulator's progress too goes to stderr
    assert state["type"] == "state" and health["source"]["scenario"] == "docking"
    assert health["method"] == "default" and "method     default" in serve.text
    assert health["source"]["loop"] is True
    assert (cache / "man_tgx_docking_seed1_1s" / "meta.yaml").is_file()
    assert response.status_code == 403 and "I2V_LOC_API_TOKEN" in response.json()["detail"]
    assert "writes     disabled" in serve.text


@pytest.mark.parametrize(
    "args, message",
    [
        (["--source", "replay:/no/such/recording"], "no such recording directory"),
        (["--source", "webcam"], "unknown source"),
        (["--require-token-for-reads"], "--require-token-for-reads needs a token"),
        (["--token-file", "/no/such/token"], "cannot read the token file"),
        (["--source", "sim:nope"], "unknown scenario 'nope' in sim:nope; known: "),
        (["--vehicle", "vw_golf"], "unknown vehicle 'vw_golf' for the simulated yard"),
        (["--method", "fast"], "unknown method 'fast'; known: paper, default"),
        (["--host", "0.0.0.0"], "pass --require-token-for-reads (with a token) or --allow-open-reads; without TLS"),
        (["--ssl-keyfile", "/no/key.pem"], "--ssl-keyfile and --ssl-certfile go together"),
    ],
)
def test_serve_user_errors(args, message, tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "I2V_LOC_API_TOKEN"}
    done = subprocess.run(
        [I2V_LOC, "serve", "--port", "0", "--cache-dir", str(tmp_path / "cache"), *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert done.returncode == 2 and message in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr  # one line, no usage text
    assert not (tmp_path / "cache").exists()  # no simulator was started


def test_access_log_and_parameter_changes_are_logged(tmp_path):
    serve = ServeProcess(
        "--source", f"replay:{sample_recording()}", "--loop", "--access-log", "--quiet", env_token="log-secret"
    )
    try:
        url = serve.url()
        with httpx.Client(base_url=url, timeout=10) as c:
            assert c.get("api/v1/health").status_code == 200
            changed = c.patch(
                "api/v1/params",
                json={"tracking": {"max_age_frames": 5}},
                headers={"Authorization": "Bearer log-secret"},
            )
            assert changed.status_code == 200, changed.text
        wait_for(lambda: "max_age_frames" in serve.text, what="the change in the log")
    finally:
        serve.stop(signal.SIGTERM)
    assert re.search(r'"GET /api/v1/health HTTP/1.1" 200', serve.text), serve.text
    assert re.search(r'"PATCH /api/v1/params HTTP/1.1" 200', serve.text), serve.text
    assert re.search(r"parameter version 1 \(token [0-9a-f]{8}\): tracking.max_age_frames: 3 -> 5", serve.text), (
        serve.text
    )
    assert "log-secret" not in serve.text


def test_open_reads_on_all_interfaces_when_asked_for(tmp_path):
    serve = ServeProcess(
        "--source", f"replay:{sample_recording()}", "--host", "0.0.0.0", "--allow-open-reads", "--quiet"
    )
    try:
        url = serve.url()
        with httpx.Client(base_url=url, timeout=10) as c:
            assert c.get("api/v1/health").status_code == 200
    finally:
        assert serve.stop(signal.SIGTERM) == 0
    assert "reads are open to the network" in serve.text and "the token travels in clear text" in serve.text
