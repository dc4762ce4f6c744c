"""Running a study on Dask, resumably, and writing what it found.

:func:`run_study` runs in memory and returns the rows and the summary. :func:`study_to_folder` (the
``calib-masonry study`` command) also keeps every finished sample as ``samples/NNNNNN.json`` the
moment it finishes (one atomic rename each), so a killed study loses at most the samples in
flight, and running the same command again computes only the missing ones. At the end it writes
``samples.csv``, ``samples.parquet``, ``summary.json`` and the figures.

Execution: a ``LocalCluster`` with one single-threaded worker process per core by default (bpy is
not thread-safe), or any running scheduler (``scheduler="tcp://HOST:PORT"``: dask-jobqueue,
Kubernetes, or ``dask scheduler`` and ``dask worker`` by hand; the workers must see the study's
files at the same paths). ``workers=0`` runs the samples in this process, one after another.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import shutil
import time
from collections.abc import Callable
from pathlib import Path

from ..errors import InputError
from ..io import OUTPUT_MARKER, check_output, write_json
from ..process import signals_deferred
from ..progress import progress as _progress
from .analysis import input_columns, output_columns, plot_study, summarize
from .design import Sample, Study, samples, study_json
from .sample import ROW_KEYS, run_sample, run_sample_async, warm_worker

__all__ = ["run_study", "study_to_folder", "dask_client", "execute_samples", "SCHEDULER_TIMEOUT_S"]

SCHEDULER_TIMEOUT_S = 10.0
# what every worker process starts with: a fixed hash seed, and one thread per numerical library (a
# worker per core; a threaded BLAS sums in an order that depends on its thread count)
WORKER_ENV = {"PYTHONHASHSEED": "0", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
WORKER_CONFIG = {"distributed.worker.profile.enabled": False, "distributed.admin.system-monitor.gil.enabled": False}


def _client(scheduler: str | None, workers: int | None):
    """A dask client (and the cluster it owns, or None) for a scheduler address or a new LocalCluster."""
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout=SCHEDULER_TIMEOUT_S), None
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(
                f"--scheduler {scheduler}: cannot reach it ({type(exc).__name__}: {str(exc).splitlines()[0]}); "
                "start `dask scheduler` there, or check the address (tcp://HOST:PORT)"
            ) from None
    import dask

    n = workers or os.cpu_count() or 1
    # no statistical profiler (it samples the sample's stack every 10 ms) and no GIL monitor in
    # the local workers: nobody reads them here, and they cost the samples' own Python time
    cluster = client = None
    try:
        # a SIGTERM or Ctrl-C while the cluster starts is raised once it stands whole, and it is
        # closed here: a cluster left half-built failed distributed's own close at exit (an
        # AssertionError traceback after the CLI's one line)
        with signals_deferred(), dask.config.set(WORKER_CONFIG):
            cluster = LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                # the scheduler serves HTTP even without a dashboard, on 8787 unless told: a port
                # in use (another cluster) printed dask's three-line note; any free port says nothing
                dashboard_address=":0",
                # a sample's error is in its row; a stopped run's closing heartbeats are no errors
                silence_logs=logging.CRITICAL,
                env=WORKER_ENV,
            )
            client = Client(cluster)
    except BaseException:
        _close(client, cluster)
        raise
    return client, cluster


def _close(client, cluster) -> None:
    """Close a client and the cluster it owns, a signal meanwhile raised after both are closed.
    Nothing distributed logs meanwhile is shown: a scheduler still reporting to the client as it
    closes logs CRITICAL "Closed comm ... while trying to write" with a CommClosedError traceback
    (seen once in CI, SIGTERM while samples ran), which is no error of the run's."""
    import logging

    handlers = [h for h in logging.getLogger("distributed").handlers if isinstance(h, logging.StreamHandler)]
    levels = [h.level for h in handlers]
    try:
        with signals_deferred():
            for h in handlers:
                h.setLevel(logging.CRITICAL + 1)
            if client is not None:
                client.close()
            if cluster is not None:
                cluster.close()
    finally:
        for h, level in zip(handlers, levels):
            if h.level == logging.CRITICAL + 1:  # as it was (the cluster's close restores its own)
                h.setLevel(level)


