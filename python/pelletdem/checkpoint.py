"""Checkpoints: a World's whole state in HDF5, written atomically (temporary name, then
rename), so a kill at any moment leaves the previous checkpoint whole. A world loaded from a
checkpoint continues bit for bit like the one that was saved (at the same thread count)."""
from __future__ import annotations

import json
import os
import tempfile

import numpy as np

from .engine import World

FORMAT = "pelletdem-checkpoint-1"


class CheckpointError(ValueError):
    """A checkpoint file that is missing, truncated, or not written by pelletdem."""


def save_world(world: World, path: str, extra: dict | None = None) -> str:
    """Write `world`'s state (and optional JSON-able `extra` metadata) to `path`; returns it."""
    import h5py

    state = world.get_state()
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".h5", dir=directory)
    os.close(fd)
    try:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = FORMAT
            f.attrs["params"] = json.dumps(state.pop("params"))
            f.attrs["extra"] = json.dumps(extra or {})
            walls = state.pop("walls")
            for k, v in state.items():
                if isinstance(v, np.ndarray):
                    f.create_dataset(k, data=v)
                else:
                    f.attrs[k] = v
            for n, wd in enumerate(walls):
                g = f.create_group(f"walls/{n:03d}")
                for k, v in wd.items():
                    if isinstance(v, np.ndarray):
                        g.create_dataset(k, data=v)
                    else:
                        g.attrs[k] = v
            f.flush()
            os.fsync(f.id.get_vfd_handle())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise
    return path


def read_state(path: str) -> tuple[dict, dict]:
    """(state dict for World.from_state, extra metadata) from a checkpoint file."""
    import h5py

    path = os.fspath(path)
    if not os.path.exists(path):
        raise CheckpointError(f"{path}: no such checkpoint")
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise CheckpointError(f"{path}: not a readable HDF5 file (truncated or foreign): {e}") from None
    with f:
        if f.attrs.get("format") != FORMAT:
            raise CheckpointError(f"{path}: not a pelletdem checkpoint (format {f.attrs.get('format')!r})")
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
