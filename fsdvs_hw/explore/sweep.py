"""Design sweeps: expand a design into points and run them on a local pool or a Dask cluster.

A *design point* is one realisation (``learned``, ``delta``, ``mesh``, ``asic``, ``metalens``) with
one setting of the sweep axes that concern it: axes under a realisation (``asic.bits``) multiply
only that realisation's points; axes elsewhere (``sensor.threshold_on``, ``kernel.params.sigma_px``)
multiply every point; axes over ``[costs]`` keys build no points (they re-cost the stored ones,
:mod:`fsdvs_hw.explore.costing`). Each point carries everything a worker needs (validated design data and the
target taps), so remote Dask workers need no files, and a key that hashes exactly what decides its
result (its own realisation options, not the others').

Execution: ``workers = 1`` runs in this process; more workers use a local
:class:`concurrent.futures.ProcessPoolExecutor` (spawned processes, one torch thread each);
``scheduler="tcp://HOST:PORT"`` submits to a running Dask distributed scheduler. In every case the
coordinator writes each result to the :class:`~fsdvs_hw.explore.store.ResultsStore` as soon as it
arrives, and skips points already stored, so a killed run resumes where it stopped.

The ``fsdvs-hw sweep`` command is :mod:`fsdvs_hw.cli.sweep`.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import socket
import time
import traceback
import urllib.parse
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, TypeVar, cast

from ..design.design import Design, axis_values, process_fit_options
from ..design.sections import design_model
from ..design.user_data_section import DEFAULT_MAX_FAILED_CLIP_FRACTION
from ..environment import env, set_env
from ..errors import InputError
from ..fingerprints import fingerprint
from ..limits import MAX_WORKERS, check_count
from ..provenance import library_versions
from ..records import Score, ScoredPoint
from ..schema import DESIGN_CONTEXT
from .store import ResultsStore

__all__ = [
    "DesignPoint",
    "SweepSummary",
    "check_scheduler_address",
    "check_sweep_size",
    "count_points",
    "dask_security",
    "evaluate_point",
    "expand_points",
    "run_design",
    "run_points",
]

#: Memory of a built design point per character of its JSON form (measured with tracemalloc: 2000
#: points of a 2.2 kB design take 11.8 MiB, 2.8 bytes per character).
_BYTES_PER_JSON_CHAR = 3

#: Design sections whose content decides every point's result (others only organise the run).
_SCORED_SECTIONS = ("kernel", "sensor", "optics", "analysis", "tasks", "emulation")


@dataclass(frozen=True)
class DesignPoint:
    """One unit of work: a realisation with its options, scored under one design setting.

    Attributes
    ----------
    key : str
        SHA-1 (hex, 20 chars) of what decides the result; the results store's primary key.
    design : str
        Design name.
    realisation : str
        ``learned``, ``delta``, ``mesh``, ``asic`` or ``metalens``.
    params : dict
        The sweep-axis values of this point (dotted keys), ``{}`` without axes.
    data : dict
        Validated design data with the axis values applied.
    target : dict
        The target kernel (:meth:`Kernel.to_dict`).
    base_dir : str
        Folder relative paths in the design are resolved against.
    """

    key: str
    design: str
    realisation: str
    params: dict[str, Any]
    data: dict[str, Any] = field(repr=False)
    target: dict[str, Any] = field(repr=False)
    base_dir: str = "."

    @property
    def spec(self) -> Any:
        """The point's design, typed (the model of :func:`~fsdvs_hw.design.sections.design_model`):
        ``point.spec.run.seed``, ``point.spec.tasks.checkpoints``; :attr:`data` is its JSON form."""
        return design_model().model_validate(self.data, context=DESIGN_CONTEXT)

    @property
    def label(self) -> str:
        if not self.params:
            return self.realisation
        return self.realisation + " " + ", ".join(f"{k.split('.')[-1]}={v}" for k, v in self.params.items())


def _point_key(realisation: str, design: Design) -> str:
    relevant: dict[str, Any] = {s: design.section(s) for s in _SCORED_SECTIONS}
    if not relevant["tasks"].get("datasets"):  # no user data: the key of a store written before the key existed
        relevant["tasks"].pop("datasets", None)
    for entry in relevant["tasks"].get("datasets", {}).values():
        entry["dataset"].pop("cache", None)  # where decoded clips are kept changes no score
        if entry.get("max_failed_clip_fraction") == DEFAULT_MAX_FAILED_CLIP_FRACTION:
            entry.pop("max_failed_clip_fraction")  # the key of a store written before the key existed
        _drop_unset_streaming_keys(entry)
    relevant["realisation"] = realisation
    relevant["options"] = design.realisation_options(realisation)
    relevant["target"] = design.target.to_dict()["taps"]
    relevant["pitch_m"] = design.target.pitch_m
    return fingerprint(relevant, length=20)


def _drop_unset_streaming_keys(entry: dict[str, Any]) -> None:
    """A table's sampling and val_fraction only when set (the key of a store written before they existed);
    of the loader's memory_mb and workers only whether the clips stream (streamed runs train the same
    network whatever they are; an in-memory run another)."""
    if entry.get("sampling") is None:
        entry.pop("sampling", None)
    train = entry.get("train") or {}
    if train.get("memory_mb") is not None or train.get("workers"):
        train["streamed"] = True
    for k in ("memory_mb", "workers"):
        train.pop(k, None)
    if not train.get("val_fraction"):
        train.pop("val_fraction", None)


def _scored_axes(design: Design) -> dict[str, list[Any]]:
    """The axes that change a point's score: all but ``costs.*``, which only re-cost stored points
    (:func:`fsdvs_hw.explore.costing.with_physical_costs`)."""
    return {k: v for k, v in axis_values(design).items() if not k.startswith("costs.")}


def count_points(design: Design) -> int:
    """How many design points :func:`expand_points` builds at most (before removing duplicates).

    Computed from the axis lengths alone: (product of the global axes) × Σ over realisations of
    (product of that realisation's axes).
    """
    axes = _scored_axes(design)
    n_global = math.prod(len(v) for k, v in axes.items() if not k.startswith("realisations."))
    per_real = sum(
        math.prod(len(v) for k, v in axes.items() if k.startswith(f"realisations.{name}."))
        for name in design.realisations
    )
    return n_global * per_real


def check_sweep_size(design: Design, max_points: int | None = None) -> int:
    """Refuse a sweep larger than ``max_points`` (default: the design's ``[run] max_points``) before
    building it; return its point count.

    Raises
    ------
    InputError
        With the point count, the memory its list would take (estimated from one point's size) and
        the limit, and how to raise it.
    """
    limit = int(design.spec.run.max_points if max_points is None else max_points)
    n = count_points(design)
    if n > limit:
        point_data = {**design.to_dict(), "sweep": {"axes": {}}}  # what each point carries
        one = len(json.dumps({"data": point_data, "target": design.target.to_dict()}, default=str))
        gib = n * one * _BYTES_PER_JSON_CHAR / 2**30
        raise InputError(
            f"{design.source}: the sweep has {n:,} design points (about {gib:.3g} GiB to hold their list, "
            f"and each is validated before it runs), more than the limit of {limit:,}; raise it with "
            f"[run] max_points or --max-points if that is what you mean"
        )
    return n


def expand_points(design: Design, *, max_points: int | None = None) -> list[DesignPoint]:
    """All design points of a design, in a stable order (references first).

    Every point's design is re-validated with its axis values before anything runs, so a bad value
    on any axis fails here, naming the axis. A sweep of more than ``max_points`` points (default
    the design's ``[run] max_points``) is refused before anything is built
    (:func:`check_sweep_size`).
    """
    check_sweep_size(design, max_points)
    axes = _scored_axes(design)
    global_axes = {k: v for k, v in axes.items() if not k.startswith("realisations.")}
    points: list[DesignPoint] = []
    seen: set[str] = set()
    g_keys = list(global_axes)
    for g_vals in itertools.product(*global_axes.values()) if g_keys else [()]:
        g_over = dict(zip(g_keys, g_vals))
        for name in design.realisations:
            r_axes = {k: v for k, v in axes.items() if k.startswith(f"realisations.{name}.")}
            r_keys = list(r_axes)
            for r_vals in itertools.product(*r_axes.values()) if r_keys else [()]:
                over = {**g_over, **dict(zip(r_keys, r_vals))}
                d = design.with_overrides(over) if over else design
                key = _point_key(name, d)
                if key in seen:
                    continue
                seen.add(key)
                params = {k.removeprefix("realisations."): v for k, v in over.items()}
                points.append(
                    DesignPoint(
                        key=key,
                        design=design.name,
                        realisation=name,
                        params=params,
                        data=d.to_dict(),
                        target=d.target.to_dict(),
                        base_dir=str(d.base_dir),
                    )
                )
    return points


def evaluate_point(point: DesignPoint) -> dict[str, Any]:
    """Fit and score one point (runs in a worker). Never raises: failures become a status.

    Warnings raised while fitting and scoring (e.g. a fitter saying the target is out of reach)
    are kept in the record's ``"warnings"`` list.

    Returns
    -------
    dict
        ``{"key", "status": "ok"|"error", "result": score record or {"reason": ...},
        "wall_s", "worker"}``.
    """
    if env("FSDVS_HW_WORKER_THREADS"):
        try:
            import torch

            torch.set_num_threads(int(env("FSDVS_HW_WORKER_THREADS") or 1))
        except ImportError:  # pragma: no cover - torch is a dependency
            pass
    t0 = time.perf_counter()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    data = point.data
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        status, rec = _fit_and_score(point, data)
    # fitters warn about unreachable targets, asymmetric kernels, ...: keep ours with the score
    ours = [w for w in caught if f"{os.sep}fsdvs_hw{os.sep}" in str(w.filename)]
    said = list(dict.fromkeys(f"{w.category.__name__}: {w.message}" for w in ours))[:20]
    versions = library_versions()  # of this worker: a Dask cluster's workers may differ
    if isinstance(rec, Score):
        result = rec.with_(warnings=said, versions=versions).to_dict()
    else:
        result = {**rec, **({"warnings": said} if said else {}), "versions": versions}
    return {"key": point.key, "status": status, "result": result, "wall_s": time.perf_counter() - t0, "worker": worker}


def _fit_and_score(point: DesignPoint, data: dict[str, Any]) -> tuple[str, Score | dict[str, Any]]:
    """``("ok", score)`` or ``("error", {"reason", "traceback"})``: one failed point must not stop a sweep."""
    from ..kernels import Kernel
    from .scoring import fit_realisation, score

    try:
        target = Kernel.from_dict(point.target, source="design point target")
        options = process_fit_options(data, point.realisation, data["realisations"].get(point.realisation, {}))
        rec: Score | dict[str, Any]
        real, fit_s = fit_realisation(point.realisation, target, options, seed=data["run"]["seed"])
        tasks = data["tasks"]
        base = Path(point.base_dir)
        rec = score(
            real,
            target=target,
            csf_methods=data["analysis"]["csf_methods"],
            focal_length_m=data["optics"]["focal_length_m"],
            checkpoints={
                t: [(p if Path(p).is_absolute() else base / p) for p in (v if isinstance(v, list) else [v])]
                for t, v in tasks["checkpoints"].items()
            },
            task_options={
                "n_test": tasks["n_test"],
                "n_test_emulation": tasks["n_test_emulation"],
                "finetune_epochs": tasks["finetune_epochs"],
                "test_clips": tasks["test_clips"],
                "tracks": tasks["tracks"],
                "datasets": tasks.get("datasets", {}),
                "base_dir": base,
                "design_sensor": data["sensor"] if tasks["sensor"] == "design" else None,
            },
            emulation={"sensor": data["sensor"], "emulation": data["emulation"], "seed": data["run"]["seed"]},
            fit_wall_s=fit_s,
        )
        rec = rec.with_(realisation=real.to_dict())
        status = "ok"
    except Exception as exc:  # noqa: BLE001 - one failed point must not stop a sweep; it is recorded
        status = "error"
        rec = {"reason": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc(limit=8)}
    return status, rec


@dataclass
class SweepSummary:
    """What a run did: points in total, skipped as already stored, run now, and their statuses."""

    total: int
    already_done: int
    ran: int
    statuses: dict[str, int]
    wall_s: float
    executor: str

    def __str__(self) -> str:
        st = ", ".join(f"{v} {k}" for k, v in sorted(self.statuses.items())) or "nothing new"
        return (
            f"{self.total} points: {self.already_done} already in the store, {self.ran} run now ({st}) "
            f"in {self.wall_s:.1f} s on {self.executor}"
        )


class _Point(Protocol):
    """What :func:`run_points` reads of a point: a :class:`DesignPoint`, or another record with these
    fields (the kernel-size ablation's training runs)."""

    @property
    def key(self) -> str: ...
    @property
    def design(self) -> str: ...
    @property
    def realisation(self) -> str: ...
    @property
    def params(self) -> dict[str, Any]: ...
    @property
    def label(self) -> str: ...


_P = TypeVar("_P", bound=_Point)


def _record(store: ResultsStore, point: _Point, res: dict[str, Any]) -> None:
    store.add(
        point.key,
        design=point.design,
        realisation=point.realisation,
        params=point.params,
        status=res["status"],
        result=res["result"],
        wall_s=res["wall_s"],
        worker=res["worker"],
    )


def run_points(
    points: Sequence[_P],
    store: ResultsStore,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool | None = None,
    on_result: Callable[[_P, dict[str, Any]], None] | None = None,
    evaluate: Callable[[Any], dict[str, Any]] | None = None,
    desc: str = "design points",
    security: Any = None,
) -> SweepSummary:
    """Run every point not yet in ``store`` and store each result as it finishes.

    Parameters
    ----------
    points : sequence of DesignPoint
        From :func:`expand_points`.
    store : ResultsStore
        Finished points are skipped; new results are committed one by one.
    workers : int
        Local worker processes (1 = in this process). Ignored with ``scheduler``.
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tls://HOST:PORT``, or ``tcp://`` on a trusted
        network only: tasks and results are pickles, so whoever can talk to the scheduler can run
        code on the workers and on this machine).
    security : distributed.Security, optional
        TLS certificates for ``tls://`` (see :func:`dask_security`); default: Dask's configuration.
    progress : bool, optional
        Show a tqdm progress bar on stderr: True, False, or None (default) when stderr is a terminal
        (:func:`fsdvs_hw.progress.progress_enabled`).
    on_result : callable, optional
        Called as ``on_result(point, result)`` after each result is stored.
    evaluate : callable, optional
        The work function run on each point (default :func:`evaluate_point`). Any module-level
        function (picklable for spawned workers and Dask) that takes a point with ``key``,
        ``design``, ``realisation``, ``params`` and ``label`` and returns ``{"key", "status",
        "result", "wall_s", "worker"}``; the kernel-size ablation runs its trainings this way.
    desc : str
        Label of the progress bar.
    """
    from ..progress import progress_bar

    t0 = time.perf_counter()
    done = store.done()
    todo = [p for p in points if p.key not in done]
    statuses: dict[str, int] = {}
    evaluate = evaluate or cast(Callable[[Any], dict[str, Any]], evaluate_point)  # the default runs DesignPoints
    bar = progress_bar(total=len(points), initial=len(points) - len(todo), desc=desc, unit="pt", progress=progress)

    def finish(point: _P, res: dict[str, Any]) -> None:
        _record(store, point, res)
        statuses[res["status"]] = statuses.get(res["status"], 0) + 1
        bar.set_postfix_str(f"{point.label}: {res['status']}", refresh=False)
        bar.update(1)
        if on_result is not None:
            on_result(point, res)

    try:
        if scheduler is not None:
            executor = f"Dask scheduler {scheduler}"
            _run_dask(todo, scheduler, finish, security, evaluate)
        elif workers <= 1 or len(todo) <= 1:
            executor = "this process"
            for p in todo:
                finish(p, evaluate(p))
        else:
            executor = f"{min(workers, len(todo))} local processes"
            _run_pool(todo, workers, finish, evaluate)
    finally:
        bar.close()
    return SweepSummary(
        total=len(points),
        already_done=len(points) - len(todo),
        ran=sum(statuses.values()),
        statuses=statuses,
        wall_s=time.perf_counter() - t0,
        executor=executor,
    )


def _run_pool(
    todo: Sequence[_P],
    workers: int,
    finish: Callable[[_P, dict[str, Any]], None],
    evaluate: Callable[[Any], dict[str, Any]] = evaluate_point,
) -> None:
    from concurrent.futures import as_completed

    from ..workers import process_pool

    set_env("FSDVS_HW_WORKER_THREADS", "1", default=True)
    pool = process_pool(min(workers, len(todo)))  # workers die with this process (no orphans)
    futures = {pool.submit(evaluate, p): p for p in todo}
    try:
        for fut in as_completed(futures):
            finish(futures[fut], fut.result())
    except BaseException:
        # interrupted (Ctrl-C) or a worker died: keep what is stored, do not wait for queued points
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def dask_security(
    ca_file: str | Path | None = None, cert: str | Path | None = None, key: str | Path | None = None
) -> Any:
    """A :class:`distributed.Security` for a ``tls://`` scheduler (mutual TLS, encryption required).

    Parameters
    ----------
    ca_file : path
        PEM file of the certificate authority that signed the scheduler's and workers' certificates.
    cert, key : path
        This client's PEM certificate and private key (``key`` may be omitted when ``cert`` holds both).

    Raises
    ------
    InputError
        A file is missing, or ``ca_file``/``cert`` is not given.
    """
    try:
        from distributed import Security
    except ImportError as exc:  # pragma: no cover - optional extra
        raise InputError(f"TLS needs dask[distributed] (pip install 'fsdvs_hw[distributed]'): {exc}") from None
    if ca_file is None or cert is None:
        raise InputError("--tls-ca-file and --tls-cert are both needed for a TLS connection to the scheduler")
    for flag, f in (("--tls-ca-file", ca_file), ("--tls-cert", cert), ("--tls-key", key)):
        if f is not None and not Path(f).is_file():
            raise InputError(f"{flag} {f}: file not found")
    return Security(
        tls_ca_file=str(ca_file),
        tls_client_cert=str(cert),
        tls_client_key=None if key is None else str(key),
        require_encryption=True,
    )


#: Address schemes a Dask scheduler is reached by (``inproc://`` only within one process).
SCHEDULER_SCHEMES = ("tcp", "tls", "inproc", "ucx")


def check_scheduler_address(address: str) -> str:
    """Parse a Dask scheduler address (``tls://HOST:PORT``) before anything connects to it.

    Parameters
    ----------
    address : str
        ``tcp://``, ``tls://`` or ``ucx://`` with a host and a port in 1..65535, or ``inproc://...``.

    Returns
    -------
    str
        The address, unchanged.

    Raises
    ------
    InputError
        One line naming the address and what is wrong (no scheme, unknown scheme, no host, a port
        that is not a number in 1..65535).
    """
    shown = repr(str(address)[:120])
    if not isinstance(address, str) or "://" not in address:
        raise InputError(
            f"--scheduler {shown}: expected an address like tcp://HOST:PORT or tls://HOST:PORT "
            f"(schemes: {', '.join(s + '://' for s in SCHEDULER_SCHEMES)})"
        )
    try:
        parts = urllib.parse.urlsplit(address)
        port = parts.port
    except ValueError as exc:  # a port that is not a number, or outside 0..65535
        raise InputError(f"--scheduler {shown}: bad port ({exc}); allowed: HOST:PORT with PORT in 1..65535") from None
    if parts.scheme not in SCHEDULER_SCHEMES:
        raise InputError(
            f"--scheduler {shown}: unknown scheme {parts.scheme[:20]!r}; allowed: "
            f"{', '.join(s + '://' for s in SCHEDULER_SCHEMES)}"
        )
    if parts.scheme == "inproc":
        return address
    if not parts.hostname:
        raise InputError(f"--scheduler {shown}: no host; allowed: {parts.scheme}://HOST:PORT")
    if port is None or not 1 <= port <= 65535:
        got = "no port" if port is None else f"port {port}"
        raise InputError(f"--scheduler {shown}: {got}; allowed: {parts.scheme}://HOST:PORT with PORT in 1..65535")
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        raise InputError(f"--scheduler {shown}: unexpected text after HOST:PORT; allowed: {parts.scheme}://HOST:PORT")
    return address


def _loopback(address: str) -> bool:
    host = address.split("://", 1)[-1].rsplit(":", 1)[0].strip("[]")
    return host in ("localhost", "::1") or host.startswith("127.")


def _run_dask(
    todo: Sequence[_P],
    scheduler: str,
    finish: Callable[[_P, dict[str, Any]], None],
    security: Any = None,
    evaluate: Callable[[Any], dict[str, Any]] = evaluate_point,
) -> None:
    try:
        from distributed import Client, as_completed
    except ImportError as exc:  # pragma: no cover - optional extra
        raise InputError(f"--scheduler needs dask[distributed] (pip install 'fsdvs_hw[distributed]'): {exc}") from None
    check_scheduler_address(scheduler)
    if scheduler.startswith("tcp://") and not _loopback(scheduler):
        warnings.warn(
            f"--scheduler {scheduler}: plain tcp:// is unencrypted and unauthenticated, and Dask tasks "
            "and results are pickles: anyone who can reach the scheduler can run code on the workers "
            "and on this machine. Use tls:// with --tls-ca-file/--tls-cert/--tls-key (README: "
            "'Sweeps on Dask with TLS') outside a trusted network.",
            RuntimeWarning,
            stacklevel=3,
        )
    kw = {} if security is None else {"security": security}
    try:
        client = Client(scheduler, timeout="20s", **kw)
    except (OSError, TimeoutError) as exc:
        raise InputError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler ({exc})") from None
    except (TypeError, ValueError) as exc:  # e.g. tls:// without certificates: Dask raises TypeError
        raise InputError(
            f"--scheduler {scheduler}: cannot connect ({' '.join(str(exc).split())[:200]}); "
            "tls:// needs --tls-ca-file/--tls-cert/--tls-key"
        ) from None
    try:
        futures = {client.submit(evaluate, p, key=f"fsdvs-point-{p.key}", pure=False): p for p in todo}
        for fut in as_completed(list(futures)):
            finish(futures[fut], fut.result())
    finally:
        client.close()


def run_design(
    design: Design,
    store_path: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: bool | None = None,
    retry_errors: bool = False,
    max_points: int | None = None,
    points: Sequence[DesignPoint] | None = None,
    security: Any = None,
) -> tuple[SweepSummary, list[ScoredPoint]]:
    """Run all points of ``design`` into the store at ``store_path``; return the summary and its points.

    The points are this design's only (a store may hold other designs too), in the order of
    :func:`expand_points`, each a :class:`~fsdvs_hw.records.ScoredPoint` of its stored row (with
    its per-clip evidence).
    Points stored as failed are final unless ``retry_errors``: then this design's failed points
    (and no other design's) are deleted and rerun. ``points`` (from :func:`expand_points`) saves
    building the list again; ``max_points`` overrides the design's ``[run] max_points``.
    """
    if points is None:
        points = expand_points(design, max_points=max_points)
    workers = design.spec.run.workers if workers is None else workers
    check_count("workers", workers, 1, MAX_WORKERS)
    with ResultsStore(store_path) as store:
        store.set_meta(f"design:{design.name}", design.to_dict())
        if retry_errors:
            store.forget(status="error", keys=[p.key for p in points])
        summary = run_points(points, store, workers=workers, scheduler=scheduler, progress=progress, security=security)
        order = {p.key: i for i, p in enumerate(points)}
        rows = sorted((dict(r) for r in store.rows() if r["key"] in order), key=lambda r: order[r["key"]])
    return summary, [ScoredPoint.from_dict(r) for r in rows]
