"""tracer: a small, exact and fast direct-lighting path tracer for comparing sampling strategies."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("tracer")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0.0.0+source"