def check_scheduler(scheduler: str) -> None:
    """Refuse an address that is not ``tcp://HOST:PORT`` (or another dask protocol) before any work."""
    if "://" not in scheduler or not scheduler.split("://", 1)[1]:
        raise InputError(f"--scheduler {scheduler!r}: give the scheduler's address as tcp://HOST:PORT")


@contextlib.contextmanager
def dask_client(scheduler: str | None, workers: int | None, simulate: bool = False):
    """A connected dask client for the run (None for ``workers=0``: this process); with ``simulate``
    its workers have started Blender."""
    if workers == 0:
        yield None
        return
    client, cluster = _client(scheduler, workers)
    try:
        client.run(warm_worker, simulate)  # the stages' imports are start-up, not the first sample's cost
        yield client
    finally:
        _close(client, cluster)


def execute_samples(
    study_: Study, todo: list[Sample], on_row: Callable[[dict], None], client, *, progress: bool | None
) -> None:
    """Run the samples ``todo`` of ``study_`` (on ``client``'s workers, or here for None), calling
    ``on_row`` with each sample's row as it ends."""
    bar = _progress(total=len(todo), desc=f"study {study_.name}", unit="sample", enabled=progress)
    try:
        if client is None:
            for s in todo:
                on_row(run_sample(study_, s))
                bar.update()
            return
        from distributed import as_completed

        # a coroutine: the worker runs it on its event loop, its main thread, where Blender is reproducible
        futures = [client.submit(run_sample_async, study_, s, pure=False, key=f"sample-{s.index}") for s in todo]
        try:
            for fut in as_completed(futures):
                on_row(fut.result())
                bar.update()
        finally:
            client.cancel(futures)
    finally:
        bar.close()


def run_study(
    study_: Study,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool | None = None,
) -> tuple[list[dict], dict]:
    """Run every sample of ``study_`` and return the rows (in sample order) and the summary; in
    memory, writing nothing."""
    if scheduler:
        check_scheduler(scheduler)
    _check_workers(workers)
    rows: dict[int, dict] = {}
    with dask_client(scheduler, workers, study_.simulate is not None and study_.simulate.bullet) as client:
        execute_samples(study_, samples(study_), lambda r: rows.__setitem__(r["sample"], r), client, progress=progress)
    ordered = [rows[i] for i in sorted(rows)]
    return ordered, summarize(study_, ordered)


def _columns(study_: Study, rows: list[dict]) -> list[str]:
    head = ["sample", "point", "status"]
    tail = ["error", "warnings", "seconds", "worker"]
    middle = [c for c in input_columns(study_, rows) + output_columns(study_, rows) if c not in ROW_KEYS]
    return head + list(dict.fromkeys(middle)) + tail


def _normalised(rows: list[dict], columns: list[str]) -> dict[str, list]:
    """Column lists for Arrow: ints promoted to float where a column mixes them, bools as ints."""
    table = {}
    for c in columns:
        vals = [r.get(c) for r in rows]
        present = [v for v in vals if v is not None]
        if present and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in present):
            if any(isinstance(v, float) for v in present):
                vals = [None if v is None else float(v) for v in vals]
        elif present and not all(isinstance(v, str) for v in present):
            vals = [None if v is None else str(v) for v in vals]
        table[c] = vals
    return table


