"""Pipelines composed from the stages of ``i2v_loc.stages`` (composition only, no stage logic).

- ``paper``: the published pipeline, kept faithful for comparison (``paper.py``).
- ``default``: the articulated estimator (``articulated.py``); ``articulated`` is another name for it.

``build_pipeline(params, method)`` builds one; every pipeline has ``process(frame) -> FrameResult``,
``update_params(patch)``, ``params``, ``counters`` and ``method``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from i2v_loc.params import DEFAULT_METHOD, Params

if TYPE_CHECKING:
    from i2v_loc.pipelines.articulated import ArticulatedPipeline
    from i2v_loc.pipelines.paper import PaperPipeline

METHODS = ("paper", "default")
ALIASES = {"articulated": "default"}


def method_name(method: str) -> str:
    """The method's name in ``METHODS`` (an alias resolved); ValueError for an unknown one."""
    name = ALIASES.get(method, method)
    if name not in METHODS:
        raise ValueError(f"unknown method {method!r}; known: {', '.join(METHODS)}")
    return name


def build_pipeline(params: Params, method: str = DEFAULT_METHOD) -> PaperPipeline | ArticulatedPipeline:
    """The pipeline of ``method`` over ``params`` (only its own module is imported: the paper's
    tracker needs filterpy and scipy.stats, half a second of start-up)."""
    if method_name(method) == "paper":
        from i2v_loc.pipelines.paper import PaperPipeline

        return PaperPipeline(params)
    from i2v_loc.pipelines.articulated import ArticulatedPipeline

    return ArticulatedPipeline(params)
