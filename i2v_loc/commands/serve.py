"""``i2v-loc serve``: the live yard service (REST, WebSocket, parameters, metrics, dashboard)."""

from __future__ import annotations

import ipaddress
import logging
import signal
import socket
import sys
import threading
import time
from pathlib import Path

from i2v_loc.cli import UserError
from i2v_loc.params import DEFAULT_METHOD

DEFAULT_SOURCE = "sim:docking"
GIL_SWITCH_INTERVAL_S = 0.0005


def register(sub) -> None:
    p = sub.add_parser(
        "serve",
        help="run the live service: REST API, WebSocket stream and dashboard",
        description="Run the pipeline live on a source and serve its states (see docs/service.md).",
    )
    p.add_argument(
        "--source",
        default=DEFAULT_SOURCE,
        help="sim[:SCENARIO] (simulated yard, loops; default %(default)s), replay:REC (any layout of `i2v-loc sources`) or ouster-udp:DIR[@PORT,...]",
    )
    p.add_argument(
        "--method",
        default=DEFAULT_METHOD,
        metavar="paper|default",
        help="pipeline method (default %(default)s: fast enough for 10 Hz; paper: the published one)",
    )
    p.add_argument(
        "--params",
        type=Path,
        metavar="FILE",
        help="parameter file: loaded at start (if it exists) and rewritten on every change",
    )
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default %(default)s: this machine only)")
    p.add_argument("--port", type=int, default=8000, help="port (default %(default)s; 0 picks a free one)")
    p.add_argument("--loop", action="store_true", help="replay the recording in an endless loop")
    p.add_argument(
        "--token-file",
        type=Path,
        metavar="PATH",
        help="file holding the API token (default: the environment variable I2V_LOC_API_TOKEN)",
    )
    p.add_argument("--require-token-for-reads", action="store_true", help="reads need the token too")
    p.add_argument(
        "--allow-open-reads",
        action="store_true",
        help="allow reads without a token on an address other than loopback (refused otherwise)",
    )
    p.add_argument(
        "--allowed-origin",
        action="append",
        default=[],
        metavar="URL",
        help="a web page origin (e.g. https://ops.example.com) allowed to open the WebSocket "
        "besides the service's own; repeatable",
    )
    p.add_argument("--ssl-keyfile", type=Path, metavar="FILE", help="TLS private key (with --ssl-certfile: HTTPS)")
    p.add_argument("--ssl-certfile", type=Path, metavar="FILE", help="TLS certificate chain")
    p.add_argument("--vehicle", default="man_tgx", help="vehicle of the simulated yard (default %(default)s)")
    p.add_argument("--sim-seed", type=int, default=1, help="seed of the simulated yard (default %(default)s)")
    p.add_argument(
        "--sim-duration",
        type=float,
        default=30.0,
        metavar="S",
        help="length of the simulated recording that loops (default %(default)s s)",
    )
    p.add_argument(
        "--cache-dir", type=Path, help="where simulated recordings are cached (default ~/.cache/i2v-loc/sim)"
    )
    p.add_argument(
        "--max-points",
        type=int,
        default=2000,
        help="foreground points per WebSocket message for the dashboard (default %(default)s; 0: none)",
    )
    p.add_argument("--no-realtime", action="store_true", help="process frames as fast as possible (benchmarking)")
    p.add_argument("--access-log", action="store_true", help="log every HTTP request")
    p.add_argument("--quiet", action="store_true", help="no live status line")
    p.set_defaults(func=run)


def run(args) -> int:
    from i2v_loc.params import load_params
    from i2v_loc.pipelines import method_name
    from i2v_loc.sources import SourceError, open_source
    from service.auth import AuthConfig, TokenError, load_token

    try:
        method_name(args.method)
    except ValueError as err:
        raise UserError(str(err)) from err
    if not 0 <= args.port <= 65535:
        raise UserError(f"--port must be within 0..65535, got {args.port}")
    if args.max_points < 0:
        raise UserError(f"--max-points must be >= 0, got {args.max_points}")
    try:
        token = load_token(args.token_file)
    except TokenError as err:
        raise UserError(str(err)) from err
    if args.require_token_for_reads and token is None:
        raise UserError("--require-token-for-reads needs a token: set I2V_LOC_API_TOKEN or pass --token-file PATH")
    _check_exposure(args)
    sock = _bind(args.host, args.port)
    try:
        source = open_source(
            args.source,
            loop=args.loop,
            vehicle=args.vehicle,
            seed=args.sim_seed,
            duration_s=args.sim_duration,
            cache_dir=args.cache_dir,
        )
    except SourceError as err:
        sock.close()
        raise UserError(str(err)) from err
    params_file = args.params
    if params_file is not None and params_file.exists() and not params_file.is_file():
        raise UserError(f"--params {params_file}: not a file")
    existing = params_file if params_file is not None and params_file.is_file() else None
    params = load_params(source.sensors_file, existing)
    auth = AuthConfig(token, args.require_token_for_reads, tuple(args.allowed_origin))
    return _serve(args, sock, source, params, params_file, auth)


LOOPBACK = ("127.0.0.1", "localhost", "::1")


def _check_exposure(args) -> None:
    """Open reads beyond this machine only when asked for; TLS files come in pairs."""
    if bool(args.ssl_keyfile) != bool(args.ssl_certfile):
        raise UserError("--ssl-keyfile and --ssl-certfile go together")
    for file in (args.ssl_keyfile, args.ssl_certfile):
        if file is not None and not file.is_file():
            raise UserError(f"{file}: no such TLS file")
    if args.host in LOOPBACK or args.require_token_for_reads or args.allow_open_reads:
        return
    raise UserError(
        f"--host {args.host} without --require-token-for-reads opens the yard's data to the network: "
        "pass --require-token-for-reads (with a token) or --allow-open-reads; without TLS "
        "(--ssl-keyfile/--ssl-certfile or a reverse proxy) tokens travel in clear text"
    )


