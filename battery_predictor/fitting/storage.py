"""Optuna storages shared by fits: SQLite files for one machine, PostgreSQL for a fleet.

A storage URL is anything Optuna's :class:`~optuna.storages.RDBStorage` takes
(``sqlite:///fit.optuna.db``, ``postgresql://user@host:5432/db``); ``postgresql://`` goes through
SQLAlchemy's default driver psycopg (``requirements.txt``). Several processes on several machines
can work on one study, each with its own sampler seed; :func:`open_storage` opens one storage
object per run and :func:`close_storage` gives its connections back, so a process that fits many
packs one after the other holds one connection pool at a time.
"""

from __future__ import annotations

import os
import socket
import time
from typing import TYPE_CHECKING, Any, overload

from battery_predictor.errors import BatteryPredictorError

if TYPE_CHECKING:
    import optuna

#: Attempts to open a storage: two processes creating the tables of a new database at once can
#: collide (PostgreSQL: duplicate key in pg_type); the loser retries after a short pause.
OPEN_ATTEMPTS = 4
#: Pause between attempts, s (doubled each time).
OPEN_PAUSE_S = 0.5


def redacted(url: str) -> str:
    """``url`` without its password (for messages and provenance)."""
    if "://" not in url or "@" not in url:
        return url
    scheme, rest = url.split("://", 1)
    credentials, host = rest.rsplit("@", 1)
    user = credentials.split(":", 1)[0]
    return f"{scheme}://{user}{':***' if ':' in credentials else ''}@{host}"


@overload
def open_storage(url: str) -> optuna.storages.RDBStorage: ...
@overload
def open_storage(url: None) -> None: ...
def open_storage(url: str | None) -> optuna.storages.RDBStorage | None:
    """The Optuna storage for ``url`` (None: in memory).

    Parameters
    ----------
    url : str or None
        Optuna RDB storage URL.

    Returns
    -------
    optuna.storages.BaseStorage or None
        An :class:`~optuna.storages.RDBStorage` (connections checked before use), or None for None.

    Raises
    ------
    BatteryPredictorError
        One line naming the (redacted) URL when the storage cannot be opened: bad scheme, missing
        driver, server unreachable, wrong credentials.
    """
    if url is None:
        return None
    import optuna

    if url.startswith(("postgresql", "postgres")):
        try:
            import psycopg  # noqa: F401 - SQLAlchemy's default PostgreSQL driver
        except ImportError:
            raise BatteryPredictorError(f"storage {redacted(url)}: PostgreSQL needs the psycopg package "
                                        "(pip install -r requirements.txt)") from None
    kwargs: dict[str, Any] = {"pool_pre_ping": True}
    if url.startswith("sqlite"):
        kwargs = {"connect_args": {"timeout": 60}}  # several processes on one file wait for its lock
    pause = OPEN_PAUSE_S
    for attempt in range(OPEN_ATTEMPTS):
        try:
            return optuna.storages.RDBStorage(url, engine_kwargs=kwargs)
        except Exception as exc:  # noqa: BLE001 - SQLAlchemy / driver errors of every kind
            message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            retry = "already exists" in str(exc) or "duplicate key" in str(exc)
            if not retry or attempt == OPEN_ATTEMPTS - 1:
                raise BatteryPredictorError(f"cannot open Optuna storage {redacted(url)}: {message}") from None
            time.sleep(pause)
            pause *= 2
    raise AssertionError("unreachable")


def close_storage(storage: optuna.storages.BaseStorage | None) -> None:
    """Give the storage's database connections back (no-op for None or in-memory storages)."""
    engine = getattr(storage, "engine", None)
    if engine is not None:
        engine.dispose()


def worker_id() -> str:
    """``host:pid`` of this process, stored with each trial it runs."""
    return f"{socket.gethostname()}:{os.getpid()}"
