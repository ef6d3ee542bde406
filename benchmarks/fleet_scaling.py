"""Fleet benchmark (issue 14, item 4): time and memory per pack as packs are added, one shared storage.

Fits N packs (default 20) one after the other in one worker through
:func:`battery_predictor.fitting.fleet.fit_fleet`, the code of ``battery-predictor fleet fit``, one
Optuna study per pack in one storage: a PostgreSQL server started for the run
(:class:`~battery_predictor.fitting.local_postgres.LocalPostgres`) where the server binaries are
installed, else a SQLite file (``--storage`` for any URL). The packs are 30-minute windows of the
four bundled temi recordings (20 distinct recordings), fitted on the SPM engine. Prints a line per
pack (seconds, resident memory after it, trials in the storage so far) and the trend: mean seconds
of the first and the last five packs, and the slope of resident memory from pack 2 on and over the second half (MB per pack).

Usage: .venv/bin/python benchmarks/fleet_scaling.py [--packs 20] [--trials 30] [--storage URL|sqlite]
       [--json OUT.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from battery_predictor.fitting.fleet import fit_fleet  # noqa: E402
from battery_predictor.fitting.local_postgres import LocalPostgres, server_binaries  # noqa: E402
from battery_predictor.fitting.storage import redacted  # noqa: E402
from battery_predictor.io.bags import read_recording_bag  # noqa: E402
from battery_predictor.params import load_params  # noqa: E402
from battery_predictor.processes import resident_mb  # noqa: E402
from battery_predictor.recording import Recording  # noqa: E402
from battery_predictor.simulation.engine import EngineSimulator  # noqa: E402

WINDOW_S = 1800.0


def pack_windows(n: int, reverse: bool = False) -> dict[str, list[str]]:
    """Pack name -> ["<bag>@<start s>"]: 30-minute windows of the bundled temi recordings."""
    packs = {f"pack{k + 1:02d}": [f"temi_dynamic_pack{k % 4 + 1}@{(k // 4) * WINDOW_S:.0f}"] for k in range(n)}
    return dict(reversed(packs.items())) if reverse else packs


def load_window(specs) -> list[Recording]:
    out = []
    for spec in specs:
        bag, start = spec.split("@")
        rec = read_recording_bag(REPO / "bags" / bag)
        t0 = float(start)
        keep = (rec.time_s >= t0) & (rec.time_s < t0 + WINDOW_S)
        out.append(Recording(time_s=rec.time_s[keep] - t0, voltage_v=rec.voltage_v[keep], current_a=rec.current_a[keep],
                             temperature_k=None, source=spec))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--packs", type=int, default=20)
    ap.add_argument("--trials", type=int, default=30, help="trials per pack (default 30)")
    ap.add_argument("--parameters", nargs="+", default=["r_c_ohm", "Electrode height [m]"])
    ap.add_argument("--storage", default=None, help="Optuna URL, or 'sqlite' (default: local PostgreSQL if installed)")
    ap.add_argument("--reverse", action="store_true", help="fit the packs in reverse order (data vs position)")
    ap.add_argument("--json", default=None, help="write the figures here")
    args = ap.parse_args(argv)
    server = None
    with tempfile.TemporaryDirectory(prefix="bp-fleet-bench-") as tmp:
        if args.storage in (None, "postgres") and server_binaries() is not None:
            server = LocalPostgres()
            storage = server.start()
        elif args.storage in (None, "sqlite", "postgres"):
            storage = f"sqlite:///{tmp}/fleet.optuna.db"
        else:
            storage = args.storage
        try:
            params = load_params(REPO / "params" / "temi.yaml")
            rows = []
            start_mb = resident_mb()
            total = 0

            def on_pack(fit) -> None:
                nonlocal total
                total += fit.trials
                rows.append(fit)
                print(f"{fit.pack}: {fit.seconds:6.2f} s ({fit.cpu_seconds:5.2f} s CPU)  {fit.rss_mb:7.1f} MB  R2_mod {fit.r2_mod:.4f}  "
                      f"{total} trials in the storage", flush=True)

            tic = time.perf_counter()
            fit_fleet(params, pack_windows(args.packs, args.reverse), load_window, storage=storage, out_dir=Path(tmp) / "fits",
                      trials=args.trials, seed=0, simulator=EngineSimulator(), parameters=args.parameters,
                      study_prefix="bench-", on_pack=on_pack)
            wall = time.perf_counter() - tic
        finally:
            if server is not None:
                server.stop()
    seconds = np.array([r.seconds for r in rows])
    cpu = np.array([r.cpu_seconds for r in rows])
    rss = np.array([r.rss_mb for r in rows])
    k = min(5, len(rows) // 2)
    slope = float(np.polyfit(np.arange(1, len(rows)), rss[1:], 1)[0]) if len(rows) > 2 else float("nan")
    half = len(rows) // 2
    slope_half = float(np.polyfit(np.arange(half, len(rows)), rss[half:], 1)[0]) if len(rows) > 3 else float("nan")
    summary = {
        "storage": redacted(storage).split("@")[0] + ("@local-postgres" if server is not None else ""),
        "packs": len(rows), "trials_per_pack": args.trials, "parameters": args.parameters,
        "wall_s": wall, "rss_mb_before": start_mb,
        "first_pack_s": float(seconds[0]),
        "mean_s_packs_2_to_6": float(seconds[1:k + 1].mean()), "mean_s_last_5": float(seconds[-k:].mean()),
        "mean_cpu_s_packs_2_to_6": float(cpu[1:k + 1].mean()), "mean_cpu_s_last_5": float(cpu[-k:].mean()),
        "order": "reverse" if args.reverse else "forward",
        "rss_mb_after_pack_1": float(rss[0]), "rss_mb_after_last": float(rss[-1]),
        "rss_mb_per_pack_slope_from_pack_2": slope, "rss_mb_per_pack_slope_second_half": slope_half,
        "per_pack": [{"pack": r.pack, "seconds": r.seconds, "cpu_seconds": r.cpu_seconds, "rss_mb": r.rss_mb,
                      "r2_mod": r.r2_mod} for r in rows],
    }
    print(f"\n{len(rows)} packs x {args.trials} trials on {summary['storage']}: {wall:.0f} s; per pack: first "
          f"{seconds[0]:.2f} s (engine built), packs 2-{k + 1} {summary['mean_s_packs_2_to_6']:.2f} s, last {k} "
          f"{summary['mean_s_last_5']:.2f} s (CPU {summary['mean_cpu_s_packs_2_to_6']:.2f} s and "
          f"{summary['mean_cpu_s_last_5']:.2f} s); RSS {rss[0]:.0f} MB after pack 1, {rss[-1]:.0f} MB after pack "
          f"{len(rows)} (slope {slope:+.2f} MB/pack from pack 2, {slope_half:+.2f} MB/pack over the second half)")
    if args.json:
        Path(args.json).write_text(json.dumps(summary, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
