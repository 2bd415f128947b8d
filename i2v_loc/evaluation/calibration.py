"""Calibrate each recording as a user would before evaluating it, once, cached.

``i2v-loc eval`` and ``sweep`` run the project's ICP calibration (``stages/calibration.py``) from
the recording's ``sensors_guess.yaml`` and evaluate with the result: the sensors of the guess with
the calibrated extrinsics, exactly the file ``i2v-loc calibrate`` writes. The result is cached,
keyed by the recording's path and content (meta.yaml, scan sizes), the guess's content and the
calibration parameters, so a second evaluation does not calibrate again. When the calibration is
refused for a sensor (``SensorCalibration.accepted``) that sensor is left out (``enabled``
false), the others evaluated with their calibration, and the status says so. Each sensor's error against the truth (``sensors.yaml``) is
measured: translation (cm), rotation (deg) and clock offset (ms).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

CACHE_VERSION = 7  # 7: a refused sensor left out (enabled: false); 6: a low fitness accepted when better than the guess's, every direction determined; 5: a refused sensor at its guess, the others calibrated; 4: structure correspondences on one side

CALIBRATED = "calibrated"
REFUSED = "refused"  # a sensor's result not accepted: that sensor left out (``accepted_sensors``)
NO_GUESS = "no_guess"  # no sensors_guess.yaml: evaluated with sensors.yaml
FROM_PARAMS = "from_params"  # the --params files set the sensors
TRUE = "true_extrinsics"  # --true-extrinsics (diagnosis)
LOUD = (REFUSED, NO_GUESS)


def default_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "i2v-loc" / "calibration"


def recording_windows(recording, sensors, windows: int, gap_frames: int) -> list[dict[str, list[np.ndarray]]]:
    """``windows`` windows spread evenly over the recording; per window and sensor, the points of
    three sweeps ``gap_frames`` apart (fewer when the recording is too short)."""
    names = {s.name for s in sensors}
    n = len(recording)
    gap = min(gap_frames, max(0, (n - 1) // 2))
    middles = np.unique(np.linspace(gap, n - 1 - gap, max(1, min(windows, n))).round().astype(int))
    result = []
    for middle in middles:
        window: dict[str, list[np.ndarray]] = {name: [] for name in names}
        for index in sorted({middle - gap, middle, middle + gap}):
            for name, scan in recording.frame(int(index)).scans.items():
                if name in window:
                    window[name].append(scan.points)
        result.append(window)
    return result


def extrinsics_error(estimate, truth) -> tuple[float, float]:
    """(translation error in cm, rotation error in deg) of two ``Extrinsics``."""
    from i2v_loc.geometry import extrinsics_matrix, rotation_angle_rad

    a, b = extrinsics_matrix(estimate), extrinsics_matrix(truth)
    return (
        float(100.0 * np.linalg.norm(a[:3, 3] - b[:3, 3])),
        float(np.degrees(rotation_angle_rad(a[:3, :3], b[:3, :3]))),
    )


def sensor_errors(used, truth) -> list[dict]:
    """Per sensor of ``used`` (SensorConfig list): its errors against ``truth`` (same names)."""
    true_by_name = {s.name: s for s in truth}
    rows = []
    for sensor in used:
        true = true_by_name.get(sensor.name)
        row = {"sensor": sensor.name, "error_cm": None, "error_deg": None, "clock_error_ms": None}
        if true is not None:
            row["error_cm"], row["error_deg"] = extrinsics_error(sensor.extrinsics, true.extrinsics)
            row["clock_error_ms"] = 1000.0 * (sensor.time_offset_s - true.time_offset_s)
        rows.append(row)
    return rows


def _file_hash(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else "-"


def cache_key(recording, calibration_params) -> str:
    """Hash of what the calibration depends on (module docstring)."""
    root = Path(recording.path)
    files = sorted((str(p.relative_to(root)), p.stat().st_size) for p in root.rglob("*") if p.is_file())
    content = {
        "version": CACHE_VERSION,
        "recording": str(root.resolve()),
        "meta": _file_hash(root / "meta.yaml") if (root / "meta.yaml").is_file() else None,
        "files": files,
        "guess": _file_hash(recording.sensors_guess_file),
        "calibration": calibration_params.model_dump(mode="json"),
    }
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()


def weak_warning(results, min_points: float) -> str | None:
    """The warning for sensors whose weakest horizontal direction has fewer than ``min_points``
    points of information (``SensorCalibration.constraint_points``), or None."""
    weak = [r for r in results if r.constraint_points < min_points]
    if not weak:
        return None
    names = ", ".join(f"{r.name} ({r.constraint_points:.0f})" for r in weak)
    return (
        f"weakly constrained calibration for {names} (fewer than {min_points:.0f} points of overlapping "
        "structure in one horizontal direction): the error along it can reach tens of centimetres; "
        "a vehicle standing where these sensors and their neighbours see it would constrain it"
    )


def run_calibration(recording, params, progress=None) -> tuple[list, bool]:
    """(SensorCalibration per sensor, refused) of the project's calibration on ``recording``
    from ``params.sensors`` (the guess). ``ValueError`` when it cannot run at all. ``progress``:
    called with each ``SensorCalibration`` as it is done."""
    from i2v_loc.stages.calibration import Calibrator

    section = params.calibration
    windows = recording_windows(recording, params.sensors, section.windows, section.window_gap_frames)
    results = Calibrator(section).calibrate(params.sensors, windows, progress)
    refused = any(not r.accepted(params.calibration.min_fitness) for r in results)
    return results, refused


def accepted_sensors(guess_sensors, results, min_fitness: float) -> tuple[list, list]:
    """The guess's sensors with the calibrated extrinsics where the calibration was accepted and,
    where it was refused (``SensorCalibration.accepted``), the guessed ones left out (``enabled``
    false; the accepted ones enabled, also when the guess, a file written before, had them off), and the
    refused results. One sensor whose registration failed leaves the others'
    calibrations standing: a refused one had made every sensor of a sloped docking stay at its
    guess, 52 cm off (38.7 % success; 94.0 % with the others calibrated). Fused at its guess (52 cm
    and 3.4 deg off), that one sensor's points made held-out generalization +1300's unknown 10.5 m
    trailer's truck 0.142 m off and its hitch 0.66 deg (0.044 m and 0.41 deg left out)."""
    by_name = {r.name: r for r in results}
    refused = [by_name[s.name] for s in guess_sensors if not by_name[s.name].accepted(min_fitness)]
    calibrated = calibrated_sensors(guess_sensors, results)
    sensors = [
        c.model_copy(update={"enabled": True})
        if by_name[g.name].accepted(min_fitness)
        else g.model_copy(update={"enabled": False})
        for g, c in zip(guess_sensors, calibrated)
    ]
    return sensors, refused


