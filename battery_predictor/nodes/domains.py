"""Private ROS domains on this machine: each claimant holds a domain id no other process holds.

A replay, the demo and each ROS test run their nodes on a domain of their own, so they neither
hear nor disturb each other or a robot's graph. Picking an id at random is not enough: two
replays (or two test processes) on one machine would share a domain now and then, and a
``/clock`` or ``BatteryState`` from the other silently corrupts the answers. A claim is an
exclusive ``flock`` on one lock file per id in the machine's temporary directory; the
operating system drops it when the process ends, so a crashed claimant never blocks an id.
"""

from __future__ import annotations

import fcntl
import os
import random
import tempfile
from dataclasses import dataclass
from pathlib import Path

from battery_predictor.errors import BatteryPredictorError

#: Domain ids handed out (Fast DDS maps 0..232 to UDP ports; 0, the default, and low ids stay free).
PRIVATE_DOMAIN_IDS = range(100, 230)


def lock_dir() -> Path:
    """The directory of the per-domain lock files (shared by every user of this machine)."""
    path = Path(tempfile.gettempdir()) / "battery_predictor-ros-domains"
    path.mkdir(mode=0o777, exist_ok=True)
    return path


@dataclass(frozen=True)
class DomainClaim:
    """An exclusive claim on ``domain_id`` held through the open lock file ``fd``."""

    domain_id: int
    fd: int

    def release(self) -> None:
        """Give the domain back (closing the lock file drops the lock)."""
        try:
            os.close(self.fd)
        except OSError:
            pass


def _try_claim(domain_id: int, directory: Path) -> DomainClaim | None:
    fd = os.open(directory / f"{domain_id}.lock", os.O_CREAT | os.O_RDWR, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        return None
    return DomainClaim(domain_id, fd)


def claim_private_domain(rng: random.Random | None = None) -> DomainClaim:
    """Claim a ROS domain id no other claimant on this machine holds.

    Parameters
    ----------
    rng : random.Random, optional
        Order in which free ids are tried (default: a fresh, unseeded generator).

    Returns
    -------
    DomainClaim
        Held until :meth:`DomainClaim.release` or the end of the process.

    Raises
    ------
    BatteryPredictorError
        When every id of :data:`PRIVATE_DOMAIN_IDS` is held.
    """
    ids = list(PRIVATE_DOMAIN_IDS)
    (rng or random.Random()).shuffle(ids)
    directory = lock_dir()
    for domain_id in ids:
        claim = _try_claim(domain_id, directory)
        if claim is not None:
            return claim
    raise BatteryPredictorError(
        f"all {len(ids)} private ROS domains ({ids and min(ids)}-{ids and max(ids)}) on this machine are in use "
        f"(lock files in {directory}); wait for other replays or tests to end, or pass --shared-domain")
