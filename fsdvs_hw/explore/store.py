"""Embedded results store: one SQLite row per finished design point.

The sweep coordinator writes each point's result the moment it arrives, in its own transaction,
so a run killed part-way keeps everything already finished; a rerun asks :meth:`ResultsStore.done`
for the finished keys and skips them. The key is a content hash of everything that decides the
result (:attr:`fsdvs_hw.explore.sweep.DesignPoint.key`), and it is the table's primary key, so a
point can never be stored twice: a duplicate insert is refused and reported.

SQLite (Python's built-in ``sqlite3``) is used in WAL mode with ``synchronous=FULL``: a committed
row survives a killed process or a power cut. Only the coordinator writes; workers (local
processes or Dask workers on other machines) return results to it.
"""

from __future__ import annotations

import contextlib
import json
import socket
import sqlite3
import time
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..paths import output_file

__all__ = ["ResultsStore", "StoredPoint"]

_SCHEMA_VERSION = 1
_COLUMNS = ["key", "design", "realisation", "params", "status", "result", "wall_s", "finished_at", "host", "worker"]

_DDL = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS points (
    key         TEXT PRIMARY KEY,
    design      TEXT NOT NULL,
    realisation TEXT NOT NULL,
    params      TEXT NOT NULL,
    status      TEXT NOT NULL,
    result      TEXT NOT NULL,
    wall_s      REAL NOT NULL,
    finished_at REAL NOT NULL,
    host        TEXT NOT NULL,
    worker      TEXT NOT NULL
);
"""


class StoredPoint(dict):
    """One stored row as a dict (``key, design, realisation, params, status, result, wall_s, ...``)."""


class ResultsStore:
    """A SQLite file holding one row per finished design point.

    Parameters
    ----------
    path : str or Path
        The database file (created with its folder if missing).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> with ResultsStore(pathlib.Path(tempfile.mkdtemp()) / "r.sqlite") as store:
    ...     store.add("k1", design="d", realisation="asic", params={"bits": 4}, status="ok",
    ...               result={"kernel_error": 0.1}, wall_s=0.5)
    ...     sorted(store.done())
    True
    ['k1']
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        output_file(self.path, flag="results store")
        try:
            self._db = sqlite3.connect(self.path, timeout=30.0, isolation_level=None)
        except sqlite3.Error as exc:
            raise InputError(f"{self.path}: cannot open the results store ({exc})") from None
        try:
            # look before touching: another application's database is refused unchanged
            tables = {r[0] for r in self._db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
            foreign = sorted(tables - {"meta", "points"})
            if foreign:
                raise InputError(
                    f"{self.path}: a SQLite database with other tables ({', '.join(foreign[:5])}), "
                    "not an fsdvs_hw results store; left unchanged (use a new --store file)"
                )
            for table, expected in (("points", _COLUMNS), ("meta", ["key", "value"])):
                if table in tables:
                    cols = [r[1] for r in self._db.execute(f"PRAGMA table_info({table})")]
                    if cols != expected:
                        raise InputError(
                            f"{self.path}: has a {table!r} table of another layout; not an fsdvs_hw "
                            "results store (use a new --store file)"
                        )
            if tables:  # an existing store: a damaged page would otherwise surface mid-run or be skipped
                check = [r[0] for r in self._db.execute("PRAGMA quick_check(3)")]
                if check != ["ok"]:
                    raise InputError(
                        f"{self.path}: the results store is damaged (SQLite quick_check: "
                        f"{' '.join('; '.join(str(c) for c in check).split())[:200]}); use a new --store file or "
                        "restore a copy"
                    )
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=FULL")
            self._db.executescript(_DDL)
            row = self._db.execute("SELECT value FROM meta WHERE key='schema_version'").fetchone()
            if row is None:
                self._db.execute("INSERT INTO meta VALUES ('schema_version', ?)", (str(_SCHEMA_VERSION),))
            elif str(row[0]) != str(_SCHEMA_VERSION):
                raise InputError(
                    f"{self.path}: results store schema version {str(row[0])[:20]!r}, this fsdvs_hw "
                    f"writes {_SCHEMA_VERSION}; use a new --store file"
                )
        except sqlite3.Error as exc:
            self._db.close()
            # sqlite's message ("file is not a database") never quotes the file's content
            raise InputError(f"{self.path}: not a usable results store ({exc})") from None
        except InputError:
            self._db.close()
            raise

    # ------------------------------------------------------------------ writing
    def add(
        self,
        key: str,
        *,
        design: str,
        realisation: str,
        params: Mapping[str, Any],
        status: str,
        result: Mapping[str, Any],
        wall_s: float,
        worker: str = "",
    ) -> bool:
        """Store one finished point in its own committed transaction.

        A point stored as ``"skipped"`` (its realisation was not installed) is replaced by a later
        result; any other stored point is final.

        Returns
        -------
        bool
            True if stored, False if ``key`` was already final (the earlier row is kept).
        """
        cur = self._db.execute(
            "INSERT INTO points VALUES (?,?,?,?,?,?,?,?,?,?) ON CONFLICT(key) DO UPDATE SET "
            "status=excluded.status, result=excluded.result, wall_s=excluded.wall_s, "
            "finished_at=excluded.finished_at, host=excluded.host, worker=excluded.worker "
            "WHERE points.status = 'skipped'",
            (
                key,
                design,
                realisation,
                json.dumps(dict(params), sort_keys=True, default=_json_default),
                status,
                json.dumps(dict(result), default=_json_default),
                float(wall_s),
                time.time(),
                socket.gethostname(),
                worker,
            ),
        )
        return cur.rowcount == 1

    def set_meta(self, key: str, value: Any) -> None:
        """Store a JSON value under ``key`` in the metadata table (replacing it)."""
        self._db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (key, json.dumps(value, default=_json_default)))

    def get_meta(self, key: str, default: Any = None) -> Any:
        row = self._db.execute("SELECT value FROM meta WHERE key=?", (key,)).fetchone()
        if row is None:
            return default
        try:
            return json.loads(row[0])
        except (TypeError, json.JSONDecodeError, RecursionError):
            raise InputError(f"{self.path}: metadata {key[:40]!r} is corrupt (not JSON)") from None

    # ------------------------------------------------------------------ reading
    def done(self) -> set[str]:
        """Keys of finished points (every status except ``"skipped"``, which a rerun retries)."""
        return {r[0] for r in self._db.execute("SELECT key FROM points WHERE status != 'skipped'")}

    def forget(self, *, status: str, keys: Iterable[str]) -> int:
        """Delete the points among ``keys`` stored with ``status`` (``"error"`` to retry failures).

        Only the given keys are touched (a store may hold other designs' points, which are never
        deleted). Returns how many rows were deleted.
        """
        n = 0
        with self._transaction():
            for key in keys:
                n += self._db.execute("DELETE FROM points WHERE status=? AND key=?", (status, key)).rowcount
        return n

    @contextlib.contextmanager
    def _transaction(self) -> Iterator[None]:
        self._db.execute("BEGIN IMMEDIATE")
        try:
            yield
        except BaseException:
            self._db.execute("ROLLBACK")
            raise
        self._db.execute("COMMIT")

    def __len__(self) -> int:
        return int(self._db.execute("SELECT COUNT(*) FROM points").fetchone()[0])

    def __contains__(self, key: object) -> bool:
        return self._db.execute("SELECT 1 FROM points WHERE key=?", (key,)).fetchone() is not None

    def rows(self, *, design: str | None = None) -> Iterator[StoredPoint]:
        """All stored points in finishing order, with ``params`` and ``result`` decoded."""
        q = "SELECT key, design, realisation, params, status, result, wall_s, finished_at, host, worker FROM points"
        args: tuple[Any, ...] = ()
        if design is not None:
            q += " WHERE design=?"
            args = (design,)
        for r in self._db.execute(q + " ORDER BY finished_at, rowid", args):
            try:
                params, result = json.loads(r[3]), json.loads(r[5])
            except (TypeError, json.JSONDecodeError, RecursionError):
                raise InputError(
                    f"{self.path}: stored point {str(r[0])[:40]!r} is corrupt (params/result not JSON); "
                    "delete that row or use a new --store file"
                ) from None
            yield StoredPoint(
                key=r[0],
                design=r[1],
                realisation=r[2],
                params=params,
                status=r[4],
                result=result,
                wall_s=r[6],
                finished_at=r[7],
                host=r[8],
                worker=r[9],
            )

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        self._db.close()

    def __enter__(self) -> ResultsStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _json_default(obj: Any) -> Any:
    """Make numpy scalars/arrays and paths JSON-serialisable."""
    if hasattr(obj, "tolist"):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__}")
