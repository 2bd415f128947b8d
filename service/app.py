"""The FastAPI application: REST API under /api/v1, WebSocket /ws/states, /metrics, dashboard /."""

from __future__ import annotations

import asyncio
import contextlib
import copy
import gc
import json
import logging
import math
import threading
import time
from pathlib import Path

import uvicorn
from fastapi import APIRouter, Depends, FastAPI, HTTPException, Request, WebSocket, WebSocketDisconnect
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse, Response
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from fastapi.staticfiles import StaticFiles
from fastapi_offline import FastAPIOffline
from prometheus_client import CONTENT_TYPE_LATEST
from uvicorn.config import LOGGING_CONFIG

from i2v_loc import __version__
from i2v_loc.params import json_schema
from service import models
from service.auth import bearer_from_header
from service.core import Service
from service.params_store import ParamsNotSaved, PatchRejected, UnknownVersion

STATIC_DIR = Path(__file__).with_name("static")
WS_AUTH_TIMEOUT_S = 5.0
MAX_PATCH_BYTES = 1_000_000
MAX_PATCH_DEPTH = 16  # the parameters nest 4 deep (vehicles.NAME.truck.length_m)
PATCH_MEDIA_TYPES = ("application/json", "application/merge-patch+json")
TRUE_WORDS = ("1", "true", "yes", "on")
FALSE_WORDS = ("", "0", "false", "no", "off")
NOT_SAVED_STATUS = 507  # Insufficient Storage: the change is in force, the file could not be written

_bearer = HTTPBearer(auto_error=False, description="The service's API token (I2V_LOC_API_TOKEN or --token-file)")


def _error(status: int, message: str) -> dict:
    return {"description": message, "content": {"application/json": {"example": {"detail": message}}}}


