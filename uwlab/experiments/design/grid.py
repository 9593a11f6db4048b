"""Design grids: the Cartesian product of values of some config keys, evaluated in chunks of bounded size.

A grid is a base design (a raw config dict) and ordered axes {"section.key": [values]}. Numeric axes form an open
mesh (one numpy axis per key) evaluated by broadcasting; categorical axes (names, files, words) are looped over.
Rows come in C order: categorical combinations outermost, then the numeric axes in the order given. Columns: the
axes (numeric as float64, categorical as strings), then the flattened outputs of `uwlab.model.design.evaluate`
(``fov_deg_x``, ``dof_m_near``, ...; an output a design does not have, such as the dome's virtual image behind a
flat port, is NaN).

A chunk is a block of consecutive rows that is itself an open mesh: one categorical combination, single values
of the leading numeric axes, a slice of one axis and the whole of the later ones, at most `CHUNK_POINTS` points.
Chunk `i` is computed from `i` alone, so any executor (this process, a Dask cluster: `distributed.py`) produces
the same rows in the same files, bit for bit. Parquet output is a directory of part files, one per chunk
(``part-000000.parquet`` ...; `pandas.read_parquet(directory)` reads them in order), written into a staging
directory beside the target and renamed when complete, so an interrupted run leaves no partial result.
"""

from __future__ import annotations

import itertools
import math
import os
import shutil
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from uwlab.errors import ConfigError, UwlabError
from uwlab.model.config import apply_override
from uwlab.model.design import build_design, evaluate
from uwlab.outputs import output_file

CHUNK_POINTS = 1 << 17
OUTPUT_SUFFIXES = (".parquet", ".csv")


def flatten_outputs(result: dict, prefix: str = "") -> dict[str, object]:
    """{"fov_deg": {"x": ..}} → {"fov_deg_x": ..}; None outputs are dropped."""
    flat = {}
    for key, value in result.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(flatten_outputs(value, f"{name}_"))
        elif value is not None:
            flat[name] = value
    return flat


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


