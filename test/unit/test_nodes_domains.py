"""Private ROS domains: a domain id held by one claimant (any process) is never handed to another."""

from __future__ import annotations

import random
import subprocess
import sys
import textwrap

import pytest

from battery_predictor.errors import BatteryPredictorError
from battery_predictor.nodes import domains


@pytest.fixture
def few_ids(monkeypatch: pytest.MonkeyPatch, tmp_path) -> range:
    """Three ids with lock files in a directory of this test's own."""
    monkeypatch.setattr(domains, "lock_dir", lambda: tmp_path)
    monkeypatch.setattr(domains, "PRIVATE_DOMAIN_IDS", range(200, 203))
    return domains.PRIVATE_DOMAIN_IDS


def test_claims_in_one_process_get_distinct_ids_until_none_is_left(few_ids: range) -> None:
    claims = [domains.claim_private_domain(random.Random(0)) for _ in few_ids]
    assert sorted(c.domain_id for c in claims) == list(few_ids)
    with pytest.raises(BatteryPredictorError, match="all 3 private ROS domains"):
        domains.claim_private_domain()
    claims[1].release()
    assert domains.claim_private_domain().domain_id == claims[1].domain_id
    for claim in claims:
        claim.release()


def test_an_id_held_by_another_process_is_not_handed_out(few_ids: range, tmp_path) -> None:
    holder = textwrap.dedent(f"""
        import fcntl, os, sys
        fds = [os.open("{tmp_path}/%d.lock" % i, os.O_CREAT | os.O_RDWR) for i in (200, 202)]
        for fd in fds:
            fcntl.flock(fd, fcntl.LOCK_EX)
        print("held", flush=True)
        sys.stdin.read()
    """)
    with subprocess.Popen([sys.executable, "-c", holder], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                          text=True) as proc:
        assert proc.stdout.readline().strip() == "held"
        mine = domains.claim_private_domain(random.Random(0))
        assert mine.domain_id == 201
        with pytest.raises(BatteryPredictorError):
            domains.claim_private_domain()
        proc.stdin.close()
        proc.wait(timeout=30)
    # the holder ended: the operating system dropped its locks
    after = domains.claim_private_domain()
    assert after.domain_id in (200, 202)
    mine.release()
    after.release()
