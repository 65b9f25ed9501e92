"""HDF5 files that survive a kill: written under a temporary name and renamed into place, so a
reader sees either the previous file or the new one, never half of one; and opened with a
check that the file is whole and of the expected kind."""
from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager


@contextmanager
def atomic_h5(path: str, fmt: str):
    """Yield an h5py.File open for writing on a temporary name beside `path`, with its
    `format` attribute set to `fmt`; on success it is synced and renamed onto `path`."""
    import h5py

    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".h5", dir=directory)
    os.close(fd)
    try:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = fmt
            yield f
            f.flush()
            os.fsync(f.id.get_vfd_handle())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def open_h5(path: str, fmt: str, error: type, what: str):
    """Open `path` for reading; raise `error` naming the file when it is missing, not HDF5
    (truncated or foreign), or not of format `fmt` (`what` names the expected kind)."""
    import h5py

    path = os.fspath(path)
    if not os.path.exists(path):
        raise error(f"{path}: no such file")
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise error(f"{path}: not a readable HDF5 file (truncated or foreign): {e}") from None
    found = f.attrs.get("format")
    if found != fmt:
        f.close()
        raise error(f"{path}: not a {what} (format attribute {found!r}, expected {fmt!r})")
    return f


def jsonable(v):
    """``json.dumps(default=...)`` hook: numpy scalars and arrays as plain Python values."""
    import numpy as np

    if isinstance(v, (np.floating, np.integer, np.bool_)):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    raise TypeError(f"not JSON-able: {type(v).__name__}")