def create_app(service: Service) -> FastAPI:
    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI):
        service.hub.bind(asyncio.get_running_loop())
        service.start()
        gc.freeze()  # the objects of the start-up live forever: full collections skip them (they cost the loop)
        try:
            yield
        finally:
            service.hub.unbind()
            await asyncio.to_thread(service.stop)

    app = FastAPIOffline(  # /docs and /redoc from assets in the package: they work without internet
        title="i2v-loc yard service",
        version=__version__,
        description="Live localization of articulated vehicles (truck + trailer) from infrastructure LiDARs. "
        "Reads are open unless the service runs with --require-token-for-reads; writes need the bearer token.",
        lifespan=lifespan,
    )
    app.state.service = service

    def guard(write: bool):
        def check(creds: HTTPAuthorizationCredentials | None = Depends(_bearer)) -> None:
            decision = service.auth.check(creds.credentials if creds else None, write)
            if not decision.allowed:
                raise HTTPException(decision.status, decision.message, headers=decision.headers or None)

        return check

    # Only the operations that check the token are marked secured in the OpenAPI document: reads
    # are, when the service runs with --require-token-for-reads.
    auth_errors = {401: _error(401, "Token missing"), 403: _error(403, "Token wrong or none configured")}
    write_guard = Depends(guard(True))
    reads_guarded = service.auth.require_token_for_reads
    read_deps = [Depends(guard(False))] if reads_guarded else []
    read_errors = auth_errors if reads_guarded else {}
    api = APIRouter(prefix="/api/v1", dependencies=read_deps, responses=read_errors)

    @app.exception_handler(RequestValidationError)
    async def _invalid_request(request: Request, exc: RequestValidationError):
        errors = [
            {"field": ".".join(str(p) for p in e.get("loc", ())), "message": e.get("msg", ""), "value": e.get("input")}
            for e in exc.errors()
        ]
        return JSONResponse(
            status_code=422,
            content=jsonable_encoder(
                {
                    "detail": "invalid request: " + "; ".join(f"{e['field']}: {e['message']}" for e in errors),
                    "errors": errors,
                }
            ),
        )

    # ------------------------------------------------------------------ state
    # The reads are async: they only copy what the pipeline thread left, so they run on the event
    # loop instead of taking a detour through the thread pool (a quarter of the loop's time under load).

    @api.get("/health", tags=["status"], summary="Liveness, readiness and per-sensor status")
    async def health() -> models.Health:
        return service.health()

    @api.get(
        "/state",
        tags=["state"],
        summary="The latest frame (state line of docs/formats.md)",
        responses={503: _error(503, "No frame processed yet")},
    )
    async def state() -> models.State:
        latest = service.runner.latest
        if latest is None:
            raise HTTPException(503, "no frame has been processed yet; retry shortly", headers={"Retry-After": "1"})
        return latest

    @api.get("/vehicles", tags=["state"], summary="Vehicles of the latest frame")
    async def vehicles() -> models.Vehicles:
        latest = service.runner.latest or {}
        return {
            "frame": latest.get("frame"),
            "stamp_s": latest.get("stamp_s"),
            "vehicles": latest.get("vehicles") or [],
        }

    @api.get(
        "/vehicles/{vehicle_id}",
        tags=["state"],
        summary="One vehicle of the latest frame",
        responses={404: _error(404, "No such vehicle in the latest frame")},
    )
    async def vehicle(vehicle_id: int) -> models.Vehicle:
        latest = service.runner.latest or {}
        found = [v for v in latest.get("vehicles") or [] if v.get("id") == vehicle_id]
        if not found:
            known = [v.get("id") for v in latest.get("vehicles") or []]
            raise HTTPException(404, f"no vehicle with id {vehicle_id} in the latest frame; known ids: {known}")
        return found[0]

    @api.get("/sensors", tags=["status"], summary="Rate, last stamp and drops per sensor")
    async def sensors() -> models.Sensors:
        return {"sensors": service.sensors()}

    # ------------------------------------------------------------------ parameters

    @api.get("/params", tags=["parameters"], summary="The parameters in force and their version")
    async def get_params() -> models.ParamsInForce:
        current = service.store.current
        return {
            "version": current.version,
            "applied_version": service.runner.params_version,
            "params": current.params.model_dump(mode="json"),
        }

    @api.get("/params/schema", tags=["parameters"], summary="JSON Schema of the parameters")
    async def get_schema() -> dict:
        return json_schema()

    @api.get("/params/history", tags=["parameters"], summary="Versions of the parameters since start-up")
    async def get_history() -> models.History:
        return {"current": service.store.version, "versions": service.store.history()}

    patch_body = {
        "requestBody": {
            "required": True,
            "description": "A JSON merge patch (RFC 7396) of the parameters",
            "content": {t: {"schema": {"type": "object"}} for t in PATCH_MEDIA_TYPES},
        }
    }

    @api.patch(
        "/params",
        tags=["parameters"],
        summary="Change parameters with a JSON merge patch",
        dependencies=[write_guard],
        openapi_extra=patch_body,
        response_model=models.ChangeAccepted,
        responses={
            **auth_errors,
            400: _error(400, "Body is not JSON"),
            415: _error(415, "Not a JSON body"),
            422: _error(422, "Validation failed: field, value and allowed range per error"),
            NOT_SAVED_STATUS: _not_saved_doc,
        },
    )
    async def patch_params(request: Request, creds: HTTPAuthorizationCredentials | None = Depends(_bearer)):
        patch = await _json_body(request)
        try:
            version = await in_daemon_thread(service.store.patch, patch, _change_source(service, creds))
        except PatchRejected as err:
            return _rejected(err)
        except ParamsNotSaved as err:
            return _not_saved(err)
        return _accepted(version)

    @api.post(
        "/params/rollback/{version}",
        tags=["parameters"],
        summary="Make an earlier version current again",
        dependencies=[write_guard],
        response_model=models.ChangeAccepted,
        responses={**auth_errors, 404: _error(404, "Unknown version"), NOT_SAVED_STATUS: _not_saved_doc},
    )
    async def rollback(version: int, creds: HTTPAuthorizationCredentials | None = Depends(_bearer)):
        try:
            entry = await in_daemon_thread(service.store.rollback, version, _change_source(service, creds))
        except UnknownVersion as err:
            raise HTTPException(404, err.args[0]) from None
        except PatchRejected as err:  # an old version that today's model refuses
            return _rejected(err)
        except ParamsNotSaved as err:
            return _not_saved(err)
        return _accepted(entry)

    # ------------------------------------------------------------------ metrics, dashboard

    @app.get(
        "/metrics",
        tags=["status"],
        summary="Prometheus metrics",
        dependencies=read_deps,
        response_class=Response,
        responses={200: {"content": {"text/plain": {}}}, **read_errors},
    )
    def metrics() -> Response:
        return Response(service.metrics.render(), media_type=CONTENT_TYPE_LATEST)

    @app.get("/", include_in_schema=False)
    def dashboard() -> FileResponse:
        return FileResponse(STATIC_DIR / "index.html")

    app.mount("/static", StaticFiles(directory=STATIC_DIR), name="static")

    # ``points`` is read by hand: a typed query parameter that fails to parse makes Starlette
    # refuse the handshake with a bare HTTP 403, which reads like an authentication error.
    @app.websocket("/ws/states")
    async def ws_states(websocket: WebSocket):
        await _serve_states(service, websocket, websocket.query_params.get("points"))

    app.include_router(api)
    _document_patch_body(app)
    return app


