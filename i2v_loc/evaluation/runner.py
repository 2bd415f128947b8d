"""Run the pipeline over recordings and compare with the truth, in parallel.

One task = one recording x one method x one sensor subset x one parameter set. Tasks are
independent, so they run inline, in local processes (concurrent.futures) or on a Dask
distributed cluster; the results are the same, returned in task order.
"""

from __future__ import annotations

import itertools
import multiprocessing
import traceback
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

from i2v_loc.params import Params, apply_patch, deep_merge, load_params, read_yaml, validate_params

EXECUTORS = ("local", "dask")


class EvaluationError(RuntimeError):
    """A task failed; the message names the recording, method and sensors."""


@dataclass(frozen=True)
class Task:
    recording: str
    method: str
    sensors: tuple[str, ...] | None = None  # None = all sensors of the recording
    params: dict = field(default_factory=dict, hash=False, compare=False)  # patch applied after REC/sensors.yaml
    labels: str | None = None  # ground truth other than the recording's ground_truth.jsonl
    gate_m: float = 4.0
    tag: str = ""  # free label (the sweep's combination index)

    @property
    def subset(self) -> str:
        return "+".join(self.sensors) if self.sensors else "all"

    @property
    def name(self) -> str:
        return f"{Path(self.recording).name} [{self.method}, {self.subset}{', ' + self.tag if self.tag else ''}]"


def recording_params(patch: dict, recording: str, sensors: Sequence[str] | None) -> Params:
    """The parameters for a recording, in the order of ``i2v-loc run``: the defaults, then the
    recording's sensors.yaml (its true extrinsics), then ``patch`` (the --params files merged, see
    ``base_params``), then only the chosen sensors."""
    from i2v_loc.formats import open_recording

    rec = open_recording(recording)
    params = load_params(rec.sensors_file if rec.sensors_file.is_file() else None)
    params = apply_patch(params, patch, source=f"{recording}: parameters after its sensors.yaml")
    if sensors:
        known = [s.name for s in params.sensors]
        missing = [s for s in sensors if s not in known]
        if missing:
            raise EvaluationError(f"{recording}: sensors {missing} not in the parameters (known: {known})")
        params = params.model_copy(update={"sensors": [s for s in params.sensors if s.name in sensors]})
    return params


def run_pipeline(task: Task) -> list[dict]:
    """State lines of the pipeline on every frame of the task's recording."""
    from i2v_loc.formats import open_recording
    from i2v_loc.pipelines import build_pipeline

    rec = open_recording(task.recording)
    params = recording_params(task.params, task.recording, task.sensors)
    pipeline = build_pipeline(params, task.method)
    return [pipeline.process(frame).to_json() for frame in rec.frames(sensors=task.sensors)]


def run_task(task: Task) -> dict:
    """Run one task: the pipeline, then the comparison. Returns records and frame rows tagged
    with the task's method, subset, recording and tag."""
    from i2v_loc.evaluation.groundtruth import load_ground_truth, seen_by
    from i2v_loc.evaluation.matching import match_states

    try:
        if task.labels:
            from i2v_loc.formats import open_recording

            gt_lines = load_ground_truth(task.labels, rate_hz=open_recording(task.recording).rate_hz)
        else:
            gt_lines = load_ground_truth(task.recording)
        if task.sensors:
            gt_lines = seen_by(gt_lines, task.sensors)
        states = run_pipeline(task)
        params = recording_params(task.params, task.recording, task.sensors)
        records, frames = match_states(states, gt_lines, params, task.gate_m)
    except Exception as err:  # re-raised in the parent with the task named
        raise EvaluationError(f"{task.name}: {type(err).__name__}: {err}\n{traceback.format_exc()}") from None
    tags = {"method": task.method, "subset": task.subset, "recording": Path(task.recording).name, "tag": task.tag}
    for row in itertools.chain(records, frames):
        row.update(tags)
    return {"task": tags, "records": records, "frames": frames}


def run_tasks(
    tasks: Sequence,
    func: Callable = run_task,
    workers: int = 1,
    executor: str = "local",
    address: str | None = None,
    progress: bool = True,
    desc: str = "evaluating",
) -> list:
    """``func`` over ``tasks``, results in task order, with a tqdm progress bar."""
    from tqdm import tqdm

    if executor not in EXECUTORS:
        raise ValueError(f"unknown executor {executor!r}; choose one of {', '.join(EXECUTORS)}")
    bar = tqdm(total=len(tasks), desc=desc, unit="task", disable=not progress)
    try:
        if executor == "dask":
            return _run_dask(tasks, func, workers, address, bar)
        if workers <= 1 or len(tasks) <= 1:
            out = []
            for task in tasks:
                out.append(func(task))
                bar.update()
            return out
        return _run_processes(tasks, func, workers, bar)
    finally:
        bar.close()


def _run_processes(tasks, func, workers, bar) -> list:
    # spawn, not fork: forking a parent with live TBB/OpenMP threads (Open3D) can deadlock
    context = multiprocessing.get_context("spawn")
    results: list = [None] * len(tasks)
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = {pool.submit(func, task): i for i, task in enumerate(tasks)}
        for future in as_completed(futures):
            results[futures[future]] = future.result()
            bar.update()
    return results


DASK_CONNECT_TIMEOUT = "10s"


def _run_dask(tasks, func, workers, address, bar) -> list:
    try:
        from distributed import Client, LocalCluster
        from distributed import as_completed as dask_completed
    except ImportError as err:
        raise EvaluationError("the dask executor needs Dask distributed: pip install 'i2v-loc[distributed]'") from err
    cluster = None
    if address:
        try:
            client = Client(address, timeout=DASK_CONNECT_TIMEOUT)
        except (OSError, ValueError, TypeError) as err:  # unreachable, or not an address
            raise EvaluationError(f"cannot connect to the Dask scheduler at {address!r}: {err}") from None
    else:
        cluster = LocalCluster(n_workers=max(1, workers), threads_per_worker=1, processes=True)
        client = Client(cluster)
    try:
        futures = client.map(func, list(tasks), pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        results: list = [None] * len(tasks)
        for future in dask_completed(futures):
            results[index[future.key]] = future.result()
            bar.update()
        return results
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def base_params(params_files: str | Path | Sequence[str | Path] | None = None) -> dict:
    """The --params files merged in order into one patch (not over the defaults, so that a file
    without a sensors section keeps each recording's sensors.yaml). Each file is validated over the
    defaults here, so a bad file fails before any task starts."""
    if params_files is None:
        files: list = []
    elif isinstance(params_files, (str, Path)):
        files = [params_files]
    else:
        files = list(params_files)
    load_params(*files)
    patch: dict = {}
    for path in files:
        patch = deep_merge(patch, read_yaml(path))
    return patch


def compare_task(item: dict) -> dict:
    """Compare already computed state lines with the truth (e.g. a saved ``i2v-loc run`` log):
    ``item`` holds ``states``, ``ground_truth`` (GT lines), ``params`` (dump) and ``task``
    (method, subset, recording, tag). Same output as ``run_task``."""
    from i2v_loc.evaluation.matching import match_states

    params = validate_params(item.get("params") or {}, source="parameters")
    records, frames = match_states(item["states"], item["ground_truth"], params, item.get("gate_m", 4.0))
    tags = {"method": "paper", "subset": "all", "recording": "", "tag": "", **item.get("task", {})}
    for row in itertools.chain(records, frames):
        row.update(tags)
    return {"task": tags, "records": records, "frames": frames}
