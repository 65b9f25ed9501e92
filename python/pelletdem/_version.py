"""The installed package version (a source tree without metadata says so)."""
from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("pelletdem")
except PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0+source"
