"""Frame sources for the live service: replay of a recording directory, and the simulated yard.

A source is random access by a running frame number ``k`` (0, 1, 2, ...): ``frame(k)`` returns the
``Frame`` the sensors deliver at ``k / rate_hz`` seconds after the start. A looping replay keeps
time monotonic: lap ``n`` shifts every sensor stamp by ``n`` times the recording's duration, so a
tracker sees the vehicle jump back to its start position, never time running backwards.

The simulated yard is a recording generated once by ``i2v-loc sim`` (cached per scenario, vehicle,
seed and duration) and replayed in a loop.
"""

from __future__ import annotations

import logging
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass, replace
from pathlib import Path

from i2v_loc.formats import open_recording
from i2v_loc.frame import Frame
from i2v_loc.recording import RecordingError

DEFAULT_SCENARIO = "docking"
DEFAULT_VEHICLE = "man_tgx"
DEFAULT_SIM_DURATION_S = 30.0
DEFAULT_SIM_SEED = 1


log = logging.getLogger("i2v_loc.sources")


class SourceError(ValueError):
    """A source specification or recording cannot be used (the message says why)."""


class ReplaySource:
    """Frames of a recording, once or in an endless loop."""

    def __init__(self, path: str | Path, loop: bool = False, label: str | None = None):
        try:
            self.recording = open_recording(path)
        except RecordingError as err:
            raise SourceError(str(err)) from err
        if len(self.recording) == 0:
            raise SourceError(f"{path}: the recording has no frames")
        self.loop = loop
        self.label = label or f"replay:{path}"

    @property
    def rate_hz(self) -> float:
        return self.recording.rate_hz

    @property
    def sensor_names(self) -> list[str]:
        return list(self.recording.sensor_names)

    @property
    def sensors_file(self) -> Path | None:
        """Parameter file with the recording's true extrinsics, if it has one."""
        file = self.recording.sensors_file
        return file if file.is_file() else None

    @property
    def n_frames(self) -> int | None:
        """Frames this source delivers in total; None when it loops forever."""
        return None if self.loop else len(self.recording)

    @property
    def duration_s(self) -> float:
        return len(self.recording) / self.rate_hz

    def starts_lap(self, k: int) -> bool:
        """Frame ``k`` starts the recording over (a looping replay's 2nd, 3rd, ... pass)."""
        return self.loop and k > 0 and k % len(self.recording) == 0

    def frame(self, k: int) -> Frame:
        """Frame number ``k`` of the stream; IndexError past the end of a non-looping replay."""
        n = len(self.recording)
        if k < 0 or (not self.loop and k >= n):
            raise IndexError(f"frame {k} out of range: the source has {n} frames")
        lap, index = divmod(k, n)
        known = len(self.recording.damaged)
        frame = self.recording.frame(index, skip_damaged=True)  # the sensors that work keep working
        if len(self.recording.damaged) > known:
            for name, reason in list(self.recording.damaged.items())[known:]:
                log.warning("sensor %s is left out of the replay from frame %d on: %s", name, index, reason)
        if lap == 0:
            return frame
        shift_s = lap * self.duration_s
        scans = {name: replace(s, stamp_s=s.stamp_s + shift_s) for name, s in frame.scans.items()}
        return Frame(index=k, scans=scans)

    @property
    def damaged(self) -> dict[str, str]:
        """Sensors of the recording that cannot be replayed (in full), and why."""
        return dict(self.recording.damaged)

    def describe(self) -> dict:
        meta = self.recording.meta
        return {
            "source": self.label,
            "path": str(self.recording.path),
            "frames": len(self.recording),
            "rate_hz": self.rate_hz,
            "loop": self.loop,
            "scenario": meta.get("scenario"),
            "generator": meta.get("generator"),
        }


@dataclass(frozen=True)
class SimSpec:
    scenario: str = DEFAULT_SCENARIO
    vehicle: str = DEFAULT_VEHICLE
    seed: int = DEFAULT_SIM_SEED
    duration_s: float = DEFAULT_SIM_DURATION_S

    def cache_name(self) -> str:
        return f"{self.vehicle}_{self.scenario}_seed{self.seed}_{self.duration_s:g}s"


def default_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "i2v-loc" / "sim"


