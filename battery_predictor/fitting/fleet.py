"""Fits for a fleet of packs of one design, sharing one Optuna storage.

Each pack gets its own study (``<prefix><pack>``) in the same storage, so any number of worker
processes, on any number of machines, can run the same fleet: every worker goes through the packs
in order and works on each pack's study until it holds the requested trials; the first worker to
reach a pack enqueues its start (the params' values) as trial 0, the others join, each with its own
sampler seed. A worker holds one pack's recordings, problem and storage connection at a time, so
its memory and its time per pack do not grow with the number of packs
(``benchmarks/fleet_scaling.py``, ``docs/fleets.md``).
"""

from __future__ import annotations

import datetime as _dt
import math
import re
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from battery_predictor.errors import InputDataError
from battery_predictor.fitting.optimiser import TPEOptimiser
from battery_predictor.fitting.problem import FitProblem
from battery_predictor.fitting.space import fit_space
from battery_predictor.params import PackParams
from battery_predictor.processes import resident_mb
from battery_predictor.simulation.base import PackSimulator

#: Pack names become file and study names.
PACK_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")


@dataclass(frozen=True)
class PackFit:
    """One pack's fit in a fleet.

    Attributes
    ----------
    pack : str
        Pack name.
    out : pathlib.Path
        The fitted params YAML.
    r2_mod : float
        R2_mod of the study's best trial (paper Eq. 1-3).
    trials, resumed_trials : int
        Finished trials in the study at the end; those it held when this worker came to it.
    own_trials : int
        Trials this worker ran.
    improved : bool
        False when no trial beat the start.
    seconds : float
        Wall time of this pack in this worker, s.
    cpu_seconds : float
        CPU time of this worker process on this pack, s (not counting other processes' load).
    rss_mb : float
        Resident memory of this worker after the pack, MB (NaN without /proc).
    study_name : str
        The pack's study.
    """

    pack: str
    out: Path
    r2_mod: float
    trials: int
    resumed_trials: int
    own_trials: int
    improved: bool
    seconds: float
    cpu_seconds: float
    rss_mb: float
    study_name: str

    def to_dict(self) -> dict:
        """JSON-ready fields."""
        return {"pack": self.pack, "out": str(self.out), "r2_mod": self.r2_mod, "trials": self.trials,
                "resumed_trials": self.resumed_trials, "own_trials": self.own_trials, "improved": self.improved,
                "seconds": self.seconds, "cpu_seconds": self.cpu_seconds, "rss_mb": self.rss_mb if math.isfinite(self.rss_mb) else None,
                "study": self.study_name}


def parse_packs(data: Sequence[str] = (), packs: Sequence[str] = ()) -> dict[str, list[str]]:
    """Pack names and their files from ``--data FILE...`` (one pack each, named by the file's stem)
    and ``--pack NAME=FILE[,FILE...]``.

    Raises
    ------
    InputDataError
        A name that is not a file/study name, a name given twice, or no pack at all.
    """
    out: dict[str, list[str]] = {}

    def add(name: str, files: list[str], origin: str) -> None:
        if not PACK_NAME.match(name):
            raise InputDataError(f"{origin}: pack name {name!r} must be 1-64 letters, digits, '_', '.' or '-'")
        if name in out:
            raise InputDataError(f"{origin}: pack {name!r} is given twice (name packs with --pack NAME=FILE)")
        if not files or not all(files):
            raise InputDataError(f"{origin}: pack {name!r} has no data file")
        out[name] = files

    for path in data:
        add(Path(path).name.split(".")[0], [path], f"--data {path}")
    for spec in packs:
        name, sep, files = spec.partition("=")
        if not sep:
            raise InputDataError(f"--pack {spec}: expected NAME=FILE[,FILE...]")
        add(name, files.split(","), f"--pack {spec}")
    if not out:
        raise InputDataError("no packs: give --data FILE... (one pack per file) or --pack NAME=FILE[,FILE...]")
    return out


def fit_fleet(params: PackParams, packs: Mapping[str, Sequence[str]], load: Callable[[Sequence[str]], list], *,
              storage: str | None, out_dir: Path, trials: int, seed: int = 0, simulator: PackSimulator | None = None,
              parameters: Sequence[str] | None = None, study_prefix: str | None = None,
              on_pack: Callable[[PackFit], None] | None = None) -> list[PackFit]:
    """Fit every pack (one study each in ``storage``) and write ``out_dir/<pack>.yaml``.

    Parameters
    ----------
    params : PackParams
        The design every pack starts from.
    packs : mapping
        Pack name -> its data files.
    load : callable
        Files -> recordings (validated against the pack), called for one pack at a time.
    storage : str or None
        Optuna storage URL shared by the workers (None: in memory, this worker only).
    out_dir : pathlib.Path
        Where the fitted params go.
    trials : int
        Trials per pack's study (all workers together).
    seed : int
        This worker's sampler seed (give every worker its own).
    simulator : Simulator, optional
        Shared by the packs (its caches are bounded).
    parameters : sequence of str, optional
        Fit these instead of the params' ``fit.parameters``.
    study_prefix : str, optional
        Study names are ``<prefix><pack>`` (default ``"<params name>-fleet-"``).
    on_pack : callable, optional
        Called with each :class:`PackFit` as it is done.
    """
    if simulator is None:
        from battery_predictor.simulation import get_simulator

        simulator = get_simulator("fast")
    prefix = f"{params.name}-fleet-" if study_prefix is None else study_prefix
    space = fit_space(params, tuple(parameters) if parameters else None)
    out_dir.mkdir(parents=True, exist_ok=True)
    results = []
    for name, files in packs.items():
        tic, cpu = time.perf_counter(), time.process_time()
        recordings = load(files)
        problem = FitProblem(params=params, recordings=recordings, simulator=simulator)
        result = TPEOptimiser(n_trials=trials, seed=seed, storage=storage, study_name=prefix + name,
                              progress=False).run(problem, space)
        fitted = params.with_values(result.best_values, provenance={
            "fitted_by": "battery-predictor fleet fit (Optuna TPE, R2_mod of the seed paper Eq. 1-3)",
            "fitted_at": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
            "pack": name,
            "data": [str(r.source) for r in recordings],
            "r2_mod": result.best_r2_mod,
            "trials": result.trials,
            "failed_trials": result.failed_trials,
            "study": result.study_name,
            "storage": result.storage,
        }, fit=params.fit)
        out = out_dir / f"{name}.yaml"
        fitted.to_yaml(out)
        done = PackFit(pack=name, out=out, r2_mod=result.best_r2_mod, trials=result.trials,
                       resumed_trials=result.resumed_trials, own_trials=result.own_trials, improved=result.improved,
                       seconds=time.perf_counter() - tic, cpu_seconds=time.process_time() - cpu, rss_mb=resident_mb(),
                       study_name=result.study_name)
        del recordings, problem, fitted, result
        results.append(done)
        if on_pack is not None:
            on_pack(done)
    return results