SHUTDOWN_GRACE_S = 0.5  # open requests get this long at shutdown; the whole stop stays under 2 s


def server_config(app: FastAPI, access_log: bool = False, **options) -> uvicorn.Config:
    """uvicorn's configuration for the service (``i2v-loc serve`` and the tests use it).

    No per-message deflate: compressing every state with points for every client made the event
    loop the bottleneck (each client compresses the same bytes again), and the states are small
    enough uncompressed. A bounded graceful shutdown: a request still running is cut off.
    """
    log_config = copy.deepcopy(LOGGING_CONFIG)
    log_config["handlers"]["access"]["stream"] = "ext://sys.stderr"  # stdout stays empty, as for the rest
    config = uvicorn.Config(
        app,
        log_level="warning",
        access_log=access_log,
        lifespan="on",
        log_config=log_config,
        ws_per_message_deflate=False,
        timeout_graceful_shutdown=SHUTDOWN_GRACE_S,
        **options,
    )
    if access_log:  # uvicorn sets its access logger to log_level, which would silence it
        logging.getLogger("uvicorn.access").setLevel(logging.INFO)
    return config


def patch_schema_components() -> dict[str, dict]:
    """OpenAPI components for a parameter patch: the parameter model with nothing required."""
    schema = json_schema()
    defs = schema.pop("$defs", {})

    def convert(node):
        if isinstance(node, dict):
            out = {k: convert(v) for k, v in node.items() if k != "required"}
            ref = out.get("$ref")
            if isinstance(ref, str) and ref.startswith("#/$defs/"):
                out["$ref"] = "#/components/schemas/ParamsPatch_" + ref.split("/")[-1]
            return out
        if isinstance(node, list):
            return [convert(v) for v in node]
        return node

    components = {f"ParamsPatch_{name}": convert(d) for name, d in defs.items()}
    root = convert(schema)
    root.update(title="ParamsPatch", description="A JSON merge patch of the parameters: any subset of the sections")
    components["ParamsPatch"] = root
    return components


def _document_patch_body(app: FastAPI) -> None:
    """Describe PATCH /params' body with the parameter model (the handler parses it itself)."""
    generate = app.openapi

    def openapi() -> dict:
        if app.openapi_schema is None:
            spec = generate()
            spec.setdefault("components", {}).setdefault("schemas", {}).update(patch_schema_components())
            content = spec["paths"]["/api/v1/params"]["patch"]["requestBody"]["content"]
            for media in content.values():
                media["schema"] = {"$ref": "#/components/schemas/ParamsPatch"}
            app.openapi_schema = spec
        return app.openapi_schema

    app.openapi = openapi