def check_sim_spec(spec: SimSpec) -> None:
    """SourceError (one line) for an unknown scenario or vehicle, before the simulator starts."""
    from i2v_loc.params import load_params
    from i2v_loc.sim.maneuvers import SCENARIOS

    if spec.scenario not in SCENARIOS:
        raise SourceError(f"unknown scenario {spec.scenario!r} in sim:{spec.scenario}; known: {', '.join(SCENARIOS)}")
    vehicles = list(load_params().vehicles)  # the simulator draws the vehicles of the default parameters
    if spec.vehicle not in vehicles:
        raise SourceError(f"unknown vehicle {spec.vehicle!r} for the simulated yard; known: {', '.join(vehicles)}")
    if not spec.duration_s > 0:
        raise SourceError(f"the simulated recording needs a duration > 0 s, got {spec.duration_s:g}")


def simulated_recording(spec: SimSpec, cache_dir: str | Path | None = None, quiet: bool = False) -> Path:
    """Path of a recording of ``spec``; generated with ``i2v-loc sim`` on first use, then cached."""
    cache = Path(cache_dir) if cache_dir else default_cache_dir()
    target = cache / spec.cache_name()
    if (target / "meta.yaml").is_file():
        return target
    cache.mkdir(parents=True, exist_ok=True)
    partial = cache / f".{spec.cache_name()}.partial-{os.getpid()}"
    shutil.rmtree(partial, ignore_errors=True)
    cmd = [
        *_i2v_loc_command(),
        "sim",
        "--vehicle",
        spec.vehicle,
        "--scenario",
        spec.scenario,
        "--seed",
        str(spec.seed),
        "--duration",
        f"{spec.duration_s:g}",
        "--out",
        str(partial),
    ]
    if not quiet:
        print(
            f"generating the simulated yard ({spec.vehicle}, {spec.scenario}, {spec.duration_s:g} s) "
            f"into {target} (once; cached)",
            file=sys.stderr,
            flush=True,
        )
    # Progress of the simulator goes straight to the terminal, on stderr like everything the
    # service prints (stdout stays empty).
    out = subprocess.DEVNULL if quiet else _stderr_fd()
    done = subprocess.run(cmd, stdout=out, stderr=subprocess.PIPE if quiet else None, text=True)
    if done.returncode != 0:
        shutil.rmtree(partial, ignore_errors=True)
        detail = f": {done.stderr.strip()}" if quiet and done.stderr else ""
        raise SourceError(f"the simulator failed (exit {done.returncode}) for {spec}{detail}")
    try:
        partial.rename(target)
    except OSError:  # another process won the race: use its recording
        shutil.rmtree(partial, ignore_errors=True)
    return target


def _stderr_fd() -> int | None:
    """This process's stderr for a child's stdout (None: inherit stdout, if stderr has no file)."""
    try:
        sys.stderr.flush()
        return sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):
        return None


def _i2v_loc_command() -> list[str]:
    """The ``i2v-loc`` console script of this interpreter's environment, else the module."""
    script = Path(sys.executable).with_name("i2v-loc")
    return [str(script)] if script.is_file() else [sys.executable, "-m", "i2v_loc.cli"]


_SPEC = re.compile(r"^(?P<kind>sim|replay)(?::(?P<arg>.*))?$")


def open_source(
    spec: str,
    loop: bool = False,
    vehicle: str = DEFAULT_VEHICLE,
    seed: int = DEFAULT_SIM_SEED,
    duration_s: float = DEFAULT_SIM_DURATION_S,
    cache_dir: str | Path | None = None,
) -> ReplaySource:
    """``sim``, ``sim:SCENARIO`` (always loops), ``replay:REC`` (any layout of docs/formats.md; loops
    with ``loop``) or ``ouster-udp:DIR[@PORT,...]`` (live Ouster packets)."""
    if spec.strip().startswith("ouster-udp:"):
        from i2v_loc.formats.live import open_udp_source

        return open_udp_source(spec.strip().removeprefix("ouster-udp:"))
    match = _SPEC.match(spec.strip())
    if not match:
        raise SourceError(f"unknown source {spec!r}: use sim, sim:SCENARIO, replay:REC or ouster-udp:DIR[@PORT,...]")
    kind, arg = match["kind"], match["arg"]
    if kind == "replay":
        if not arg:
            raise SourceError("replay needs a recording directory: replay:REC_DIR")
        return ReplaySource(arg, loop=loop)
    sim = SimSpec(scenario=arg or DEFAULT_SCENARIO, vehicle=vehicle, seed=seed, duration_s=duration_s)
    check_sim_spec(sim)
    path = simulated_recording(sim, cache_dir)
    return ReplaySource(path, loop=True, label=f"sim:{sim.scenario} ({sim.vehicle}, seed {sim.seed})")