@dataclass(frozen=True)
class DesignGrid:
    """A base design and its grid axes; `chunk(i)` evaluates the i-th block of rows."""

    raw: dict
    axes: dict
    base_dir: Path | None = None
    outputs: tuple[str, ...] | None = None  # output columns to keep (all when None)
    chunk_points: int = CHUNK_POINTS

    def __post_init__(self) -> None:
        for key, values in self.axes.items():
            if not values:
                raise ConfigError(key, values, "grid has no values")
        if self.chunk_points < 1:
            raise ConfigError("chunk_points", self.chunk_points, "must be >= 1")

    @cached_property
    def numeric(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v, float) for k, v in self.axes.items() if all(_is_number(x) for x in v)}

    @cached_property
    def categorical(self) -> dict[str, list]:
        return {k: list(v) for k, v in self.axes.items() if k not in self.numeric}

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(v.size for v in self.numeric.values())

    @cached_property
    def combinations(self) -> list[tuple]:
        return list(itertools.product(*self.categorical.values()))

    @property
    def points(self) -> int:
        return len(self.combinations) * math.prod(self.shape)

    @cached_property
    def _split(self) -> tuple[int, int]:
        """(axis s sliced within a chunk, slice length): later axes whole, earlier ones one value at a time."""
        shape = self.shape
        for s in range(len(shape)):
            inner = math.prod(shape[s + 1 :])
            if inner <= self.chunk_points:
                return s, max(1, min(shape[s], self.chunk_points // inner))
        return len(shape), 1

    @property
    def chunks_per_combination(self) -> int:
        s, step = self._split
        if s == len(self.shape):
            return 1
        return math.prod(self.shape[:s]) * math.ceil(self.shape[s] / step)

    @property
    def chunks(self) -> int:
        return len(self.combinations) * self.chunks_per_combination

    def _config(self, combination: tuple, ranges: list[tuple[int, int]]) -> dict:
        config = {s: dict(b) if isinstance(b, dict) else b for s, b in self.raw.items()}
        for key, value in zip(self.categorical, combination, strict=True):
            apply_override(config, key, value)
        n = len(ranges)
        for axis, ((key, values), (lo, hi)) in enumerate(zip(self.numeric.items(), ranges, strict=True)):
            apply_override(config, key, values[lo:hi].reshape([-1 if i == axis else 1 for i in range(n)]))
        return config

    def _ranges(self, index: int) -> tuple[tuple, list[tuple[int, int]]]:
        combination, within = divmod(index, self.chunks_per_combination)
        shape = self.shape
        s, step = self._split
        if s == len(shape):
            return self.combinations[combination], [(0, n) for n in shape]
        lead = np.unravel_index(within, shape[:s] + (math.ceil(shape[s] / step),))
        ranges = [(int(i), int(i) + 1) for i in lead[:-1]]
        ranges.append((int(lead[-1]) * step, min(shape[s], (int(lead[-1]) + 1) * step)))
        ranges += [(0, n) for n in shape[s + 1 :]]
        return self.combinations[combination], ranges

    def check(self) -> list[str]:
        """Validate every value of every axis (for each categorical combination) and the chosen outputs before
        the grid is evaluated; returns the output columns."""
        for combination in self.combinations:
            build_design(self._config(combination, [(0, n) for n in self.shape]), self.base_dir)
        return list(self.output_types)

    def chunk(self, index: int) -> pd.DataFrame:
        """Rows of chunk `index` with every column of `schema`."""
        return pd.DataFrame(self.chunk_columns(index))

    def chunk_table(self, index: int) -> pa.Table:
        """Chunk `index` as an Arrow table with `schema`."""
        return pa.table(self.chunk_columns(index), schema=self.schema)

    def chunk_columns(self, index: int) -> dict[str, np.ndarray]:
        """Columns of chunk `index`: name → 1-D array."""
        if not 0 <= index < self.chunks:
            raise IndexError(index)
        combination, ranges = self._ranges(index)
        result = flatten_outputs(evaluate(build_design(self._config(combination, ranges), self.base_dir)))
        shape = tuple(hi - lo for lo, hi in ranges)
        n = math.prod(shape)
        columns = {}
        for key in self.axes:
            if key in self.categorical:
                columns[key] = np.full(n, str(combination[list(self.categorical).index(key)]), dtype=object)
            else:
                axis = list(self.numeric).index(key)
                lo, hi = ranges[axis]
                values = self.numeric[key][lo:hi].reshape([-1 if i == axis else 1 for i in range(len(shape))])
                columns[key] = np.broadcast_to(values, shape).ravel()
        for name, dtype in self.output_types.items():
            value = result.get(name)
            columns[name] = (
                np.full(n, np.nan) if value is None else np.broadcast_to(np.asarray(value, dtype), shape).ravel()
            )
        return columns

    @cached_property
    def output_types(self) -> dict[str, type]:
        """Flattened output columns (in `evaluate` order, union over the categorical combinations, restricted
        to `outputs`) and their dtypes."""
        types: dict[str, type] = {}
        for combination in self.combinations:
            probe = flatten_outputs(
                evaluate(build_design(self._config(combination, [(0, 1)] * len(self.shape)), self.base_dir))
            )
            for name, value in probe.items():
                types.setdefault(name, bool if np.asarray(value).dtype == bool else float)
        if self.outputs is None:
            return types
        unknown = [name for name in self.outputs if name not in types]
        if unknown:
            raise ConfigError("--columns", ",".join(unknown), f"unknown output; outputs are {', '.join(types)}")
        return {name: types[name] for name in self.outputs}

    @cached_property
    def schema(self) -> pa.Schema:
        fields = [pa.field(k, pa.string() if k in self.categorical else pa.float64()) for k in self.axes]
        fields += [pa.field(k, pa.bool_() if t is bool else pa.float64()) for k, t in self.output_types.items()]
        return pa.schema(fields)

    def row_bytes(self) -> int:
        """Bytes per row held in memory as a DataFrame (8 per number or string reference, 1 per flag)."""
        return sum(1 if t == pa.bool_() else 8 for t in self.schema.types)

    def part_name(self, index: int) -> str:
        return f"part-{index:0{max(6, len(str(self.chunks - 1)))}d}.parquet"


def write_part(grid: DesignGrid, index: int, directory: str | Path) -> int:
    """Evaluate chunk `index` of `grid` into `directory`/part-NNNNNN.parquet; returns its row count.

    Axis columns are dictionary-encoded (their values repeat); outputs are plain (dictionary attempts on
    continuous values cost more than the evaluation)."""
    table = grid.chunk_table(index)
    pq.write_table(table, Path(directory) / grid.part_name(index), use_dictionary=list(grid.axes))
    return table.num_rows


def check_output_path(out: str | Path) -> Path:
    """The `--out` target of a grid: .parquet (a directory of parts) or .csv, a new path in an existing directory
    that accepts files (`uwlab.outputs.output_file`)."""
    if Path(out).suffix.lower() not in OUTPUT_SUFFIXES:
        raise ConfigError("--out", str(out), "must end in .parquet or .csv")
    return output_file(out, "--out")


@contextmanager
def staged(out: Path, directory: bool):
    """A staging path beside `out` (a directory or a file), renamed to `out` on success, removed on failure."""
    stage = out.parent / f".{out.name}.partial-{os.getpid()}"
    if directory:
        stage.mkdir()
    try:
        yield stage
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True) if directory else stage.unlink(missing_ok=True)
        raise
    if out.exists():
        raise UwlabError(f"{out} appeared while the grid was written; the result is left in {stage}")
    stage.rename(out)


DISK_MARGIN = 1.1


def check_disk_space(grid: DesignGrid, stage: Path, rows_written: int = 0) -> None:
    """Refuse to go on when the grid, at the bytes per row written so far, would not fit on the disk holding
    ``stage`` (with a 10 % margin): a huge grid stops after its first chunk, not when the disk is full."""
    if stage.is_dir():  # Parquet parts: each holds one chunk (the last may be shorter)
        parts = [p.stat().st_size for p in stage.iterdir() if p.is_file()]
        per_point = sum(parts) / (len(parts) * grid.points / grid.chunks) if parts else 0.0
        remaining = max(grid.chunks - len(parts), 0) * grid.points / grid.chunks
    else:
        per_point = stage.stat().st_size / rows_written if rows_written else 0.0
        remaining = grid.points - rows_written
    needed = per_point * remaining * DISK_MARGIN
    free = shutil.disk_usage(stage if stage.is_dir() else stage.parent).free
    if needed > free:
        raise UwlabError(
            f"--out: the grid needs about {needed / 2**30:.3g} GiB more on disk "
            f"({per_point:.0f} bytes per point), {free / 2**30:.3g} GiB free; "
            "choose fewer points or fewer --columns"
        )


def write_grid(grid: DesignGrid, out: str | Path, progress=None) -> dict:
    """Evaluate `grid` chunk by chunk into `out` (.parquet: a directory of parts; .csv: one file) with memory
    bounded by one chunk; returns {"points", "out", "chunks", "columns"}. `progress(rows)` is called per chunk."""
    out = check_output_path(out)
    grid.check()
    rows = 0
    if out.suffix.lower() == ".parquet":
        with staged(out, directory=True) as stage:
            for index in range(grid.chunks):
                written = write_part(grid, index, stage)
                rows += written
                if index == 0:
                    check_disk_space(grid, stage, rows)
                if progress:
                    progress(written)
    else:
        with staged(out, directory=False) as stage:
            for index in range(grid.chunks):
                frame = grid.chunk(index)
                frame.to_csv(stage, mode="a", header=index == 0, index=False, float_format="%.17g")  # round trip
                rows += len(frame)
                if index == 0:
                    check_disk_space(grid, stage, rows)
                if progress:
                    progress(len(frame))
    return {"points": rows, "out": str(out), "chunks": grid.chunks, "columns": grid.schema.names}


def available_memory_bytes() -> int:
    import psutil

    return int(psutil.virtual_memory().available)


def in_memory_frame(grid: DesignGrid, memory_fraction: float = 0.5) -> pd.DataFrame:
    """The whole grid as one DataFrame, refused (one line, before any evaluation) when the result and its
    assembly (twice its size) would take more than `memory_fraction` of the available memory."""
    grid.check()
    needed = 2 * grid.points * grid.row_bytes()
    available = available_memory_bytes()
    if needed > memory_fraction * available:
        raise UwlabError(
            f"--grid: {grid.points:,} points need about {needed / 2**30:.3g} GiB in memory "
            f"({available / 2**30:.3g} GiB available); stream them to disk with --out FILE.parquet"
        )
    return pd.concat([grid.chunk(i) for i in range(grid.chunks)], ignore_index=True)


def evaluate_grid(raw: dict, axes: dict[str, list], base_dir: Path | None = None) -> pd.DataFrame:
    """Evaluate the design `raw` at every point of the Cartesian product of `axes`, in memory."""
    return in_memory_frame(DesignGrid(raw, axes, base_dir))
