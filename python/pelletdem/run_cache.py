"""The run cache: one small JSON record per run, named by the run's key
(:attr:`pelletdem.runs.RunSpec.key`).

A record holds the run's scalars and its sigma_1(dL/D) curve; a scan or fit pointed at the
same directory resumes where it stopped and never runs a point twice. A failed run
(overlap, escape, NaN) is cached too: it is deterministic. The cache is written by the
driver (:class:`pelletdem.execution.Evaluator`), not by the workers, so remote workers need
no shared file system.
"""
from __future__ import annotations

import contextlib
import json
import os
import tempfile
import threading
import warnings
from typing import Dict, List, Optional, Union

from .h5io import jsonable

__all__ = ["RunCache"]


class RunCache:
    """Run records on disk, one JSON file per run key: ``<directory>/<key[:2]>/<key>.json``.

    A record holds the run's inputs (``spec``), its scalar outputs (SI), its sigma_1(dL/D) and
    compaction curves (a few hundred points), whether it succeeded, and its wall time (s).
    Writes are atomic (temporary file, then rename), so a killed scan leaves whole files; an
    unreadable file is treated as missing (and rewritten). ``directory=None``: memory only.
    """

    def __init__(self, directory: Optional[Union[str, os.PathLike]] = None):
        self.directory = None if directory is None else os.fspath(directory)
        self._memory: Dict[str, dict] = {}
        self._lock = threading.Lock()
        if self.directory is not None:
            os.makedirs(self.directory, exist_ok=True)

    def path(self, key: str) -> Optional[str]:
        """File of `key` (None for a memory-only cache)."""
        if self.directory is None:
            return None
        return os.path.join(self.directory, key[:2], key + ".json")

    def get(self, key: str) -> Optional[dict]:
        """The record of `key`, or None."""
        with self._lock:
            if key in self._memory:
                return self._memory[key]
        path = self.path(key)
        if path is None or not os.path.exists(path):
            return None
        try:
            with open(path) as fh:
                rec = json.load(fh)
            if rec.get("key") != key:
                raise ValueError("key mismatch")
        except (OSError, ValueError) as e:
            warnings.warn(f"{path}: unreadable cache record ({e}); it will be recomputed", stacklevel=2)
            return None
        with self._lock:
            self._memory[key] = rec
        return rec

    def put(self, record: dict) -> None:
        """Store a record (it must have a 'key')."""
        key = record["key"]
        with self._lock:
            self._memory[key] = record
        path = self.path(key)
        if path is None:
            return
        os.makedirs(os.path.dirname(path), exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".json", dir=os.path.dirname(path))
        try:
            with os.fdopen(fd, "w") as fh:
                json.dump(record, fh, default=jsonable)
            os.replace(tmp, path)
        except BaseException:
            with contextlib.suppress(OSError):
                os.remove(tmp)
            raise

    def __contains__(self, key: str) -> bool:
        return self.get(key) is not None

    def keys(self) -> List[str]:
        """All keys on disk (and in memory)."""
        keys = set(self._memory)
        if self.directory is not None:
            for sub in os.listdir(self.directory):
                d = os.path.join(self.directory, sub)
                if os.path.isdir(d):
                    keys.update(f[:-5] for f in os.listdir(d) if f.endswith(".json") and not f.startswith("."))
        return sorted(keys)

    def __len__(self) -> int:
        return len(self.keys())