def calibrated_sensors(guess_sensors, results) -> list:
    """The guess's sensors with the calibrated extrinsics of ``results`` (accepted or not)."""
    by_name = {r.name: r.extrinsics for r in results}
    return [s.model_copy(update={"extrinsics": by_name[s.name]}) for s in guess_sensors]


def refused_message(refused, min_fitness: float) -> str:
    """What a refusal means, naming the refused sensors."""
    from i2v_loc.stages.calibration import DETERMINED_POINTS

    low = ", ".join(
        f"{r.name} ({r.fitness:.2f}, {r.guess_fitness:.2f} at the guess, weakest direction "
        f"{r.constraint_points:.1f} points)"
        for r in refused
    )
    return (
        f"CALIBRATION REFUSED (fitness below {min_fitness} and no better than at the guess, or a "
        f"horizontal direction with less than {DETERMINED_POINTS:.0f} point of information: {low}): "
        "left out (enabled: false, at the guess of sensors_guess.yaml), the other sensors calibrated"
    )


def calibrate_recording(recording_path: str, patch: dict, cache_dir: str | Path | None = None) -> dict:
    """The sensors to evaluate ``recording_path`` with, and how they were obtained (a JSON-able
    dict: ``recording``, ``status``, ``message``, ``sensors`` (list of sensor dicts; None = the
    recording's sensors.yaml), ``per_sensor`` (fitness and errors against the truth), ``cached``).
    ``patch`` is the merged --params files: its calibration section is used."""
    from i2v_loc.formats import open_recording
    from i2v_loc.params import apply_patch, load_params

    recording = open_recording(recording_path)
    name = Path(recording_path).name
    truth = load_params(recording.sensors_file).sensors if recording.sensors_file.is_file() else []
    if "sensors" in patch:
        return _status(name, FROM_PARAMS, "sensors from the --params files (not calibrated here)", None, [])
    if not recording.sensors_guess_file.is_file():
        used = truth
        return _status(
            name,
            NO_GUESS,
            "NO sensors_guess.yaml: evaluated with the recording's sensors.yaml "
            "(true extrinsics for a simulated recording)",
            None,
            sensor_errors(used, truth),
        )
    guess = apply_patch(load_params(recording.sensors_guess_file), patch, source=f"{recording_path}: --params")
    cache = Path(cache_dir) if cache_dir else default_cache_dir()
    file = cache / f"{name}-{cache_key(recording, guess.calibration)[:20]}.json"
    if file.is_file():
        cached = json.loads(file.read_text())
        cached["cached"] = True
        return cached
    results, _ = run_calibration(recording, guess)
    by_name = {r.name: r for r in results}
    calibrated = calibrated_sensors(guess.sensors, results)
    used, refused = accepted_sensors(guess.sensors, results, guess.calibration.min_fitness)
    rows = []
    for row, cal_row, guess_row in zip(
        sensor_errors(used, truth), sensor_errors(calibrated, truth), sensor_errors(guess.sensors, truth)
    ):
        r = by_name[row["sensor"]]
        row.update(
            fitness=r.fitness,
            guess_fitness=r.guess_fitness,
            inlier_rmse_m=r.inlier_rmse_m,
            target=r.target,
            constraint_points=r.constraint_points if np.isfinite(r.constraint_points) else None,
            calibrated_error_cm=cal_row["error_cm"],
            calibrated_error_deg=cal_row["error_deg"],
            guess_error_cm=guess_row["error_cm"],
            guess_error_deg=guess_row["error_deg"],
        )
        rows.append(row)
    if refused:
        message = refused_message(refused, guess.calibration.min_fitness)
        result = _status(name, REFUSED, message, [s.model_dump(mode="json") for s in used], rows)
    else:
        result = _status(
            name, CALIBRATED, "calibrated from sensors_guess.yaml", [s.model_dump(mode="json") for s in used], rows
        )
    result["warning"] = weak_warning(results, guess.calibration.min_constraint_points)
    cache.mkdir(parents=True, exist_ok=True)
    tmp = file.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_text(json.dumps(result, indent=1))
    tmp.replace(file)  # atomic: a concurrent evaluation reads either nothing or the whole entry
    return result


