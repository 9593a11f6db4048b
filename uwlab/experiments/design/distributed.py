"""Design grids on a Dask cluster (`dask.distributed`): the chunks of a `DesignGrid` as tasks, each writing its own
Parquet part.

`address` is ``local`` or a scheduler address ``tcp://HOST:PORT`` (`uwlab.experiments.cluster`). Workers run
`uwlab.experiments.design.grid.write_part`, the function the in-process writer runs, on the same chunk numbers, so
the files are the same bit for bit. Workers write the parts themselves, as `dask.dataframe.to_parquet` does: on a
multi-machine cluster `--out` must be on a file system every worker and this machine share (NFS, a cluster file
system), and every worker needs uwlab (the same version) and the data files the design names. At most a few chunks
per worker thread are in flight, so memory stays bounded on both sides whatever the grid size.
"""

from __future__ import annotations

from pathlib import Path

from uwlab.errors import ConfigError
from uwlab.experiments.cluster import dask_client
from uwlab.experiments.design.grid import DesignGrid, check_disk_space, check_output_path, staged, write_part

IN_FLIGHT_PER_THREAD = 3


def write_grid_dask(grid: DesignGrid, out: str | Path, address: str, progress=None) -> dict:
    """Evaluate `grid` on the Dask cluster at `address` into the Parquet directory `out` (see the module
    docstring); returns {"points", "out", "chunks", "columns", "workers"}."""
    from distributed import as_completed

    out = check_output_path(out)
    if out.suffix.lower() != ".parquet":
        raise ConfigError("--out", str(out), "a Dask grid writes Parquet: use a .parquet name")
    grid.check()
    schema = grid.schema  # computed here, shipped with the grid
    rows = 0
    with dask_client(address) as client, staged(out, directory=True) as stage:
        threads = sum(client.nthreads().values())
        remote = client.scatter(grid, broadcast=True)
        indices = iter(range(grid.chunks))
        pending = as_completed()
        for index in indices:
            pending.add(client.submit(write_part, remote, index, str(stage), pure=False))
            if pending.count() >= IN_FLIGHT_PER_THREAD * threads:
                break
        for future in pending:
            written = future.result()
            if rows == 0:
                check_disk_space(grid, stage)
            rows += written
            if progress:
                progress(written)
            future.release()
            following = next(indices, None)
            if following is not None:
                pending.add(client.submit(write_part, remote, following, str(stage), pure=False))
        workers = len(client.nthreads())
    return {"points": rows, "out": str(out), "chunks": grid.chunks, "columns": schema.names, "workers": workers}
