"""Running a sweep: the frames not done yet, in this process or on Dask, each row written as it
finishes, then the table."""

from __future__ import annotations

import logging
import math
import os
import sys
import time
import uuid
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from .. import io
from ..materials import MATERIAL_NAMES
from ..pipeline import Pipeline
from .frames import FrameOutcome, _error_text, _frame_task, run_frame
from .spec import (
    CLOUDS_DIR,
    CONNECT_TIMEOUT_S,
    FRAMES_DIR,
    MANIFEST_NAME,
    TABLE_NAME,
    Frame,
    Sweep,
    SweepError,
    _cloud_format,
    _describe,
)
from .table import _assemble_table, _read_row, _row_path, _write_parquet


@dataclass(frozen=True, eq=False)
class SweepReport:
    """The outcome of :func:`run_sweep`.

    Attributes
    ----------
    out_dir, table_path : Path
    n_frames, n_skipped, n_run, n_failed : int
        Frames in the sweep; already done and skipped; run now; failed (now or before).
    n_workers : int
        Workers that ran the frames (0: in this process, without Dask).
    wall_s : float
        Wall time of run_sweep [s].
    table : pyarrow.Table
        One row per frame, in frame order (``read_table`` reads it back).
    """

    out_dir: Path
    table_path: Path
    n_frames: int
    n_skipped: int
    n_run: int
    n_failed: int
    n_workers: int
    wall_s: float
    table: Any

    def rows(self) -> list[dict[str, Any]]:
        """The table as a list of dicts, one per frame."""
        return self.table.to_pylist()

    def describe(self) -> str:
        """One line for the command line."""
        where = f"{self.n_workers} workers" if self.n_workers else "in process"
        failed = f", {self.n_failed} failed (rerun to retry)" if self.n_failed else ""
        return (
            f"{self.n_frames} frames ({self.n_run} run, {self.n_skipped} already done{failed}) "
            f"in {self.wall_s:.1f} s on {where} -> {self.table_path}"
        )


def run_sweep(
    sweep: Sweep,
    out_dir: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    client=None,
    clouds: str | bool | None = None,
    progress: bool = True,
    connect_timeout_s: float = CONNECT_TIMEOUT_S,
) -> SweepReport:
    """Run every frame not done yet in ``out_dir``, then (re)write the table.

    Parameters
    ----------
    sweep : Sweep
        From :func:`load_sweep` or :func:`build_sweep`.
    out_dir : str or Path
        The output folder (created if missing); see the module docstring for its layout.
    workers : int, optional
        Worker processes of a Dask LocalCluster started for this run (one thread each); default
        the number of cores. 0 runs the frames in this process, one after the other, without Dask.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://HOST:8786``) to use instead.
    client : distributed.Client, optional
        An existing Dask client to use instead (a notebook's cluster).
    clouds : "ply", "las", False or None
        Write each frame's point cloud; None: as the sweep says.
    progress : bool
        A progress bar on stderr.
    connect_timeout_s : float
        How long to wait for ``scheduler`` and one of its workers [s].

    Returns
    -------
    SweepReport

    Raises
    ------
    SweepError
        Conflicting arguments, an output path that is a file, an unreachable scheduler or one
        without workers: before any frame runs and before anything is written.
    """
    start = time.perf_counter()
    options = {"workers": workers, "scheduler": scheduler, "client": client}
    given = [name for name, value in options.items() if value is not None]
    if len(given) > 1:
        raise SweepError(f"give one of workers, scheduler or client, not {' and '.join(given)}")
    if workers is not None and (
        isinstance(workers, bool) or not isinstance(workers, int) or workers < 0
    ):
        raise SweepError(f"workers must be a whole number >= 0, got {workers!r}")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise SweepError(f"output folder {str(out)!r} is a file")
    fmt = sweep.clouds if clouds is None else _cloud_format(clouds, "clouds")
    pending = [f for f in sweep.frames if not _is_done(out, f, fmt)]
    n_failed_now = 0
    n_workers = 0
    with _Executor(pending, workers, scheduler, client, connect_timeout_s) as submit:
        for sub in (FRAMES_DIR, *((CLOUDS_DIR,) if fmt else ())):
            (out / sub).mkdir(parents=True, exist_ok=True)
        io.write_json(out / MANIFEST_NAME, _manifest(sweep))
        n_workers = submit.n_workers
        bar = tqdm(
            total=len(sweep),
            initial=len(sweep) - len(pending),
            desc=f"sweep {sweep.name}",
            unit="frame",
            file=sys.stderr,
            disable=not progress,
            dynamic_ncols=True,
        )
        with bar:
            for frame, outcome in submit(pending, fmt is not None):
                _record(out, sweep, frame, outcome, fmt)
                n_failed_now += outcome.error is not None
                if outcome.error is not None:
                    bar.set_postfix_str(f"{n_failed_now} failed")
                bar.update()
    table = _assemble_table(out, sweep)
    path = out / TABLE_NAME
    _write_parquet(path, table)
    n_failed = sum(1 for s in table.column("status").to_pylist() if s != "ok")
    return SweepReport(
        out_dir=out,
        table_path=path,
        n_frames=len(sweep),
        n_skipped=len(sweep) - len(pending),
        n_run=len(pending),
        n_failed=n_failed,
        n_workers=n_workers,
        wall_s=time.perf_counter() - start,
        table=table,
    )