def _bind(host: str, port: int) -> socket.socket:
    """Bind here, so a busy port is a clear error (and port 0 gives a free one)."""
    try:
        family = socket.AF_INET6 if ipaddress.ip_address(host).version == 6 else socket.AF_INET
    except ValueError:
        family = socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as err:
        sock.close()
        raise UserError(f"cannot listen on {host}:{port}: {err.strerror or err}") from err
    sock.listen(128)
    sock.set_inheritable(True)
    return sock


def _serve(args, sock, source, params, params_file, auth) -> int:
    import uvicorn

    from i2v_loc.params import ParamsError
    from service.app import create_app, server_config
    from service.core import build_service

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    # The pipeline thread runs much Python code; at the default 5 ms switch interval every
    # request waited several intervals for the GIL (a convoy: REST p50 300-470 ms with 100
    # WebSocket clients on 2 busy cores, 16-29 ms at 0.5 ms, and the pipeline kept up better too).
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    try:
        service = build_service(
            source,
            params,
            params_file,
            auth,
            realtime=not args.no_realtime,
            points_cap=args.max_points,
            method=args.method,
        )
    except ParamsError as err:  # the method's own checks (e.g. the background grid) refuse the parameters
        sock.close()
        raise UserError(f"method {args.method}: {err}") from err
    app = create_app(service)
    host, port = sock.getsockname()[:2]
    shown = f"[{host}]" if ":" in host else host
    scheme = "https" if args.ssl_keyfile else "http"
    url = f"{scheme}://{'127.0.0.1' if host in ('0.0.0.0', '::') else shown}:{port}/"
    _announce(args, source, service, params_file, auth, url)
    tls = {"ssl_keyfile": str(args.ssl_keyfile), "ssl_certfile": str(args.ssl_certfile)} if args.ssl_keyfile else {}
    config = server_config(app, access_log=args.access_log, ws_ping_interval=20.0, ws_ping_timeout=20.0, **tls)
    server = uvicorn.Server(config)
    received: list[int] = []
    # uvicorn shuts down gracefully on SIGINT/SIGTERM, then re-raises the signal to the handler
    # in place before it started: these record it instead of killing the process mid-message.
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, _frame: received.append(signum))
    status = None if args.quiet else _StatusLine(service, url)
    if status:
        status.start()
    try:
        server.run(sockets=[sock])
    finally:
        if status:
            status.stop()
    if service.save_error:
        saved = f"; parameters NOT saved: {service.save_error}"
    else:
        saved = f"; parameters saved to {params_file}" if params_file else ""
    print(f"i2v-loc serve: stopped after {service.runner.frames_processed} frames{saved}", file=sys.stderr)
    return 1 if service.save_error else 0


def _announce(args, source, service, params_file, auth, url) -> None:
    info = service.source_info
    lines = [
        f"i2v-loc serve: source {info.get('source')} ({info.get('frames')} frames at {source.rate_hz:g} Hz"
        f"{', looping' if source.n_frames is None else ''})",
        f"  method     {service.runner.method}",
        f"  dashboard  {url}",
        f"  API        {url}api/v1/  (docs {url}docs)",
        f"  parameters {params_file if params_file else 'not persisted (pass --params FILE to keep changes)'}",
        "  writes     "
        + (
            "need the bearer token"
            if auth.token
            else "disabled: set I2V_LOC_API_TOKEN or pass --token-file PATH to enable them"
        ),
    ]
    if auth.require_token_for_reads:
        lines.append("  reads      need the bearer token")
    if args.host not in LOOPBACK:
        if not auth.require_token_for_reads:
            lines.append(f"  warning    listening on {args.host}: reads are open to the network (--allow-open-reads)")
        if not args.ssl_keyfile:
            lines.append(
                "  warning    no TLS: the token travels in clear text (use --ssl-keyfile/--ssl-certfile "
                "or a reverse proxy)"
            )
    print("\n".join(lines), file=sys.stderr, flush=True)


class _StatusLine:
    """A live status line on the terminal (rewritten in place), or a log line every 10 s."""

    def __init__(self, service, url: str):
        self.service = service
        self.url = url
        self.tty = sys.stderr.isatty()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="i2v-loc-status", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        if self.tty:
            sys.stderr.write("\n")

    def _run(self) -> None:
        interval_s = 1.0 if self.tty else 10.0
        while not self._stop.wait(interval_s):
            line = format_status(self.service.runner.status(), self.service.hub.client_count)
            if self.tty:
                sys.stderr.write("\r\033[K" + line + f" | {self.url}")
            else:
                sys.stderr.write(time.strftime("%H:%M:%S ") + line + "\n")
            sys.stderr.flush()


def format_status(status: dict, ws_clients: int) -> str:
    vehicles = status.get("vehicles") or []
    if vehicles:
        shown = ", ".join(
            f"#{v['id']} {v.get('vehicle') or '?'} hitch "
            + (f"{v['hitch_deg']:+.1f}°" if isinstance(v.get("hitch_deg"), (int, float)) else "-")
            for v in vehicles[:4]
        )
    else:
        shown = "no vehicle"
    drops = sum(status.get("frames_dropped", {}).values())
    return (
        f"{status.get('method') or '?'} | {status.get('frame_rate_hz', 0):5.1f} fps | frame {status.get('frame')} | {shown} | "
        f"dropped {drops} | params v{status.get('params_version')} | ws {ws_clients}"
    )
