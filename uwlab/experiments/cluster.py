"""The Dask cluster uwlab's distributed work runs on (design grids, EMVA fleets): ``local`` (a
`distributed.LocalCluster` on this machine: one single-threaded worker process per core) or a scheduler address
``tcp://HOST:PORT`` (a cluster started with ``dask scheduler`` and ``dask worker tcp://HOST:PORT`` on each
machine)."""

from __future__ import annotations

import logging
import os
from contextlib import contextmanager

from uwlab.errors import ConfigError, UwlabError

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
