"""A throwaway PostgreSQL server on a local port, for trying fleets, their test and their benchmark.

Uses the server binaries of Debian's ``postgresql`` package (``initdb``, ``pg_ctl``, on ``PATH`` or
in ``/usr/lib/postgresql/<version>/bin``). The cluster lives in a new temporary directory, listens
on 127.0.0.1 only with trust authentication, and is removed on exit. PostgreSQL refuses to run as
root, so a root process runs it as the package's ``postgres`` system user (else ``nobody``).
"""

from __future__ import annotations

import glob
import os
import shutil
import socket
import subprocess
import tempfile
from pathlib import Path

from battery_predictor.errors import BatteryPredictorError


def server_binaries() -> tuple[str, str] | None:
    """(initdb, pg_ctl) from ``PATH`` or Debian's ``/usr/lib/postgresql/<version>/bin`` (newest), or None."""
    for bindir in [None, *sorted(glob.glob("/usr/lib/postgresql/*/bin"), reverse=True)]:
        initdb = shutil.which("initdb", path=bindir)
        pg_ctl = shutil.which("pg_ctl", path=bindir)
        if initdb and pg_ctl:
            return initdb, pg_ctl
    return None


def free_port() -> int:
    """A TCP port free on 127.0.0.1 at the time of the call."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class LocalPostgres:
    """``with LocalPostgres() as url:`` a server for the duration of the block.

    Parameters
    ----------
    user : str
        Database user created by ``initdb`` (the URL's user).
    max_connections : int
        The server's connection limit.
    """

    def __init__(self, user: str = "fleet", max_connections: int = 40) -> None:
        binaries = server_binaries()
        if binaries is None:
            raise BatteryPredictorError("PostgreSQL server binaries (initdb, pg_ctl) not found: "
                                        "apt-get install postgresql")
        self.initdb, self.pg_ctl = binaries
        self.user = user
        self.max_connections = int(max_connections)
        self.base: Path | None = None
        self.url: str | None = None
        self._as: dict = {}

    def start(self) -> str:
        """Start the server; returns its URL (``postgresql://<user>@127.0.0.1:<port>/postgres``)."""
        self.base = Path(tempfile.mkdtemp(prefix="bp-postgres-"))
        if os.geteuid() == 0:  # the server refuses root
            import pwd

            try:
                account = pwd.getpwnam("postgres")
            except KeyError:
                account = pwd.getpwnam("nobody")
            self._as = {"user": account.pw_uid, "group": account.pw_gid, "extra_groups": []}
            os.chown(self.base, account.pw_uid, account.pw_gid)
        data, port, log = self.base / "data", free_port(), self.base / "server.log"
        try:
            subprocess.run([self.initdb, "-D", str(data), "-U", self.user, "--auth=trust", "-E", "UTF8", "--no-sync"],
                           check=True, capture_output=True, text=True, timeout=120, **self._as)
            with open(data / "postgresql.conf", "a") as conf:
                conf.write(f"\nport = {port}\nlisten_addresses = '127.0.0.1'\nunix_socket_directories = '{self.base}'\n"
                           f"fsync = off\nsynchronous_commit = off\nmax_connections = {self.max_connections}\n")
            subprocess.run([self.pg_ctl, "-D", str(data), "-l", str(log), "-w", "-t", "60", "start"],
                           check=True, capture_output=True, text=True, timeout=120, **self._as)
        except (subprocess.CalledProcessError, subprocess.TimeoutExpired, OSError) as exc:
            detail = getattr(exc, "stderr", "") or str(exc)
            server_log = log.read_text()[-1500:] if log.exists() else ""
            self.stop()
            raise BatteryPredictorError(f"could not start PostgreSQL: {str(detail)[-1500:]} {server_log}") from None
        self.url = f"postgresql://{self.user}@127.0.0.1:{port}/postgres"
        return self.url

    def stop(self) -> None:
        """Stop the server and remove its directory."""
        if self.base is None:
            return
        data = self.base / "data"
        if (data / "postmaster.pid").exists():
            subprocess.run([self.pg_ctl, "-D", str(data), "-m", "fast", "-w", "stop"], capture_output=True,
                           timeout=120, **self._as)
        shutil.rmtree(self.base, ignore_errors=True)
        self.base = self.url = None

    def __enter__(self) -> str:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
