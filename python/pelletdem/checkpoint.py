"""Checkpoints: a World's whole state in HDF5, written atomically (temporary name, then
rename), so a kill at any moment leaves the previous checkpoint whole. A world loaded from a
checkpoint continues bit for bit like the one that was saved (at the same thread count).

`RunCheckpoint` checkpoints a whole pellet run (pipeline.run_pellet, `pelletdem run`): at the
end of every stage and, inside a stage, every `interval` seconds of wall time. A run started
again on the same file resumes from its last checkpoint and ends with the same bits as a run
that was never stopped:

- at a stage end the file holds the world, the Pellet's fields (wall indices, heights, mass,
  snapshots) and the Result so far;
- inside a stage it holds the same as of the stage's start plus, for the stage under way, the
  world after each of its engine runs that has finished and the world inside the current run
  (saved between two chunks, where no stop condition has fired). On resume the stage function
  runs again from its start on the stage-start world, so every value it computed before or
  between its runs is computed again from the same bits, and its runs are replayed from the
  file: a finished run restores the world after it, the interrupted one restores the world
  inside it and runs its remaining steps with the same stop conditions.

Stop conditions are tested on the world's step count, not on the run's, so a run split at a
checkpoint tests the same steps as one that was not split.
"""
from __future__ import annotations

import json
import math
import os
import time
from contextlib import contextmanager
from typing import Optional

import numpy as np

from .engine import ParameterError, RunOutcome, World
from .h5io import atomic_h5, jsonable, open_h5

FORMAT = "pelletdem-checkpoint-1"
RUN_FORMAT = "pelletdem-run-checkpoint-1"


class CheckpointError(ValueError):
    """A checkpoint file that is missing, truncated, not written by pelletdem, or written by
    another run (other arguments) than the one that tries to resume from it."""


# --- one world -----------------------------------------------------------------------------

def save_world(world: World, path: str, extra: dict | None = None) -> str:
    """Write `world`'s state (and optional JSON-able `extra` metadata) to `path`; returns it."""
    state = world.get_state()
    with atomic_h5(path, FORMAT) as f:
        f.attrs["extra"] = json.dumps(extra or {})
        write_state(f, state)
    return path


def write_state(group, state: dict) -> None:
    """A state dict from World.get_state() into an open HDF5 group (arrays as datasets, plain
    values as attributes, the construction parameters as JSON)."""
    state = dict(state)
    group.attrs["params"] = json.dumps(state.pop("params"), default=jsonable)
    walls = state.pop("walls")
    samples = state.pop("samples", None)
    wall_samples = state.pop("wall_samples", None)
    _write_flat(group, state)
    for n, wd in enumerate(walls):
        _write_flat(group.create_group(f"walls/{n:03d}"), wd)
    if samples is not None:
        _write_flat(group.create_group("samples"), samples)
        for n, wd in enumerate(wall_samples or []):
            _write_flat(group.create_group(f"wall_samples/{n:03d}"), wd)


def _write_flat(group, values: dict) -> None:
    # Arrays become datasets, plain values attributes.
    for k, v in values.items():
        if isinstance(v, np.ndarray):
            group.create_dataset(k, data=v)
        else:
            group.attrs[k] = v


def _read_flat(group, skip=()) -> dict:
    out = {k: group[k][()] for k in group if k not in skip}
    for k, v in group.attrs.items():
        if k not in skip:
            out[k] = v.item() if hasattr(v, "item") else v
    return out


def read_state_group(group) -> dict:
    """The state dict (for World.from_state) kept in an open HDF5 group by write_state."""
    state = _read_flat(group, skip=("walls", "samples", "wall_samples", "format", "params", "extra"))
    state["params"] = json.loads(group.attrs["params"])
    state["params"]["box"] = tuple(tuple(b) for b in state["params"]["box"])
    state["params"]["gravity"] = tuple(state["params"]["gravity"])
    walls = group.get("walls", {})
    state["walls"] = [_read_flat(walls[name]) for name in sorted(walls)]
    if "samples" in group:
        state["samples"] = _read_flat(group["samples"])
        ws = group.get("wall_samples", {})
        state["wall_samples"] = [_read_flat(ws[name]) for name in sorted(ws)]
    return state


