"""Checkpoints: a World's whole state in HDF5, written atomically (temporary name, then
rename), so a kill at any moment leaves the previous checkpoint whole. A world loaded from a
checkpoint continues bit for bit like the one that was saved (at the same thread count)."""
from __future__ import annotations

import json
import os

import numpy as np

from .engine import World
from .h5io import atomic_h5, open_h5

FORMAT = "pelletdem-checkpoint-1"


class CheckpointError(ValueError):
    """A checkpoint file that is missing, truncated, or not written by pelletdem."""


def save_world(world: World, path: str, extra: dict | None = None) -> str:
    """Write `world`'s state (and optional JSON-able `extra` metadata) to `path`; returns it."""
    state = world.get_state()
    with atomic_h5(path, FORMAT) as f:
        f.attrs["params"] = json.dumps(state.pop("params"))
        f.attrs["extra"] = json.dumps(extra or {})
        walls = state.pop("walls")
        _write_flat(f, state)
        for n, wd in enumerate(walls):
            _write_flat(f.create_group(f"walls/{n:03d}"), wd)
    return path


def _write_flat(group, values: dict) -> None:
    # Arrays become datasets, plain values attributes.
    for k, v in values.items():
        if isinstance(v, np.ndarray):
            group.create_dataset(k, data=v)
        else:
            group.attrs[k] = v


def read_state(path: str) -> tuple[dict, dict]:
    """(state dict for World.from_state, extra metadata) from a checkpoint file."""
    with open_h5(path, FORMAT, CheckpointError, "pelletdem checkpoint") as f:
        state = {k: f[k][()] for k in f if k != "walls"}
        for k, v in f.attrs.items():
            if k not in ("format", "params", "extra"):
                state[k] = v.item() if hasattr(v, "item") else v
        state["params"] = json.loads(f.attrs["params"])
        state["params"]["box"] = tuple(tuple(b) for b in state["params"]["box"])
        walls = []
        for name in sorted(f.get("walls", {})):
            g = f["walls"][name]
            wd = {k: g[k][()] for k in g}
            for k, v in g.attrs.items():
                wd[k] = v.item() if hasattr(v, "item") else v
            walls.append(wd)
        state["walls"] = walls
        return state, json.loads(f.attrs["extra"])


def load_world(path: str, threads: int | None = None) -> World:
    """The World saved in checkpoint `path`; `threads` overrides the saved thread count."""
    state, _ = read_state(path)
    return World.from_state(state, threads=threads)
