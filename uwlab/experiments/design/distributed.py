"""Design grids on a Dask cluster (`dask.distributed`): the chunks of a `DesignGrid` as tasks, each writing its
own Parquet part.

`address` is ``local`` (a `distributed.LocalCluster` on this machine: one single-threaded worker process per
core) or a scheduler address ``tcp://HOST:PORT`` (a cluster started with ``dask scheduler`` and
``dask worker tcp://HOST:PORT`` on each machine). Workers run `uwlab.experiments.design.grid.write_part`, the
function the in-process writer runs, on the same chunk numbers, so the files are the same bit for bit. Workers
write the parts themselves, as `dask.dataframe.to_parquet` does: on a multi-machine cluster `--out` must be on a
file system every worker and this machine share (NFS, a cluster file system), and every worker needs uwlab (the
same version) and the data files the design names. At most a few chunks per worker thread are in flight, so
memory stays bounded on both sides whatever the grid size.
"""

from __future__ import annotations

import logging
import os
from contextlib import contextmanager
from pathlib import Path

from uwlab.errors import ConfigError, UwlabError
from uwlab.experiments.design.grid import DesignGrid, check_disk_space, check_output_path, staged, write_part

IN_FLIGHT_PER_THREAD = 3
WORKER_TIMEOUT_S = 30


@contextmanager
def dask_client(address: str):
    """A `distributed.Client` for ``local`` (a LocalCluster, closed afterwards) or a ``tcp://`` scheduler."""
    from distributed import Client, LocalCluster

    if address == "local":
        cluster = LocalCluster(
            n_workers=os.cpu_count() or 1,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=logging.ERROR,
        )
        try:
            with Client(cluster) as client:
                yield client
        finally:
            cluster.close()
        return
    if not address.startswith(("tcp://", "tls://")):
        raise ConfigError("--dask", address, "expected local or a scheduler address tcp://HOST:PORT")
    try:
        client = Client(address, timeout=f"{WORKER_TIMEOUT_S}s")
    except (OSError, TimeoutError) as exc:
        raise UwlabError(f"--dask: cannot reach the Dask scheduler at {address} ({exc})") from None
    with client:
        try:
            client.wait_for_workers(1, timeout=WORKER_TIMEOUT_S)
        except TimeoutError:
            raise UwlabError(
                f"--dask: no worker joined the scheduler at {address} within {WORKER_TIMEOUT_S} s"
            ) from None
        yield client


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
            index = next(indices, None)
            if index is not None:
                pending.add(client.submit(write_part, remote, index, str(stage), pure=False))
        workers = len(client.nthreads())
    return {"points": rows, "out": str(out), "chunks": grid.chunks, "columns": schema.names, "workers": workers}
