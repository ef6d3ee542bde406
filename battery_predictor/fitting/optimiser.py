"""Seeded tree-structured Parzen estimator (Optuna ``TPESampler``) over a fit problem.

Studies live in an Optuna RDB storage (SQLite file by default, any Optuna storage
URL such as PostgreSQL otherwise), so several processes can work on one study and
a stopped fit resumes where it stopped. A failing simulation (a solver
failure, or a parameter combination whose initial state lies outside the cell's voltage
window) never stops the fit: it is recorded as a *pruned* trial carrying the error in its
``error`` user attribute. Pruned rather than failed, because Optuna's TPE ignores failed
trials but ranks pruned ones below every completed trial: the sampler learns to avoid
infeasible regions instead of proposing them again (the measurement behind this rule:
docs/findings.md, "Code notes (issue 15)").
"""

from __future__ import annotations

import hashlib
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING

from battery_predictor.errors import BatteryPredictorError, SimulationError
from battery_predictor.fitting.problem import FitProblem
from battery_predictor.fitting.space import FitParameter
from battery_predictor.fitting.storage import close_storage, open_storage, redacted, worker_id
from battery_predictor.processes import ProcessPool, shared

if TYPE_CHECKING:
    import optuna
    from optuna import Study
    from optuna.samplers import BaseSampler
    from optuna.storages import BaseStorage
    from optuna.trial import FrozenTrial

#: Startup (random) trials per searched parameter, as in the seed paper.
STARTUP_TRIALS_PER_PARAMETER = 20


@dataclass(frozen=True)
class FitResult:
    """Outcome of a fit.

    Attributes
    ----------
    best_values : dict
        Best parameter values found (in each key's unit).
    best_r2_mod : float
        R2_mod of the best trial.
    trials : int
        Finished trials in the study (complete + failed).
    failed_trials : int
        Trials whose simulation failed.
    seconds : float
        Wall time of this run in s.
    study_name, storage : str
        Where the study is stored.
    resumed_trials : int
        Trials the study already held when this run started (a resumed study).
    improved : bool
        False when no trial beat the starting values (the enqueued trial 0 is the best).
    own_trials : int
        Finished trials this process ran (the others came from other processes sharing the study).
    """

    best_values: dict[str, float]
    best_r2_mod: float
    trials: int
    failed_trials: int
    seconds: float
    study_name: str
    storage: str
    resumed_trials: int = 0
    improved: bool = True
    own_trials: int = 0


def study_name_for(problem: FitProblem, space: Sequence[FitParameter]) -> str:
    """A study name that identifies the params, the data and the searched space."""
    h = hashlib.sha1()
    h.update(repr(sorted(problem.params.cell_values.items())).encode())
    h.update(repr(sorted(problem.params.interconnect.items())).encode())
    for rec in problem.recordings:
        h.update(rec.time_s.tobytes())
        h.update(rec.voltage_v.tobytes())
    h.update(repr([(p.name, p.low, p.high, p.log) for p in space]).encode())
    return f"{problem.params.name}-{h.hexdigest()[:12]}"


def resumed_study_message(study_name: str, storage: str | None, done: int, n_trials: int) -> str:
    """One line telling a user that a fit resumes a stored study, and how to start afresh.

    Parameters
    ----------
    study_name : str
        Name of the resumed study.
    storage : str or None
        Its Optuna storage URL.
    done : int
        Finished trials the study already holds.
    n_trials : int
        Total trials asked for.
    """
    trials = f"{done} trial{'s' if done != 1 else ''}"
    if done >= n_trials:
        plan = f"no new trial runs (pass --trials N with N > {done} to continue)"
    else:
        plan = f"running {n_trials - done} more up to --trials {n_trials}"
    afresh = "pass another --study-name"
    if storage and storage.startswith("sqlite:///"):
        afresh += f", or delete {storage[len('sqlite:///'):]}"
    return (f"fit: resuming study {study_name!r} in {storage}: it already holds {trials}; {plan}. "
            f"To start afresh, {afresh}.")