# HDF5 notices a cut-off end when the file is opened, damage inside only when it is read:
# these are what reading a damaged file raises.
_DAMAGE = (OSError, KeyError, ValueError, TypeError, AttributeError, json.JSONDecodeError)


def read_state(path: str) -> tuple[dict, dict]:
    """(state dict for World.from_state, extra metadata) from a checkpoint file. A missing,
    truncated, damaged or foreign file raises CheckpointError naming the file."""
    with open_h5(path, FORMAT, CheckpointError, "pelletdem checkpoint") as f:
        try:
            return read_state_group(f), json.loads(f.attrs["extra"])
        except _DAMAGE as e:
            raise CheckpointError(f"{os.fspath(path)}: damaged pelletdem checkpoint "
                                  f"({type(e).__name__}: {e})") from None


def load_world(path: str, threads: int | None = None) -> World:
    """The World saved in checkpoint `path`; `threads` overrides the saved thread count."""
    state, _ = read_state(path)
    try:
        return World.from_state(state, threads=threads)
    except ParameterError as e:
        raise CheckpointError(f"{os.fspath(path)}: the saved state does not load: {e}") from None


# --- a whole run -----------------------------------------------------------------------------

_PELLET_FIELDS = ("mould_radius", "mass", "h0", "diameter", "height")


class Resumed:
    """What a run checkpoint holds: the Result so far (`result`), the names of the finished
    stages (`stages_done`), the Pellet's fields (`pellet`: walls dict, lengths in m, mass in
    kg, snapshots), the world at the end of the last finished stage (`world_state`, None
    before the fill has finished), the time already spent (`wall_time_s`, s), and the stage
    under way when it was saved (`progress`, None at a stage end)."""

    def __init__(self, result, stages_done, pellet, world_state, wall_time_s, progress):
        self.result = result
        self.stages_done = stages_done
        self.pellet = pellet
        self.world_state = world_state
        self.wall_time_s = wall_time_s
        self.progress = progress

    def make_pellet(self, preset):
        """The Pellet at the end of the last finished stage (None before the fill)."""
        from .stages import Pellet

        if self.world_state is None:
            return None
        world = World.from_state(self.world_state)
        p = self.pellet
        return Pellet(world, preset, dict(p["walls"]), p["mould_radius"], p["mass"], h0=p["h0"],
                      diameter=p["diameter"], height=p["height"], snapshots=dict(p["snapshots"]))


