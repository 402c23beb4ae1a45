"""An on-disk cache of training samples, so that a window is drawn once per dataset and sample
settings rather than once per epoch and run.

A sample is kept in two folders, each named by the hash of its key (`cache_keys`: everything
that determines its arrays): `raster-<hash>` holds the raster, which depends on the dataset (its
index, shards and collection settings), the raster configuration and the code and libraries that
draw it; `maps-<hash>` holds every other array, which depends on those and on the grid
(resolution), the uncertainty sigmas, the goal variance and the goal source. Runs that differ in
those settings only (ablations) share the raster, 0.32 of a window's 0.39 MB at 200x200 px.
In each folder:

    meta.json      the key, the window count and each array's shape and dtype
    <name>.npy     [windows, *shape] per sample array (raster uint8), memory-mapped
    check.npy      uint64 [windows]: 0 while a window is missing, else FILLED plus the CRC-32 of
                   its arrays' bytes

A folder is made whole beside its final name and renamed into place; windows fill in as they are
first built (sparse files: only the windows used take space). A window is served only while its
stored bytes match its checksum, so one half-written by a killed run is built again; a folder
that does not open as its key says (truncated or missing file, another layout, unreadable
meta.json) is made anew. Concurrent runs and DataLoader workers may fill the same folders: they
write identical bytes.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
import zlib
from pathlib import Path

import numpy as np

CACHE_VERSION = 1
FILLED = np.uint64(1 << 32)
META = "meta.json"
CHECK = "check.npy"


def _sha256_of_files(paths) -> str:
    digest = hashlib.sha256()
    for path in paths:
        digest.update(Path(path).name.encode() + b"\0")
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
    return digest.hexdigest()


def _code_digest() -> str:
    """The hash of the code that draws a sample (the `rasterize` package, the dataset and this
    module): a change to it makes another key."""
    import rasterize

    here = Path(__file__).resolve()
    sources = sorted(Path(rasterize.__file__).resolve().parent.rglob("*.py"))
    return _sha256_of_files(sources + [here.with_name("dataset.py"), here])


RASTER = "raster"


def cache_keys(dataset) -> dict[str, dict]:
    """Everything that determines the samples of `dataset` (a `DemoDataset`), as plain JSON: the
    key of its raster and that of its other arrays (`maps`)."""
    import cv2

    from riskmap.data.collect import INDEX

    drawn = {
        "version": CACHE_VERSION,
        "dataset": {
            "config": dataset.manifest["config"],
            "index_sha256": _sha256_of_files([dataset.root / INDEX]),
            "shards_sha256": _sha256_of_files(dataset.shard_paths),
            "windows": len(dataset),
        },
        "raster": dataset.raster_config.to_dict(),
        "code_sha256": _code_digest(),
        "libraries": {"numpy": np.__version__, "opencv": cv2.__version__},
    }
    maps = drawn | {
        "grid": dataset.grid.to_dict(),
        "sigma_x": float(dataset.sigma_x),
        "sigma_y": float(dataset.sigma_y),
        "goal_variance": float(dataset.goal_variance),
        "goal": dataset.goal_source,
        # the space-time planner's per-step maps (absent from spatial samples' keys, as before)
        **({"spacetime": dataset.spacetime.to_dict()} if getattr(dataset, "spacetime", None) else {}),
    }
    return {RASTER: drawn, "maps": maps}


def key_hash(key: dict) -> str:
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]


def _layout(arrays: dict[str, np.ndarray]) -> dict[str, list]:
    return {name: [list(a.shape), a.dtype.str] for name, a in arrays.items()}


def _map_npy(path: Path, shape: tuple, dtype: np.dtype) -> np.memmap:
    """`path` (.npy) memory-mapped for reading and writing; ValueError unless it holds exactly
    `shape` `dtype` (numpy itself would lengthen a short file with zeros)."""
    readers = {(1, 0): np.lib.format.read_array_header_1_0,
               (2, 0): np.lib.format.read_array_header_2_0}
    with open(path, "rb") as f:
        version = np.lib.format.read_magic(f)
        if version not in readers:
            raise ValueError(f"{path.name}: .npy format {version}")
        header = readers[version](f)
        offset = f.tell()
    size = int(np.prod(shape)) * dtype.itemsize
    if header != (tuple(shape), False, dtype) or path.stat().st_size != offset + size:
        raise ValueError(f"{path.name} does not hold {shape} {dtype}")
    return np.memmap(path, dtype=dtype, mode="r+", shape=tuple(shape), offset=offset)


class CacheFolder:
    """One cache folder (some of the arrays of every window), memory-mapped.

    `get(i)` gives window i's arrays (copies) or None when missing or damaged; `put(i, arrays)`
    stores them.
    """

    def __init__(self, directory: Path, windows: int, layout: dict[str, list]):
        self.directory, self.windows, self.layout = Path(directory), windows, layout
        self._map()

    def _map(self) -> None:
        self._check = _map_npy(self.directory / CHECK, (self.windows,), np.dtype(np.uint64))
        self._arrays = {name: _map_npy(self.directory / f"{name}.npy", (self.windows, *shape),
                                       np.dtype(dtype))
                        for name, (shape, dtype) in self.layout.items()}

    # Worker processes started by spawn get the folder, not a copy of the mapped arrays.
    def __getstate__(self) -> dict:
        return {"directory": self.directory, "windows": self.windows, "layout": self.layout}

    def __setstate__(self, state: dict) -> None:
        self.__init__(state["directory"], state["windows"], state["layout"])

    def _checksum(self, arrays: dict[str, np.ndarray]) -> np.uint64:
        crc = 0
        for name in self.layout:
            crc = zlib.crc32(np.ascontiguousarray(arrays[name]).data, crc)
        return np.uint64(crc) | FILLED

    def get(self, index: int) -> dict[str, np.ndarray] | None:
        check = self._check[index]
        if check == 0:
            return None
        arrays = {name: np.array(array[index]) for name, array in self._arrays.items()}
        return arrays if self._checksum(arrays) == check else None

    def put(self, index: int, arrays: dict[str, np.ndarray]) -> None:
        """Store window `index`; OSError (the disk full) before anything is written."""
        if arrays.keys() != self.layout.keys() or _layout(arrays) != self.layout:
            raise ValueError(f"sample arrays {_layout(arrays)} do not fit cache {self.layout}")
        # Disk blocks first: writing a memory map where the disk has none left kills the process
        # (SIGBUS) instead of raising.
        for name, array in self._arrays.items():
            size = array[index].nbytes
            with open(self.directory / f"{name}.npy", "r+b") as f:
                os.posix_fallocate(f.fileno(), array.offset + index * size, size)
        self._check[index] = 0                  # not served while being written
        for name, array in self._arrays.items():
            array[index] = arrays[name]
        self._check[index] = self._checksum(arrays)

    def filled(self) -> int:
        """How many windows the folder holds (checksums unverified)."""
        return int(np.count_nonzero(self._check))


class SampleCache:
    """A dataset's cached samples: its raster folder and its maps folder (open it with
    `open_sample_cache`). `get(i)` gives window i's arrays, or None unless both folders hold
    them intact; `put(i, arrays)` stores them. `hits` / `misses` count this process's look-ups.
    """

    def __init__(self, folders: dict[str, CacheFolder]):
        self.folders = folders
        self.hits = self.misses = 0

    def get(self, index: int) -> dict[str, np.ndarray] | None:
        arrays = {}
        for folder in self.folders.values():
            part = folder.get(index)
            if part is None:
                self.misses += 1
                return None
            arrays |= part
        self.hits += 1
        return arrays

    def put(self, index: int, arrays: dict[str, np.ndarray]) -> None:
        if arrays.keys() != {name for folder in self.folders.values() for name in folder.layout}:
            raise ValueError(f"sample arrays {sorted(arrays)} do not fit the cache")
        for folder in self.folders.values():
            folder.put(index, {name: arrays[name] for name in folder.layout})

    def filled(self) -> int:
        """How many windows the cache holds whole (checksums unverified)."""
        return min(folder.filled() for folder in self.folders.values())


def _create(directory: Path, meta: dict) -> None:
    """Make the folder `directory` whole under a temporary name and rename it into place (if
    another process made it meanwhile, theirs is kept)."""
    directory.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{directory.name}.", suffix=".tmp", dir=directory.parent))
    try:
        windows = meta["windows"]
        np.lib.format.open_memmap(tmp / CHECK, mode="w+", dtype=np.uint64, shape=(windows,)).flush()
        with open(tmp / CHECK, "r+b") as f:     # its blocks now (see CacheFolder.put)
            os.posix_fallocate(f.fileno(), 0, os.fstat(f.fileno()).st_size)
        for name, (shape, dtype) in meta["layout"].items():
            np.lib.format.open_memmap(tmp / f"{name}.npy", mode="w+", dtype=np.dtype(dtype),
                                      shape=(windows, *shape)).flush()
        (tmp / META).write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")
        try:
            os.rename(tmp, directory)
        except OSError:
            if not directory.is_dir():
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _open(directory: Path, meta: dict) -> CacheFolder:
    if json.loads((directory / META).read_text()) != meta:
        raise ValueError(f"{directory / META} describes another cache")
    return CacheFolder(directory, meta["windows"], meta["layout"])


def open_folder(directory: Path, meta: dict) -> CacheFolder:
    """The cache folder `directory` described by `meta` (made if missing; made anew if it does
    not open as `meta` says)."""
    meta = json.loads(json.dumps(meta))     # as it reads back
    if directory.exists():
        try:
            return _open(directory, meta)
        except (OSError, ValueError, KeyError, TypeError, SyntaxError, EOFError):
            # Damaged (truncated, half-deleted, rewritten by hand): not trusted, made anew.
            doomed = directory.with_name(f".{directory.name}.{os.getpid()}.damaged")
            try:
                os.replace(directory, doomed)
            except OSError:
                if directory.exists():    # not another process's removal meanwhile
                    raise
            shutil.rmtree(doomed, ignore_errors=True)
    _create(directory, meta)
    return _open(directory, meta)


def open_sample_cache(dataset, root: str | Path) -> SampleCache:
    """The cache of `dataset`'s samples under folder `root` (see the module docstring). Builds
    one sample to learn the arrays' shapes."""
    keys = cache_keys(dataset)
    layout = _layout(dataset.sample_arrays(dataset.scene(0)))
    parts = {RASTER: {RASTER: layout[RASTER]},
             "maps": {name: spec for name, spec in layout.items() if name != RASTER}}
    return SampleCache({
        name: open_folder(Path(root) / f"{name}-{key_hash(keys[name])}",
                          {"key": keys[name], "windows": len(dataset), "layout": parts[name]})
        for name in (RASTER, "maps")})
