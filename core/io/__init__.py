"""Reading and writing point clouds and atomic output (formats: core.io.formats, docs/formats.md)."""
from .atomic import atomic_dir, atomic_path
from .formats import READ_SUFFIXES, WRITE_SUFFIXES, ReaderOptions, read_cloud, write_cloud, write_csv

__all__ = ["read_cloud", "write_cloud", "write_csv", "atomic_path", "atomic_dir", "READ_SUFFIXES",
           "WRITE_SUFFIXES", "ReaderOptions"]