class RunCheckpoint:
    """The checkpoint file of one pellet run.

    `path`: the HDF5 file (written atomically). `run_args`: JSON-able values that define the
    run (preset, variant, seed, thread count, ...); a file written with other values is refused
    on resume, naming what differs. `interval`: seconds of wall time between checkpoints inside
    a stage (>= 0; 0 saves after every chunk of the engine, about ten times a second; inf saves
    at stage ends only). Saving never changes the run's results: it reads the world between two
    chunks and the chunking itself does not change the bits.
    """

    def __init__(self, path, run_args: dict, interval: float = 300.0):
        try:
            interval = float(interval)
        except (TypeError, ValueError):
            raise ParameterError(f"checkpoint interval = {interval!r} must be a number of seconds >= 0") from None
        if math.isnan(interval) or interval < 0:
            raise ParameterError(f"checkpoint interval = {interval} s is out of range: allowed >= 0 s")
        self.path = os.fspath(path)
        self.run_args = json.loads(json.dumps(run_args, default=jsonable))
        self.interval = interval
        self.n_saved = 0            # checkpoints written by this process
        self._last_save = time.monotonic()
        self._t0 = time.monotonic()
        self._prior_wall_time = 0.0
        self._base = None           # the stage under way: its start, for mid-stage saves
        self._replay = None         # progress read from the file, for the stage it names

    # -- reading ---------------------------------------------------------------------------
    def resume(self) -> Optional[Resumed]:
        """What the file holds, or None when there is no file (a fresh run). Raises
        CheckpointError for a damaged or foreign file or one of another run."""
        if not os.path.exists(self.path):
            return None
        from .result import Result, read_snapshots

        with open_h5(self.path, RUN_FORMAT, CheckpointError, "pelletdem run checkpoint") as f:
            try:
                saved_args = json.loads(f.attrs["run_args"])
                self._check_args(saved_args)
                result = Result.read_group(f["result"])
                stages_done = json.loads(f.attrs["stages_done"])
                pg = f["pellet"]
                pellet = {k: float(pg.attrs[k]) for k in _PELLET_FIELDS}
                pellet["walls"] = {k: int(v) for k, v in json.loads(pg.attrs["walls"]).items()}
                pellet["snapshots"] = read_snapshots(pg)
                world_state = read_state_group(f["world"]) if "world" in f else None
                wall_time = float(f.attrs["wall_time_s"])
                progress = self._read_progress(f["progress"]) if "progress" in f else None
            except CheckpointError:
                raise
            except _DAMAGE as e:
                raise CheckpointError(f"{self.path}: damaged pelletdem run checkpoint "
                                      f"({type(e).__name__}: {e}); start again with --restart") from None
        if list(result.stages) != stages_done:
            raise CheckpointError(f"{self.path}: damaged pelletdem run checkpoint (stages "
                                  f"{list(result.stages)} vs {stages_done})")
        self._prior_wall_time = wall_time
        self._replay = progress
        return Resumed(result, stages_done, pellet, world_state, wall_time, progress)

    def _check_args(self, saved: dict) -> None:
        if saved == self.run_args:
            return
        keys = sorted(set(saved) | set(self.run_args))
        diff = ", ".join(f"{k}: {saved.get(k, '(none)')!r} in the checkpoint, {self.run_args.get(k, '(none)')!r} now"
                         for k in keys if saved.get(k) != self.run_args.get(k))
        raise CheckpointError(f"{self.path} is the checkpoint of another run ({diff}); "
                              "give the same arguments to resume it, --restart to discard it, "
                              "or another --out directory")

    @staticmethod
    def _read_progress(g) -> dict:
        runs = []
        for name in sorted(g.get("runs", {})):
            r = g["runs"][name]
            runs.append({"name": str(r.attrs["name"]), "max_steps": int(r.attrs["max_steps"]),
                         "reason": str(r.attrs["reason"]), "steps": int(r.attrs["steps"]),
                         "time": float(r.attrs["time"]), "state": read_state_group(r["state"])})
        m = g["mid"]
        mid = {"name": str(m.attrs["name"]), "max_steps": int(m.attrs["max_steps"]),
               "done": int(m.attrs["done"]), "state": read_state_group(m["state"])}
        return {"stage": str(g.attrs["stage"]), "elapsed_s": float(g.attrs["elapsed_s"]),
                "runs": runs, "mid": mid}

    # -- writing ---------------------------------------------------------------------------
    @contextmanager
    def stage(self, name: str, pellet, result):
        """Run the stage `name` inside this block: its engine runs are checkpointed every
        `interval` s and, when the file held this stage under way, replayed up to where it
        stopped. `pellet` (None for the fill) and `result` are the run's state at the stage's
        start. Yields the stage's journal; its `prior_elapsed_s` is the wall time (s) the stage
        had already taken before a resume."""
        from . import stages

        replay = self._replay if self._replay is not None and self._replay["stage"] == name else None
        self._replay = None
        self._base = {"stage": name, "result": result, "pellet": _pellet_fields(pellet),
                      "world": pellet.world.get_state() if pellet is not None else None,
                      "t0": time.monotonic()}
        journal = _StageJournal(self, name, replay)
        token = stages.STAGE_RUNNER.set(journal)
        try:
            yield journal
        finally:
            stages.STAGE_RUNNER.reset(token)
            self._base = None

    def stage_done(self, pellet, result) -> None:
        """Save the run at the end of a stage: the world, the Pellet's fields and `result`
        (whose stages are the finished ones)."""
        self._write(result, _pellet_fields(pellet), pellet.world.get_state(), None)

    def _save_mid(self, journal: "_StageJournal", mid: dict) -> None:
        b = self._base
        progress = {"stage": b["stage"], "runs": journal.runs, "mid": mid,
                    "elapsed_s": journal.prior_elapsed_s + time.monotonic() - b["t0"]}
        self._write(b["result"], b["pellet"], b["world"], progress)

    def _due(self) -> bool:
        return time.monotonic() - self._last_save >= self.interval

    def _write(self, result, pellet: dict, world_state, progress) -> None:
        from .result import write_snapshots

        with atomic_h5(self.path, RUN_FORMAT) as f:
            f.attrs["run_args"] = json.dumps(self.run_args)
            f.attrs["stages_done"] = json.dumps(list(result.stages))
            f.attrs["wall_time_s"] = self._prior_wall_time + time.monotonic() - self._t0
            result.write_group(f.create_group("result"))
            pg = f.create_group("pellet")
            for k in _PELLET_FIELDS:
                pg.attrs[k] = pellet[k]
            pg.attrs["walls"] = json.dumps(pellet["walls"])
            write_snapshots(pg, pellet["snapshots"])
            if world_state is not None:
                write_state(f.create_group("world"), world_state)
            if progress is not None:
                g = f.create_group("progress")
                g.attrs["stage"] = progress["stage"]
                g.attrs["elapsed_s"] = progress["elapsed_s"]
                for k, r in enumerate(progress["runs"]):
                    rg = g.create_group(f"runs/{k:03d}")
                    for key in ("name", "max_steps", "reason", "steps", "time"):
                        rg.attrs[key] = r[key]
                    write_state(rg.create_group("state"), r["state"])
                m = progress["mid"]
                mg = g.create_group("mid")
                for key in ("name", "max_steps", "done"):
                    mg.attrs[key] = m[key]
                write_state(mg.create_group("state"), m["state"])
        self.n_saved += 1
        self._last_save = time.monotonic()

    @property
    def wall_time_s(self) -> float:
        """Wall time of the run so far, s, over every session that worked on it."""
        return self._prior_wall_time + time.monotonic() - self._t0


