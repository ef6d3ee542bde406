"""``tools/setup_step.py``: a ``make setup`` step prints one line, keeps its output in the log, shows it on failure."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
STEP = str(REPO / "tools" / "setup_step.py")
NOISY = "import sys; print('Collecting numpy==2.0'); print('BuildBackendWarning: noise', file=sys.stderr)"


def _step(log: Path, code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, STEP, str(log), "doing it", "--total", "3", "--", sys.executable, "-c",
                           code], capture_output=True, text=True, timeout=60)


def test_successful_step_prints_one_line_and_logs_the_noise(tmp_path):
    log = tmp_path / "setup.log"
    proc = _step(log, NOISY)
    assert proc.returncode == 0
    assert proc.stdout.splitlines() == [proc.stdout.strip()]
    assert proc.stdout.startswith("setup: doing it ... ok (")
    assert "noise" not in proc.stdout + proc.stderr
    assert "BuildBackendWarning: noise" in log.read_text()


def test_failing_step_returns_its_exit_code_and_shows_the_log_tail(tmp_path):
    proc = _step(tmp_path / "setup.log", NOISY + "; sys.exit(3)")
    assert proc.returncode == 3
    assert "failed (exit code 3)" in proc.stdout
    assert "BuildBackendWarning: noise" in proc.stdout
