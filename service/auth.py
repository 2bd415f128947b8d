"""Bearer-token access control. The token is never logged or echoed back."""

from __future__ import annotations

import hashlib
import hmac
import os
from dataclasses import dataclass, field
from pathlib import Path

TOKEN_ENV = "I2V_LOC_API_TOKEN"
HOW_TO_SET = (
    f"no API token is configured, so writes are disabled: start the service with the environment "
    f"variable {TOKEN_ENV} set, or with --token-file PATH (a file holding the token)"
)


class TokenError(ValueError):
    pass


def load_token(token_file: str | Path | None = None, environ: dict | None = None) -> str | None:
    """The token from ``token_file`` if given, else from the environment; None if neither."""
    if token_file is not None:
        path = Path(token_file)
        try:
            token = path.read_text().strip()
        except OSError as err:
            raise TokenError(f"cannot read the token file {path}: {err.strerror or err}") from err
        if not token:
            raise TokenError(f"the token file {path} is empty")
        return token
    token = (environ if environ is not None else os.environ).get(TOKEN_ENV, "").strip()
    return token or None


@dataclass(frozen=True)
class AuthDecision:
    allowed: bool
    status: int = 200
    message: str = ""
    headers: dict = field(default_factory=dict)


@dataclass(frozen=True)
class AuthConfig:
    token: str | None = field(default=None, repr=False)
    require_token_for_reads: bool = False
    # Browser pages allowed to open the WebSocket besides the service's own (scheme://host[:port]).
    allowed_origins: tuple[str, ...] = ()

    @property
    def token_id(self) -> str:
        """Names the token in logs and the parameter history without revealing it."""
        return hashlib.sha256(self.token.encode()).hexdigest()[:8] if self.token else "none"

    def origin_allowed(self, origin: str | None, host: str | None, ws_scheme: str = "ws") -> bool:
        """A WebSocket handshake from ``origin``: clients outside a browser send none (allowed);
        a browser page must come from this service itself or from an allowed origin."""
        if origin is None:
            return True
        origin = origin.rstrip("/").lower()
        page_scheme = {"ws": "http", "wss": "https"}.get(ws_scheme, ws_scheme)
        if host and origin == f"{page_scheme}://{host}".lower():
            return True
        return origin in {o.rstrip("/").lower() for o in self.allowed_origins}

    def check(self, presented: str | None, write: bool) -> AuthDecision:
        """Decide on a request carrying bearer token ``presented`` (None when absent)."""
        if not write and not self.require_token_for_reads:
            return AuthDecision(True)
        if self.token is None:
            return AuthDecision(False, 403, HOW_TO_SET)
        if presented is None:
            return AuthDecision(
                False,
                401,
                "a bearer token is required: send the header 'Authorization: Bearer <token>'",
                {"WWW-Authenticate": "Bearer"},
            )
        if not hmac.compare_digest(presented.encode(), self.token.encode()):
            return AuthDecision(False, 403, "the bearer token is not valid")
        return AuthDecision(True)


def bearer_from_header(value: str | None) -> str | None:
    """The token of an 'Authorization: Bearer <token>' header; None if absent or another scheme."""
    if not value:
        return None
    scheme, _, token = value.strip().partition(" ")
    if scheme.lower() != "bearer" or not token.strip():
        return None
    return token.strip()