def _cloud_name(frame: Frame, fmt: str) -> str:
    return f"{CLOUDS_DIR}/{frame.frame_id}.{fmt}"


def _is_done(out: Path, frame: Frame, fmt: str | None) -> bool:
    """A frame is done when its row says ok and, if clouds are asked, its cloud file exists."""
    row = _read_row(_row_path(out, frame))
    if row is None or row.get("status") != "ok":
        return False
    return fmt is None or (out / _cloud_name(frame, fmt)).is_file()


def _record(out: Path, sweep: Sweep, frame: Frame, outcome: FrameOutcome, fmt: str | None) -> None:
    """Write the frame's cloud (if any), then its row: the row marks the frame done."""
    cloud_name = None
    if outcome.cloud is not None and fmt is not None:
        cloud_name = _cloud_name(frame, fmt)
        comments = (
            "lmapd-sim point cloud, sensor frame (x right, y down, z boresight), metres",
            f"sweep {sweep.name} frame {frame.index} ({frame.frame_id}): {_describe(frame.params)}",
            f"scene {frame.scene.name}",
            outcome.target_line,
            f"material_id indexes: {' '.join(MATERIAL_NAMES)}",
        )
        io.write_cloud(out / cloud_name, outcome.cloud, comments)
    row = {
        "frame_id": frame.frame_id,
        "params": frame.params,
        "status": "ok" if outcome.error is None else "error",
        "error": outcome.error,
        "metrics": outcome.metrics,
        "frame_s": outcome.frame_s,
        "cloud": cloud_name,
    }
    io.write_json(_row_path(out, frame), row)


def _manifest(sweep: Sweep) -> dict[str, Any]:
    return {
        "name": sweep.name,
        "source": sweep.source,
        "base": sweep.base.name,
        "set": sweep.fixed,
        "clouds": sweep.clouds,
        "n_frames": len(sweep),
        "frames": [
            {"index": f.index, "frame_id": f.frame_id, "params": f.params} for f in sweep.frames
        ],
    }


class _Submit:
    """Runs frames and yields (frame, outcome) as they finish."""

    n_workers = 0

    def __call__(self, frames: Sequence[Frame], want_cloud: bool) -> Iterator:
        raise NotImplementedError


class _Serial(_Submit):
    """The frames one after the other in this process, through one Pipeline: ``run`` is
    ``run_frame``'s shape, ``(scene, pipeline, want_cloud) -> FrameOutcome``."""

    def __init__(self, run=run_frame):
        self.pipeline = Pipeline()
        self.run = run

    def __call__(self, frames, want_cloud):
        for frame in frames:
            yield frame, self.run(frame.scene, self.pipeline, want_cloud)