def _pellet_fields(pellet) -> dict:
    if pellet is None:
        return {"walls": {}, "snapshots": {}, **{k: float("nan") for k in _PELLET_FIELDS}}
    out = {k: float(getattr(pellet, k)) for k in _PELLET_FIELDS}
    out["walls"] = {k: int(v) for k, v in pellet.walls.items()}
    out["snapshots"] = dict(pellet.snapshots)  # the stage adds keys; its arrays stay as they are
    return out


class _StageJournal:
    """The stage runner (stages.STAGE_RUNNER) of one stage under a RunCheckpoint: it runs the
    engine, saves between chunks when a checkpoint is due, remembers the world after each
    finished run, and replays the runs of a resumed stage."""

    def __init__(self, owner: RunCheckpoint, stage: str, replay: Optional[dict]):
        self.owner = owner
        self.stage = stage
        self.replay = replay
        self.runs = []  # finished runs of this stage: name, max_steps, reason, steps, time, state
        self.next_index = 0
        self.prior_elapsed_s = replay["elapsed_s"] if replay is not None else 0.0

    def _check(self, rec: dict, name: str, max_steps: int) -> None:
        if rec["name"] != name or rec["max_steps"] != max_steps:
            raise CheckpointError(
                f"{self.owner.path}: the checkpoint's stage '{self.stage}' ran '{rec['name']}' for "
                f"{rec['max_steps']} steps where this code runs '{name}' for {max_steps}: it was "
                "written by other code; start again with --restart")

    def __call__(self, pellet, name: str, max_steps: int, progress, conditions: dict) -> RunOutcome:
        from .stages import run_engine

        k = self.next_index
        self.next_index += 1
        world = pellet.world
        done0 = 0
        if self.replay is not None:
            if k < len(self.replay["runs"]):
                rec = self.replay["runs"][k]
                self._check(rec, name, max_steps)
                world.restore_state(rec["state"])
                self.runs.append(rec)
                return RunOutcome(rec["reason"], rec["steps"], rec["time"])
            mid = self.replay["mid"]
            self._check(mid, name, max_steps)
            world.restore_state(mid["state"])
            done0 = mid["done"]
            self.replay = None

        def between(done: int) -> None:
            if self.owner._due():
                self.owner._save_mid(self, {"name": name, "max_steps": max_steps, "done": done0 + done,
                                            "state": world.get_state()})

        out = run_engine(pellet, name, max_steps - done0, progress, conditions, between=between)
        out = RunOutcome(out.reason, out.steps + done0, out.time)
        self.runs.append({"name": name, "max_steps": max_steps, "reason": out.reason,
                          "steps": out.steps, "time": out.time, "state": world.get_state()})
        return out