def in_daemon_thread(fn, *args):
    """Run ``fn`` in a daemon thread of its own: unlike ``asyncio.to_thread`` nothing waits for
    it when the server stops, so a change still in flight never holds up the shutdown."""
    loop = asyncio.get_running_loop()
    future = loop.create_future()

    def settle(outcome, error) -> None:
        if not future.done():
            future.set_exception(error) if error is not None else future.set_result(outcome)

    def work() -> None:
        try:
            outcome, error = fn(*args), None
        except Exception as err:  # handed to the awaiting request
            outcome, error = None, err
        with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
            loop.call_soon_threadsafe(settle, outcome, error)

    threading.Thread(target=work, name="i2v-loc-params-change", daemon=True).start()
    return future


def _change_source(service: Service, creds: HTTPAuthorizationCredentials | None) -> str:
    """Who made a change, for the history and the log: the token's id, never the token."""
    return f"token {service.auth.token_id}" if creds is not None else "anonymous"


async def _json_body(request: Request):
    media = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if media not in PATCH_MEDIA_TYPES:
        raise HTTPException(
            415, f"send the patch as JSON (Content-Type {' or '.join(PATCH_MEDIA_TYPES)}), got {media or 'none'!r}"
        )
    body = await _read_limited(request, MAX_PATCH_BYTES)
    if not body.strip():
        raise HTTPException(400, 'empty body: send a JSON object, e.g. {"clustering": {"tolerance_m": 0.5}}')
    try:
        data = json.loads(body, parse_constant=_non_finite, parse_float=_finite_float)
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise HTTPException(400, f"the body is not valid JSON: {err}") from None
    except ValueError as err:
        raise HTTPException(400, str(err)) from None
    except RecursionError:
        raise HTTPException(400, f"the body is nested deeper than {MAX_PATCH_DEPTH} levels") from None
    if nesting_depth(data) > MAX_PATCH_DEPTH:
        raise HTTPException(400, f"the body is nested deeper than {MAX_PATCH_DEPTH} levels; the parameters nest 4 deep")
    return data


async def _read_limited(request: Request, limit: int) -> bytes:
    """The body, refused with 413 by its declared Content-Length or as soon as it passes ``limit``."""
    too_large = HTTPException(413, f"the patch is larger than {limit} bytes")
    declared = request.headers.get("content-length")
    if declared is not None:
        if not declared.strip().isdigit():
            raise HTTPException(400, f"Content-Length {declared!r} is not a number of bytes")
        if int(declared) > limit:
            raise too_large
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > limit:
            raise too_large
        chunks.append(chunk)
    return b"".join(chunks)


def nesting_depth(value) -> int:
    """Levels of objects and arrays in a parsed JSON value (a scalar is 0), without recursion."""
    depth, level = 0, [(value, 1)]
    while level:
        node, d = level.pop()
        children = node.values() if isinstance(node, dict) else node if isinstance(node, list) else None
        if children is None:
            continue
        depth = max(depth, d)
        level.extend((child, d + 1) for child in children)
    return depth


def _non_finite(word: str):
    raise ValueError(f"the body holds {word}: numbers must be finite")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"the body holds {text}, which is out of range for a number")
    return value


_not_saved_doc = {
    "description": "The change is in force but the parameter file could not be written",
    "content": {
        "application/json": {
            "example": {
                "detail": "parameter version 3 is in force but could not be written to yard.yaml: No space left on device; ...",
                "version": 3,
                "in_force": True,
                "saved": False,
            }
        }
    },
}


def _not_saved(err: ParamsNotSaved) -> JSONResponse:
    body = {
        "detail": str(err),
        "version": err.version.version,
        "in_force": True,
        "saved": False,
        "file": str(err.path),
        **_accepted(err.version),
    }
    return JSONResponse(status_code=NOT_SAVED_STATUS, content=jsonable_encoder(body))


