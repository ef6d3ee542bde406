#!/usr/bin/env python3
"""Run one step of ``make setup`` with its output in a log: one line on the terminal, a bar while it runs.

Usage::

    python3 tools/setup_step.py LOG "what it does" [--total N] -- COMMAND [ARG...]

The command's stdout and stderr are appended to LOG. The terminal gets ``setup: what it does ... ok (12 s)``;
on an interactive terminal a bar counts the packages pip reports (``Collecting X`` or ``Requirement
already satisfied: X``) against ``--total`` while the step runs, shown after 2 s. When the command fails,
the last lines of the log are printed and its exit code is returned. Standard library only: it runs
before anything is installed.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

#: pip lines that name one package of the resolved set.
PACKAGE_LINE = re.compile(r"^(?:Collecting|Requirement already satisfied:)\s+([A-Za-z0-9_.\-]+)")
#: The bar appears only once the step has lasted this long, s.
BAR_DELAY_S = 2.0
#: Log lines shown when a step fails.
TAIL_LINES = 40
BAR_WIDTH = 30


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("log", type=Path)
    parser.add_argument("what")
    parser.add_argument("--total", type=int, default=0, help="packages expected (0: no bar, elapsed time only)")
    if "--" not in argv or argv.index("--") == len(argv) - 1:
        parser.error("give the command after --")
    split = argv.index("--")
    args = parser.parse_args(argv[:split])
    args.command = argv[split + 1:]
    return args


class _Status:
    """Packages seen so far and the phase, fed from the command's output lines."""

    def __init__(self) -> None:
        self.packages: set[str] = set()
        self.phase = ""
        self.lock = threading.Lock()

    def feed(self, line: str) -> None:
        match = PACKAGE_LINE.match(line)
        with self.lock:
            if match:
                self.packages.add(match.group(1).lower())
            elif line.startswith("Installing collected packages"):
                self.phase = "installing"
            elif line.startswith("Building wheel"):
                self.phase = "building wheels"


def _bar(status: _Status, total: int, elapsed_s: float) -> str:
    with status.lock:
        done, phase = len(status.packages), status.phase
    if total <= 0:
        return f"{elapsed_s:4.0f} s {phase}"
    done = min(done, total)
    filled = round(BAR_WIDTH * done / total)
    return f"[{'#' * filled}{'.' * (BAR_WIDTH - filled)}] {done}/{total} packages {elapsed_s:4.0f} s {phase}"


def _draw(prefix: str, status: _Status, total: int, start: float, stop: threading.Event) -> None:
    shown = False
    while not stop.wait(0.5):
        elapsed = time.monotonic() - start
        if elapsed < BAR_DELAY_S:
            continue
        sys.stdout.write(f"\r{prefix}{_bar(status, total, elapsed)}\033[K")
        sys.stdout.flush()
        shown = True
    if shown:
        sys.stdout.write(f"\r{prefix}\033[K")


def run_step(log: Path, what: str, command: list[str], total: int = 0) -> int:
    """Run ``command`` with its output appended to ``log``; returns its exit code."""
    prefix = f"setup: {what} ... "
    sys.stdout.write(prefix)
    sys.stdout.flush()
    status, stop, start = _Status(), threading.Event(), time.monotonic()
    drawer = None
    if sys.stdout.isatty():
        drawer = threading.Thread(target=_draw, args=(prefix, status, total, start, stop), daemon=True)
        drawer.start()
    log.parent.mkdir(parents=True, exist_ok=True)
    with log.open("a", encoding="utf-8") as sink:
        sink.write(f"$ {' '.join(command)}\n")
        sink.flush()
        proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                errors="replace")
        assert proc.stdout is not None
        for line in proc.stdout:
            sink.write(line)
            status.feed(line)
        code = proc.wait()
    stop.set()
    if drawer is not None:
        drawer.join()
    seconds = time.monotonic() - start
    if code == 0:
        print(f"ok ({seconds:.0f} s)")
        return 0
    print(f"failed (exit code {code}); last lines of {log}:")
    lines = log.read_text(encoding="utf-8", errors="replace").splitlines()
    print("\n".join("  " + ln for ln in lines[-TAIL_LINES:]))
    return code


def main(argv: list[str] | None = None) -> int:
    args = _parse(sys.argv[1:] if argv is None else argv)
    return run_step(args.log, args.what, args.command, args.total)


if __name__ == "__main__":
    sys.exit(main())