def true_extrinsics_status(recording_path: str) -> dict:
    return _status(
        Path(recording_path).name,
        TRUE,
        "TRUE extrinsics and clock offsets (--true-extrinsics: diagnosis only, not what a deployment has)",
        None,
        [],
    )


def _status(name: str, status: str, message: str, sensors: list[dict] | None, rows: list[dict]) -> dict:
    return {
        "recording": name,
        "status": status,
        "message": message,
        "sensors": sensors,
        "per_sensor": rows,
        "cached": False,
    }


def calibration_job(item: tuple) -> dict:
    """``run_tasks`` entry: ``(recording, patch, cache_dir)`` -> ``calibrate_recording``; a failure
    is re-raised as EvaluationError naming the recording."""
    from i2v_loc.evaluation.runner import EvaluationError

    recording, patch, cache_dir = item
    try:
        return calibrate_recording(recording, patch, cache_dir)
    except Exception as err:
        raise EvaluationError(f"{Path(recording).name} [calibration]: {type(err).__name__}: {err}") from None


def task_patch(patch: dict, calibration: dict) -> dict:
    """The parameter patch of a recording's tasks: its calibrated (or guessed) sensors replace
    sensors.yaml's, then the --params files (``patch``) as given."""
    from i2v_loc.params import deep_merge

    if calibration.get("sensors") is None:
        return patch
    return deep_merge({"sensors": calibration["sensors"]}, patch)


def calibrate_recordings(
    recordings: list, patch: dict, true_extrinsics: bool = False, cache_dir: str | Path | None = None, **run_kwargs
) -> dict[str, dict]:
    """``{recording path: calibrate_recording(...)}`` for every recording (in parallel like the
    evaluation's tasks; ``run_kwargs`` go to ``run_tasks``), or the true-extrinsics status."""
    from i2v_loc.evaluation.runner import run_tasks

    if true_extrinsics:
        return {str(r): true_extrinsics_status(str(r)) for r in recordings}
    items = [(str(r), patch, str(cache_dir) if cache_dir else None) for r in recordings]
    results = run_tasks(items, func=calibration_job, desc="calibrating", **run_kwargs)
    return {str(r): result for r, result in zip(recordings, results)}
