"""Where the jobs run: in this process, or on a Dask cluster (a local one by default).

Both map a picklable function over items and return the results in the items' order, calling
``progress(done, total)`` as results come in, so that the output does not depend on the engine.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol

Progress = Callable[[int, int], None]


class Engine(Protocol):
    name: str

    def map(self, fn: Callable[[Any], Any], items: Sequence[Any], progress: Progress | None = None) -> list[Any]:
        ...

    def close(self) -> None:
        ...


class SerialEngine:
    name = "serial"

    def map(self, fn: Callable[[Any], Any], items: Sequence[Any], progress: Progress | None = None) -> list[Any]:
        out = []
        for i, item in enumerate(items):
            out.append(fn(item))
            if progress:
                progress(i + 1, len(items))
        return out

    def close(self) -> None:
        pass


class DaskEngine:
    """``dask.distributed``: a ``LocalCluster`` of ``workers`` single-threaded processes, or the
    scheduler at ``address`` (``tcp://host:8786``) of a real cluster, whose workers must have this
    package installed."""

    name = "dask"

    def __init__(self, address: str | None = None, workers: int = 2) -> None:
        from dask.distributed import Client, LocalCluster

        self._cluster = None
        if address:
            self.client = Client(address)
        else:
            # one thread per worker process: the science is BLAS-bound and deterministic that way
            self._cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                         dashboard_address=None)
            self.client = Client(self._cluster)

    def map(self, fn: Callable[[Any], Any], items: Sequence[Any], progress: Progress | None = None) -> list[Any]:
        from dask.distributed import as_completed

        futures = self.client.map(fn, list(items), pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        out: list[Any] = [None] * len(futures)
        for done, fut in enumerate(as_completed(futures), 1):
            out[index[fut.key]] = fut.result()  # a job's exception is raised here, with its traceback
            if progress:
                progress(done, len(futures))
        return out

    def close(self) -> None:
        self.client.close()
        if self._cluster is not None:
            self._cluster.close()


def make_engine(kind: str, address: str | None = None, workers: int = 2) -> Engine:
    if kind == "serial":
        return SerialEngine()
    if kind == "dask":
        return DaskEngine(address, workers)
    raise ValueError(f"engine must be serial|dask, got {kind!r}")