def _objective_factory(problem: FitProblem, space: Sequence[FitParameter]) -> Callable[[optuna.Trial], float]:
    worker = worker_id()

    def objective(trial: optuna.Trial) -> float:
        values = {p.name: trial.suggest_float(p.name, p.low, p.high, log=p.log) for p in space}
        import optuna

        trial.set_user_attr("worker", worker)
        try:
            ev = problem.evaluate(values)
        except BatteryPredictorError as exc:
            trial.set_user_attr("error", str(exc)[:300])
            raise optuna.TrialPruned(str(exc)[:300]) from None
        if not math.isfinite(ev.r2_mod):
            trial.set_user_attr("error", "non-finite R2_mod")
            raise optuna.TrialPruned("non-finite R2_mod")
        trial.set_user_attr("rmse_mv", [float(x) for x in ev.rmse_mv])
        return ev.r2_mod

    return objective


def _worker(storage: str, study_name: str, problem: FitProblem, space: Sequence[FitParameter], seed: int, n_startup: int,
            n_trials_total: int) -> None:
    """Child-process worker: runs trials until the study holds ``n_trials_total``."""
    import optuna
    from optuna.trial import TrialState

    optuna.logging.set_verbosity(optuna.logging.ERROR)
    sampler = optuna.samplers.TPESampler(seed=seed, n_startup_trials=n_startup)
    rdb = open_storage(storage)
    study = optuna.load_study(study_name=study_name, storage=rdb, sampler=sampler)

    def stop_when_done(study: optuna.Study, _trial: optuna.trial.FrozenTrial) -> None:
        states = (TrialState.COMPLETE, TrialState.FAIL, TrialState.PRUNED)
        if len(study.get_trials(deepcopy=False, states=states)) >= n_trials_total:
            study.stop()

    try:
        study.optimize(_objective_factory(problem, space), n_trials=n_trials_total, catch=(SimulationError,),
                       callbacks=[stop_when_done])
    finally:
        close_storage(rdb)


def _pool_worker(seed: int) -> None:
    """A :class:`~battery_predictor.processes.ProcessPool` task: :func:`_worker` with the study the parent shared."""
    storage, study_name, problem, space, n_startup, n_trials_total = shared("tpe_worker")
    _worker(storage, study_name, problem, space, seed, n_startup, n_trials_total)


