"""The parameter hand-off every pipeline has: ``update_params`` validates a patch at once (from
any thread), the next frame applies it (``_apply_pending`` -> the pipeline's ``_build``)."""

from __future__ import annotations

import threading

from i2v_loc.params import Params, ParamsError, apply_patch
from i2v_loc.stages.background import check_grid


def check_background(params: Params) -> None:
    if params.background.enabled:
        try:
            check_grid(params.background, params.region)
        except ValueError as err:
            raise ParamsError(f"background: {err}") from err


class ParameterHandoff:
    def _init_params(self, params: Params) -> None:
        check_background(params)
        self._lock = threading.Lock()
        self._pending: Params | None = None
        self._active = params  # written under the lock only once the pipeline is shared

    def _build(self, params: Params) -> None:
        raise NotImplementedError

    @property
    def params(self) -> Params:
        """The latest accepted parameters (a pending patch takes effect at the next frame)."""
        with self._lock:
            return self._pending or self._active

    def update_params(self, patch: dict) -> Params:
        with self._lock:
            new = apply_patch(self._pending or self._active, patch)
            check_background(new)
            self._pending = new
        return new

    def _apply_pending(self) -> None:
        # _active changes under the lock: a patch arriving meanwhile builds on the new parameters
        with self._lock:
            pending, self._pending = self._pending, None
            if pending is not None:
                self._active = pending
        if pending is not None:
            self._build(pending)
