"""The held-out folds of a calibration in parallel, while the whole-data fit runs (`folds_in_background`).

- On this machine: worker processes of their own, ``python -m uwlab.experiments.calibration.parallel``, each given
  its share of the folds (pickled on its stdin) and returning their predictions (pickled on its stdout); as many
  workers as cores, never more than folds. They are never children of the caller's ``__main__``:
  multiprocessing's ``spawn`` and ``forkserver`` start methods import the main script again in every child (as
  ``__mp_main__``), which re-runs a user's script that has no ``if __name__ == "__main__"`` guard, and ``fork``
  copies a process that may hold threads. The workers run single-threaded BLAS (``OMP_NUM_THREADS`` and its kin,
  unless the caller set them): the cores are theirs.
- On a Dask cluster (`uwlab.experiments.cluster.dask_client`: ``local`` or ``tcp://HOST:PORT``): one task per fold.
  The workers need uwlab installed and the dataset's rigs' files (a characterised sensor's profile) at the same
  paths, as for ``uwlab emva fleet --dask``.

Every fold fits with the config's sampler seed and draws its predictions from seed + its number, wherever it runs,
so the numbers do not depend on where or in which order the folds ran.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from typing import cast

import pandas as pd

from uwlab.errors import UwlabError
from uwlab.experiments.calibration.fit import FitConfig
from uwlab.experiments.calibration.forward import reused_configurations
from uwlab.experiments.calibration.validation import HeldOutFold, held_out_fold

SINGLE_THREAD = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@dataclass(frozen=True)
class FoldJob:
    """Folds to fit: the dataset's points and rigs, the fit config, the chain (`kind`), the prediction seed, the
    folds as (number, held-out sweeps) and the configurations' chains evaluated already (a `reused_configurations`
    store: the whole-data fit's)."""

    points: pd.DataFrame
    rigs: dict
    config: FitConfig
    kind: str | None
    seed: int
    folds: tuple[tuple[int, tuple[str, ...]], ...]
    configurations: dict = field(default_factory=dict)

    def share(self, index: int, count: int) -> FoldJob:
        """Every `count`-th fold from the `index`-th."""
        return replace(self, folds=self.folds[index::count])


def run_folds(job: FoldJob) -> list[HeldOutFold | None]:
    """Fit and predict the job's folds here, in order (`uwlab.experiments.calibration.validation.held_out_fold`),
    each configuration's chain evaluated once for all of them, or not at all where the job carries it
    (`reused_configurations`)."""
    with reused_configurations(job.configurations):
        return [
            held_out_fold(job.points, job.rigs, job.config, list(fold), number, job.kind, seed=job.seed)
            for number, fold in job.folds
        ]


def _reply(job: FoldJob) -> tuple[str, object]:
    """A worker's answer: ("ok", `run_folds`'s results) or ("error", the message of its `UwlabError`), which
    pickles where the error may not and leaves no traceback in the worker's log."""
    try:
        return "ok", run_folds(job)
    except UwlabError as exc:
        return "error", str(exc)


def _result(reply: tuple[str, object]) -> list[HeldOutFold | None]:
    status, value = reply
    if status == "ok":
        return cast("list[HeldOutFold | None]", value)
    raise UwlabError(str(value))


@contextmanager
def folds_in_background(
    job: FoldJob, workers: int | None = None, dask: str | None = None
) -> Iterator[Callable[[], list[HeldOutFold | None]]]:
    """Start the job's folds (module docstring) on `workers` processes (None: one per core) or on the Dask
    cluster at `dask`; yields the function that waits for them and returns their results in the job's order.
    Leaving the block stops the folds still running."""
    if dask is not None:
        with _on_dask(job, dask) as collect:
            yield collect
        return
    count = max(1, min(workers or os.cpu_count() or 1, len(job.folds)))
    shares = [pickle.dumps(job.share(i, count)) for i in range(count)]
    env = {**os.environ, **{name: os.environ.get(name, "1") for name in SINGLE_THREAD}}
    processes: list[subprocess.Popen] = []
    try:
        for _ in range(count):
            processes.append(
                subprocess.Popen(
                    [sys.executable, "-m", __name__],
                    stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.PIPE,
                    env=env,
                )
            )
        with ThreadPoolExecutor(count) as pool:
            talks = [pool.submit(p.communicate, share) for p, share in zip(processes, shares, strict=True)]

            def collect() -> list[HeldOutFold | None]:
                done = [_answer(process, *talk.result()) for process, talk in zip(processes, talks, strict=True)]
                return [done[i % count][i // count] for i in range(len(job.folds))]

            try:
                yield collect
            finally:
                _stop(processes)  # so that the pool's threads return
    finally:
        _stop(processes)


def _stop(processes: list[subprocess.Popen]) -> None:
    for process in processes:
        if process.poll() is None:
            process.kill()
        process.wait()


def _answer(process: subprocess.Popen, out: bytes, err: bytes) -> list[HeldOutFold | None]:
    """A worker's results, or its error as a `UwlabError`."""
    if process.returncode == 0:
        return _result(pickle.loads(out))
    last = err.decode(errors="replace").strip().splitlines()[-1:] or [f"exit code {process.returncode}"]
    raise UwlabError(f"a held-out fold's worker failed: {last[0]}")


@contextmanager
def _on_dask(job: FoldJob, address: str) -> Iterator[Callable[[], list[HeldOutFold | None]]]:
    from uwlab.experiments.cluster import dask_client

    with dask_client(address) as client:
        futures = [client.submit(_reply, job.share(i, len(job.folds)), pure=False) for i in range(len(job.folds))]
        try:
            yield lambda: [_result(future.result())[0] for future in futures]
        finally:
            client.cancel(futures)


def main() -> int:
    """A worker: a pickled `FoldJob` on stdin, ("ok", its results) or ("error", the message) pickled on stdout."""
    job = pickle.load(sys.stdin.buffer)
    answer = sys.stdout.buffer
    sys.stdout = sys.stderr  # nothing but the answer on stdout
    try:
        reply = _reply(job)
    except KeyboardInterrupt:
        return 130
    pickle.dump(reply, answer)
    answer.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