class TPEOptimiser:
    """Seeded Optuna TPE.

    Parameters
    ----------
    n_trials : int
        Total trials of the study (a resumed study runs only the missing ones).
    seed : int
        Sampler seed (worker ``k`` uses ``seed + k``).
    storage : str or None
        Optuna storage URL (``sqlite:///fit.db``, ``postgresql://...``); None = in memory. Other
        processes (other machines too) may work on the same study at the same time, each with its
        own ``seed``: every process stops when the study holds ``n_trials`` finished trials.
    study_name : str or None
        Default: derived from params, data and space.
    workers : int
        Processes working on the study (needs an RDB storage when > 1).
    progress : bool
        Show a progress bar (trials, best R2_mod, ETA) on stderr.
    notice : callable or None
        Called with one line of text before any trial runs when the study already holds finished trials
        (a resumed study: its name, storage, trial count and how to start afresh).
    """

    def __init__(self, n_trials: int = 1000, seed: int = 0, storage: str | None = None,
                 study_name: str | None = None, workers: int = 1, progress: bool = True,
                 notice: Callable[[str], None] | None = None) -> None:
        if n_trials < 1:
            raise BatteryPredictorError(f"--trials must be >= 1, got {n_trials}")
        if workers < 1:
            raise BatteryPredictorError(f"--workers must be >= 1, got {workers}")
        if workers > 1 and storage is None:
            raise BatteryPredictorError("several workers need an RDB storage (--storage sqlite:///...)")
        self.n_trials = n_trials
        self.seed = seed
        self.storage = storage
        self.study_name = study_name
        self.workers = workers
        self.progress = progress
        self.notice = notice

    def run(self, problem: FitProblem, space: Sequence[FitParameter]) -> FitResult:
        """Run (or resume) the study and return the best values."""
        import optuna

        optuna.logging.set_verbosity(optuna.logging.ERROR)
        tic = time.perf_counter()
        n_startup = STARTUP_TRIALS_PER_PARAMETER * len(space)
        name = self.study_name or study_name_for(problem, space)
        sampler = optuna.samplers.TPESampler(seed=self.seed, n_startup_trials=n_startup)
        storage = open_storage(self.storage)
        try:
            return self._run(optuna, storage, sampler, name, n_startup, problem, space, tic)
        finally:
            close_storage(storage)

    def _run(self, optuna: ModuleType, storage: BaseStorage | None, sampler: BaseSampler, name: str, n_startup: int, problem: FitProblem,
             space: Sequence[FitParameter], tic: float) -> FitResult:
        from optuna.trial import TrialState

        try:
            study = optuna.create_study(study_name=name, storage=storage, sampler=sampler,
                                        direction="maximize", load_if_exists=True)
        except Exception as exc:  # noqa: BLE001 - storage unreachable, schema of another Optuna...
            raise BatteryPredictorError(f"cannot open study {name!r} in {redacted(str(self.storage))}: "
                                        f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
        finished_states = (TrialState.COMPLETE, TrialState.FAIL, TrialState.PRUNED)
        done = len(study.get_trials(deepcopy=False, states=finished_states))
        if done == 0 and not study.get_trials(deepcopy=False):  # the start is trial 0 (once, whoever comes first)
            study.enqueue_trial({p.name: min(max(p.initial, p.low), p.high) for p in space}, skip_if_exists=True)
        remaining = self.n_trials - done
        if done and self.notice is not None:
            self.notice(resumed_study_message(name, redacted(str(self.storage)), done, self.n_trials))
        bar = None
        if self.progress and remaining > 0:
            from tqdm import tqdm

            bar = tqdm(total=self.n_trials, initial=done, desc="fit", unit="trial", file=sys.stderr,
                       dynamic_ncols=True)

        def on_trial(study: Study, _trial: FrozenTrial) -> None:
            n = len(study.get_trials(deepcopy=False, states=finished_states))
            if bar is not None:
                bar.n = min(n, self.n_trials)
                try:
                    bar.set_postfix_str(f"best R2_mod={study.best_value:.4f}", refresh=False)
                except ValueError:
                    pass
                bar.refresh()
            if n >= self.n_trials:
                study.stop()

        if remaining > 0:
            # the other workers run in forked processes beside this one, on the same study (each its own seed)
            helpers = self.workers - 1 if self.workers > 1 else 0
            args = (self.storage, name, problem, space, n_startup, self.n_trials)
            with ProcessPool(helpers, shared={"tpe_worker": args}, background=True) as pool:
                running = [pool.start(_pool_worker, self.seed + k) for k in range(1, helpers + 1)]
                try:
                    study.optimize(_objective_factory(problem, space), n_trials=remaining, catch=(SimulationError,),
                                   callbacks=[on_trial])
                finally:
                    for job in running:
                        job.wait(timeout=600)
                    if bar is not None:
                        bar.close()
        trials = study.get_trials(deepcopy=False)
        complete = [t for t in trials if t.state == TrialState.COMPLETE]
        failed = [t for t in trials if t.state in (TrialState.FAIL, TrialState.PRUNED)]
        if not complete:
            reasons = {t.user_attrs.get("error", "?") for t in failed[:5]}
            raise SimulationError(f"every trial failed ({len(failed)}); e.g. {'; '.join(sorted(reasons))}")
        best = study.best_trial
        me = worker_id()
        return FitResult(
            best_values={k: float(v) for k, v in best.params.items()},
            best_r2_mod=float(best.value),
            trials=len(complete) + len(failed),
            failed_trials=len(failed),
            seconds=time.perf_counter() - tic,
            study_name=name,
            storage=redacted(self.storage) if self.storage else "memory",
            resumed_trials=done,
            improved=best.number != 0,
            own_trials=sum(1 for t in complete + failed if t.user_attrs.get("worker") == me),
        )
