"""Versioned parameters of the running service: validation, history, rollback, persistence.

A change is validated against the parameter model, then handed to ``on_change`` (the pipeline
runner, which has the pipeline check it at once and apply it between two frames); only then does
it get the next version number and is written atomically to the parameter file (if one is
configured). An invalid change, or one the pipeline refuses, raises ``PatchRejected`` and changes
nothing. A change in force whose file could not be written raises ``ParamsNotSaved``.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ValidationError

from i2v_loc.params import MAX_ERRORS_REPORTED, Params, ParamsError, apply_patch, describe_validation_error, save_params

log = logging.getLogger("i2v_loc.service")

HISTORY_LIMIT = 200  # versions kept; version 0 (the parameters loaded at start) is always kept


class PatchRejected(Exception):
    """A patch failed validation; ``errors`` are records with field, value, message, allowed."""

    def __init__(self, message: str, errors: list[dict[str, Any]]):
        super().__init__(message)
        self.errors = errors


class UnknownVersion(KeyError):
    pass


class ParamsNotSaved(Exception):
    """A change is in force (``version``) but the parameter file could not be written."""

    def __init__(self, version: Version, path: Path, error: OSError):
        reason = error.strerror or str(error)
        super().__init__(
            f"parameter version {version.version} is in force but could not be written to {path}: "
            f"{reason}; it will be lost at a restart unless a later change or the shutdown saves it"
        )
        self.version = version
        self.path = path
        self.reason = reason


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
    def __init__(
        self, params: Params, path: str | Path | None = None, on_change: Callable[[Version], None] | None = None
    ):
        self._lock = threading.Lock()
        self._save_lock = threading.Lock()  # one writer of the file at a time (a change, the shutdown)
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
        """Validate and apply a JSON merge patch; raises ``PatchRejected`` or ``ParamsNotSaved``."""
        with self._lock:
            _refuse_section_nulls(patch)
            _refuse_unknown_keys(patch)
            new_params = _validated(self.params, patch)
            return self._commit(new_params, patch, source)

    def rollback(self, version: int, source: str | None = None) -> Version:
        """A new version whose parameters equal those of ``version``."""
        with self._lock:
            target = self.get(version).params
            patch = merge_patch_diff(self.params.model_dump(mode="json"), target.model_dump(mode="json"))
            return self._commit(target, patch, f"rollback to {version}" + (f" by {source}" if source else ""))

    def save(self) -> None:
        """Write the parameters in force to the file (OSError if it cannot be written)."""
        if self.path is not None:
            with self._save_lock:
                save_params(self.params, self.path)

    def _commit(self, params: Params, patch: dict, source: str) -> Version:
        entry = Version(self.current.version + 1, time.time(), source, patch, params)
        if self.on_change is not None:
            try:
                self.on_change(entry)
            except ValueError as err:  # ParamsError: a check only the pipeline makes (e.g. grid size)
                raise PatchRejected(
                    f"{source}: the pipeline refused the parameters: {err}",
                    [{"source": source, "field": "", "value": None, "message": str(err), "allowed": ""}],
                ) from err
        log.info(
            "parameter version %d (%s): %s",
            entry.version,
            source,
            describe_changes(self.params.model_dump(mode="json"), params.model_dump(mode="json")),
        )
        self._history.append(entry)
        if len(self._history) > HISTORY_LIMIT:
            del self._history[1 : len(self._history) - HISTORY_LIMIT + 1]
        if self.path is not None:
            try:
                with self._save_lock:
                    save_params(params, self.path)
            except OSError as err:
                failure = ParamsNotSaved(entry, self.path, err)
                log.error("%s", failure)
                raise failure from err
        return entry


def describe_changes(old: dict, new: dict, limit: int = 20) -> str:
    """'a.b: 1 -> 2, c: x -> (removed)', from the merge patch of ``old`` to ``new``."""
    changes: list[str] = []

    def walk(patch: dict, before: Any, prefix: str) -> None:
        for key, value in patch.items():
            name, previous = f"{prefix}{key}", before.get(key) if isinstance(before, dict) else None
            if isinstance(value, dict) and isinstance(previous, dict):
                walk(value, previous, name + ".")
            else:
                changes.append(f"{name}: {_short(previous)} -> {'(removed)' if value is None else _short(value)}")

    walk(merge_patch_diff(old, new), old, "")
    more = f", and {len(changes) - limit} more" if len(changes) > limit else ""
    return (", ".join(changes[:limit]) + more) or "no change"


def _short(value: Any, width: int = 80) -> str:
    text = json.dumps(value, separators=(",", ":"), default=str)
    return text if len(text) <= width else text[: width - 3] + "..."


def _refuse_section_nulls(patch: Any) -> None:
    """``{"section": null}`` would silently reset a whole section (all sensors, all vehicles) to
    the built-in defaults: refused; ``null`` inside a section (a field, a vehicle) is fine."""
    if not isinstance(patch, dict):
        return
    nulls = sorted(str(k) for k, v in patch.items() if v is None)
    if nulls:
        errors = [
            {
                "source": "patch",
                "field": name,
                "value": None,
                "allowed": "an object (or a list for sensors)",
                "message": "null would reset the whole section to the built-in defaults; "
                "send the fields to change (null inside a section resets that field)",
            }
            for name in nulls
        ]
        raise PatchRejected(
            f"patch: {', '.join(nulls)} = null: a whole section cannot be deleted; send the fields to change instead",
            errors,
        )


def _refuse_unknown_keys(patch: Any) -> None:
    """Unknown sections and unknown fields of the flat sections, found by set arithmetic before
    the model is validated: a patch of a hundred thousand unknown keys is refused in milliseconds
    (pydantic would describe every one of them) and never holds the lock for long."""
    if not isinstance(patch, dict):
        return
    unknown = [str(k) for k in patch if k not in Params.model_fields]
    for section, value in patch.items():
        field = Params.model_fields.get(section)
        model = getattr(field, "annotation", None)
        if isinstance(value, dict) and isinstance(model, type) and issubclass(model, BaseModel):
            unknown.extend(f"{section}.{k}" for k in value if k not in model.model_fields)
        limit = next((m.max_length for m in getattr(field, "metadata", ()) if hasattr(m, "max_length")), None)
        if limit is not None and isinstance(value, (list, dict)) and len(value) > limit:
            raise PatchRejected(
                f"patch: {section} holds {len(value)} entries, at most {limit} are allowed",
                [
                    {
                        "source": "patch",
                        "field": section,
                        "value": None,
                        "allowed": f"at most {limit} entries",
                        "message": f"{len(value)} entries",
                    }
                ],
            )
    if not unknown:
        return
    shown = unknown[:MAX_ERRORS_REPORTED]  # in the order sent
    errors = [
        {"source": "patch", "field": name, "value": None, "allowed": "", "message": "unknown key"} for name in shown
    ]
    more = f" (and {len(unknown) - len(shown)} more)" if len(unknown) > len(shown) else ""
    raise PatchRejected(
        f"patch: {len(unknown)} unknown keys: {', '.join(shown)}{more}; GET /api/v1/params/schema lists the known ones",
        errors,
    )


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
