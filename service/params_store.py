"""Versioned parameters of the running service: validation, history, rollback, persistence.

Every accepted change gets the next version number, is written atomically to the parameter file
(if one is configured) and is handed to ``on_change`` (the pipeline runner, which applies it
between two frames). An invalid change raises ``PatchRejected`` and changes nothing.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from i2v_loc.params import Params, ParamsError, apply_patch, describe_validation_error, save_params

HISTORY_LIMIT = 200


class PatchRejected(Exception):
    """A patch failed validation; ``errors`` are records with field, value, message, allowed."""

    def __init__(self, message: str, errors: list[dict[str, Any]]):
        super().__init__(message)
        self.errors = errors


class UnknownVersion(KeyError):
    pass


@dataclass
class Version:
    version: int
    time_s: float
    source: str
    patch: dict
    params: Params = field(repr=False)

    def summary(self) -> dict:
        return {"version": self.version, "time_s": self.time_s, "source": self.source, "patch": self.patch}


def merge_patch_diff(old: Any, new: Any) -> dict:
    """The JSON merge patch (RFC 7396) that turns dict ``old`` into dict ``new``."""
    patch: dict = {}
    for key in old.keys() - new.keys():
        patch[key] = None
    for key, value in new.items():
        if key not in old:
            patch[key] = value
        elif isinstance(value, dict) and isinstance(old[key], dict):
            sub = merge_patch_diff(old[key], value)
            if sub:
                patch[key] = sub
        elif value != old[key]:
            patch[key] = value
    return patch


class ParamStore:
    def __init__(self, params: Params, path: str | Path | None = None,
                 on_change: Callable[[Version], None] | None = None):
        self._lock = threading.Lock()
        self.path = Path(path) if path else None
        self.on_change = on_change
        self._history: list[Version] = [Version(0, time.time(), "start", {}, params)]

    @property
    def current(self) -> Version:
        return self._history[-1]

    @property
    def params(self) -> Params:
        return self.current.params

    @property
    def version(self) -> int:
        return self.current.version

    def history(self) -> list[dict]:
        return [v.summary() for v in self._history]

    def get(self, version: int) -> Version:
        for v in self._history:
            if v.version == version:
                return v
        known = [v.version for v in self._history]
        raise UnknownVersion(f"no parameter version {version}; known versions: {known[0]}..{known[-1]}")

    def patch(self, patch: Any, source: str = "patch") -> Version:
        """Validate and apply a JSON merge patch; raises ``PatchRejected``."""
        with self._lock:
            new_params = _validated(self.params, patch)
            return self._commit(new_params, patch, source)

    def rollback(self, version: int) -> Version:
        """A new version whose parameters equal those of ``version``."""
        with self._lock:
            target = self.get(version).params
            patch = merge_patch_diff(self.params.model_dump(mode="json"), target.model_dump(mode="json"))
            return self._commit(target, patch, f"rollback to {version}")

    def save(self) -> None:
        if self.path is not None:
            save_params(self.params, self.path)

    def _commit(self, params: Params, patch: dict, source: str) -> Version:
        entry = Version(self.current.version + 1, time.time(), source, patch, params)
        if self.path is not None:
            save_params(params, self.path)
        self._history.append(entry)
        del self._history[:-HISTORY_LIMIT]
        if self.on_change is not None:
            self.on_change(entry)
        return entry


def _validated(params: Params, patch: Any) -> Params:
    try:
        return apply_patch(params, patch)
    except ParamsError as err:
        cause = err.__cause__
        if isinstance(cause, ValidationError):
            errors = describe_validation_error(cause, "patch")
        else:
            errors = [{"source": "patch", "field": "", "value": None, "message": str(err), "allowed": ""}]
        raise PatchRejected(str(err), errors) from err