class _Dask(_Submit):
    """The frames as Dask tasks: ``task`` is ``_frame_task``'s shape, ``(scene, want_cloud) ->
    FrameOutcome``, run by a worker through its own Pipeline."""

    def __init__(self, client, n_workers: int, task=_frame_task):
        self.client = client
        self.n_workers = n_workers
        self.task = task

    def __call__(self, frames, want_cloud):
        from distributed import as_completed  # noqa: PLC0415

        by_key = {}
        futures = []
        run = uuid.uuid4().hex[:8]  # task keys unique per run: a notebook may rerun a sweep
        for frame in frames:
            fut = self.client.submit(
                self.task, frame.scene, want_cloud, key=f"lmapd-frame-{frame.frame_id}-{run}"
            )
            by_key[fut.key] = frame
            futures.append(fut)
        try:
            # this client's loop: as_completed would take the default client's, and with two
            # clients in one process it would then wait forever
            done = as_completed(
                futures, loop=self.client.loop, with_results=True, raise_errors=False
            )
            for fut, value in done:
                frame = by_key.pop(fut.key)
                if not isinstance(value, FrameOutcome):  # the task itself failed (worker lost)
                    exc = value[1] if isinstance(value, tuple) and len(value) == 3 else value
                    value = FrameOutcome(None, _error_text(exc), math.nan)
                fut.release()
                yield frame, value
        finally:
            self.client.cancel(list(futures))


class _Executor:
    """Context manager: the frame runner, with any cluster it starts closed on exit.

    ``run`` and ``task`` are what one frame runs, in this process and on a Dask worker
    (:class:`_Serial`, :class:`_Dask`): a sweep's frame by default."""

    def __init__(self, pending, workers, scheduler, client, timeout_s, run=None, task=None):
        self.pending = pending
        self.workers = workers
        self.scheduler = scheduler
        self.client = client
        self.timeout_s = timeout_s
        self.run = run or run_frame
        self.task = task or _frame_task
        self.owned: list = []

    def __enter__(self) -> _Submit:
        try:
            return self._start()
        except BaseException:
            self.__exit__()  # __exit__ does not run when __enter__ raises
            raise

    def _start(self) -> _Submit:
        if self.client is not None:
            return _Dask(self.client, len(self.client.scheduler_info()["workers"]), self.task)
        if self.scheduler:
            client = _connect(self.scheduler, self.timeout_s)
            self.owned.append(client)
            return _Dask(client, len(client.scheduler_info()["workers"]), self.task)
        n = (os.cpu_count() or 1) if self.workers is None else self.workers
        if n == 0 or not self.pending:
            return _Serial(self.run)
        n = min(n, len(self.pending))
        from distributed import Client, LocalCluster  # noqa: PLC0415  (slow import)

        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",
            silence_logs=logging.ERROR,
        )
        self.owned.append(cluster)
        client = Client(cluster)
        self.owned.append(client)
        return _Dask(client, n, self.task)

    def __exit__(self, *exc) -> None:
        for obj in reversed(self.owned):
            obj.close()


def _connect(address: str, timeout_s: float):
    """A Client of the scheduler at ``address`` with at least one worker, or SweepError."""
    from distributed import Client  # noqa: PLC0415

    try:
        client = Client(address, timeout=timeout_s)
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        raise SweepError(
            f"cannot reach the Dask scheduler at {address!r} within {timeout_s:g} s ({exc}); "
            "give its address as tcp://HOST:PORT (default port 8786) and check it is running"
        ) from None
    try:
        client.wait_for_workers(1, timeout=timeout_s)
    except (OSError, TimeoutError) as exc:
        client.close()
        raise SweepError(
            f"the Dask scheduler at {address!r} has no workers after {timeout_s:g} s ({exc}); "
            "start some with `dask worker ADDRESS`"
        ) from None
    return client