def write_table(study_: Study, rows: list[dict], folder: Path) -> None:
    """``samples.csv`` and ``samples.parquet``: one row per sample."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    columns = _columns(study_, rows)
    with open(folder / "samples.csv.partial", "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        for r in rows:
            w.writerow(["" if r.get(c) is None else _csv(r.get(c)) for c in columns])
    os.replace(folder / "samples.csv.partial", folder / "samples.csv")
    pq.write_table(pa.table(_normalised(rows, columns)), folder / "samples.parquet.partial")
    os.replace(folder / "samples.parquet.partial", folder / "samples.parquet")


def _csv(v):
    return repr(v) if isinstance(v, float) and math.isfinite(v) else v


def _prepare(out: Path, study_: Study, overwrite: bool) -> Path:
    """The output folder, new or this study's earlier (resumable) one; refuses anything else."""
    out = check_output(out, command="study", overwrite=overwrite)
    info = study_json(study_)
    if out.exists() and any(out.iterdir()):
        meta = out / "study.json"
        earlier = json.loads(meta.read_text(encoding="utf-8")) if meta.is_file() else {}
        if overwrite or earlier.get("fingerprint") != info["fingerprint"]:
            if not overwrite:
                raise InputError(
                    f"--out {out}: it holds the samples of a different study (or of this one before it was "
                    "edited); choose a new folder, or add --overwrite to start this study there afresh"
                )
            shutil.rmtree(out)
    (out / "samples").mkdir(parents=True, exist_ok=True)
    (out / OUTPUT_MARKER).write_text(json.dumps({"command": "study"}) + "\n", encoding="utf-8")
    write_json(out / "study.json", info)
    for stale in (out / "samples").glob("*.partial"):
        stale.unlink()
    return out


def _read_done(folder: Path) -> dict[int, dict]:
    done = {}
    for f in sorted(folder.glob("[0-9]*.json")):
        try:
            row = json.loads(f.read_text(encoding="utf-8"))
            done[int(row["sample"])] = row
        except (ValueError, KeyError, OSError):
            f.unlink(missing_ok=True)  # unreadable: computed again
    return done


def study_to_folder(
    study_: Study,
    out: str | Path,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool | None = None,
    overwrite: bool = False,
    figures: bool = True,
) -> tuple[list[dict], dict, int]:
    """``calib-masonry study``: run the samples not yet in ``out`` and write the table, the
    summary and the figures. Returns the rows, the summary and how many samples this call ran."""
    if scheduler:
        check_scheduler(scheduler)
    _check_workers(workers)
    check_output(out, command="study", overwrite=overwrite)
    # an unreachable scheduler is refused before --out is touched
    with dask_client(scheduler, workers, study_.simulate is not None and study_.simulate.bullet) as client:
        return _run_into(study_, Path(out), client, progress=progress, overwrite=overwrite, figures=figures)


def _check_workers(workers: int | None) -> None:
    if workers is not None and not 0 <= workers <= 1024:
        raise InputError(f"--workers {workers}: give 1..1024 worker processes (0: in this process)")


def _run_into(study_: Study, out: Path, client, *, progress, overwrite: bool, figures: bool):
    out = _prepare(out, study_, overwrite)
    sample_dir = out / "samples"
    done = _read_done(sample_dir)
    every = samples(study_)
    todo = [s for s in every if s.index not in done]

    def keep(row: dict) -> None:
        tmp = sample_dir / f"{row['sample']:06d}.json.partial"
        tmp.write_text(json.dumps(row, default=str) + "\n", encoding="utf-8")
        os.replace(tmp, sample_dir / f"{row['sample']:06d}.json")
        done[row["sample"]] = row

    t0 = time.perf_counter()
    try:
        execute_samples(study_, todo, keep, client, progress=progress)
    except KeyboardInterrupt as exc:
        ran = len(done) - (len(every) - len(todo))
        exc.written = (
            f"{len(done)} of {len(every)} samples are kept in {sample_dir} ({ran} from this run, "
            f"{time.perf_counter() - t0:.0f} s); run the same command again to compute the rest"
        )
        raise
    rows = [done[i] for i in sorted(done)]
    summary = summarize(study_, rows)
    write_table(study_, rows, out)
    write_json(out / "summary.json", summary)
    if figures:
        shutil.rmtree(out / "figures", ignore_errors=True)
        plot_study(study_, rows, summary, out / "figures")
    return rows, summary, len(todo)