def _rejected(err: PatchRejected) -> JSONResponse:
    return JSONResponse(status_code=422, content=jsonable_encoder({"detail": str(err), "errors": err.errors}))


def _accepted(version) -> dict:
    return {
        "version": version.version,
        "source": version.source,
        "patch": version.patch,
        "params": version.params.model_dump(mode="json"),
    }


def parse_flag(text: str | None) -> bool | None:
    """A query flag: true / false in the usual spellings (absent = false), None if neither."""
    word = (text or "").strip().lower()
    if word in TRUE_WORDS:
        return True
    if word in FALSE_WORDS:
        return False
    return None


async def _serve_states(service: Service, websocket: WebSocket, points: str | None) -> None:
    """One JSON message per frame; a slow client only ever gets the newest state."""
    auth = service.auth
    if not auth.origin_allowed(websocket.headers.get("origin"), websocket.headers.get("host"), websocket.url.scheme):
        # Refused before the handshake completes: a page of another site never gets a stream.
        await websocket.close(code=1008, reason="origin not allowed")
        return
    await websocket.accept()
    want_points = parse_flag(points)
    if want_points is None:
        await _ws_refuse(websocket, 400, f"points must be true or false, got {points!r}")
        return
    if not await _ws_authorised(service, websocket):
        return
    client = service.hub.add(want_points)
    sender = asyncio.create_task(_send_loop(websocket, client))
    receiver = asyncio.create_task(_receive_loop(websocket))
    try:
        await asyncio.wait({sender, receiver}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        service.hub.remove(client)
        for task in (sender, receiver):
            task.cancel()
        await asyncio.gather(sender, receiver, return_exceptions=True)


async def _send_loop(websocket: WebSocket, client) -> None:
    with contextlib.suppress(WebSocketDisconnect, RuntimeError, OSError):
        while True:
            text = await client.next_text()
            # the wall-clock send time: frame in (``frame_in_unix_s``) to message out is measured
            await websocket.send_text(f'{text[:-1]},"sent_unix_s":{time.time():.6f}}}')
            client.sent += 1


async def _receive_loop(websocket: WebSocket) -> None:
    """Clients have nothing to say: any message (text or binary) is ignored; this notices them leave."""
    with contextlib.suppress(WebSocketDisconnect, RuntimeError, OSError):
        while True:
            message = await websocket.receive()
            if message.get("type") == "websocket.disconnect":
                return


async def _ws_authorised(service: Service, websocket: WebSocket) -> bool:
    """Token from the Authorization header, or (browsers) a first message {"token": "..."}."""
    auth = service.auth
    if not auth.require_token_for_reads:
        return True
    token = bearer_from_header(websocket.headers.get("authorization"))
    if token is None:
        token = await _first_message_token(websocket)
    decision = auth.check(token, write=False)
    if not decision.allowed:
        await _ws_refuse(websocket, decision.status, decision.message)
        return False
    return True


async def _first_message_token(websocket: WebSocket) -> str | None:
    """The token of a first message {"token": "..."} (text or UTF-8 binary), else None."""
    try:
        first = await asyncio.wait_for(websocket.receive(), WS_AUTH_TIMEOUT_S)
        if first.get("type") == "websocket.disconnect":
            return None
        text = first.get("text") if first.get("text") is not None else (first.get("bytes") or b"").decode()
        token = json.loads(text).get("token")
    except (TimeoutError, ValueError, AttributeError, WebSocketDisconnect, RuntimeError):
        return None
    return token if isinstance(token, str) and token else None


async def _ws_refuse(websocket: WebSocket, status: int, message: str) -> None:
    """An error message {"type": "error", "status", "detail"}, then close code 1008 with the reason."""
    with contextlib.suppress(RuntimeError, WebSocketDisconnect, OSError):
        await websocket.send_text(json.dumps({"type": "error", "status": status, "detail": message}))
        await websocket.close(code=1008, reason=message[:120])
