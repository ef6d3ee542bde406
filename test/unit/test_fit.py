"""TPE fitting: recovers a liionpack-made pack, records failures, resumes, is seeded."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from battery_predictor.errors import SimulationError
from battery_predictor.fitting.optimiser import STARTUP_TRIALS_PER_PARAMETER, TPEOptimiser
from battery_predictor.fitting.problem import FitProblem
from battery_predictor.fitting.space import fit_space
from battery_predictor.recording import Recording
from battery_predictor.simulation import PackSimResult


@dataclass
class _LinearSimulator:
    """Stand-in simulator: V = 4 - slope * t / 3600 with slope = 'Electrode height [m]'; fails above a limit."""

    fail_above: float = np.inf
    name: str = "linear"

    def simulate(self, params, request) -> PackSimResult:
        slope = params.value("Electrode height [m]")
        if slope > self.fail_above:
            raise SimulationError("solver failed (test)")
        t = request.output_times()
        v = 4.0 - slope * t / 3600.0
        return PackSimResult(t, v, np.ones_like(t), v, "end_of_load", float(t[-1]))


def _linear_problem(temi_params, fail_above=np.inf) -> FitProblem:
    t = np.arange(0.0, 3600.0, 30.0)
    rec = Recording(t, 4.0 - 0.7 * t / 3600.0, np.ones_like(t), source="linear")
    return FitProblem(temi_params, [rec], _LinearSimulator(fail_above), initial_state="params", extend_fraction=0.0)


def test_tpe_recovers_known_value_with_startup_trials_20_per_parameter(temi_params):
    problem = _linear_problem(temi_params)
    space = fit_space(temi_params, ("Electrode height [m]",))
    assert STARTUP_TRIALS_PER_PARAMETER == 20
    result = TPEOptimiser(n_trials=60, seed=0, progress=False).run(problem, space)
    assert result.best_values["Electrode height [m]"] == pytest.approx(0.7, rel=0.02)
    assert result.trials == 60 and result.failed_trials == 0


def test_failing_simulations_are_failed_trials_and_do_not_stop_the_fit(temi_params):
    problem = _linear_problem(temi_params, fail_above=1.0)
    space = fit_space(temi_params, ("Electrode height [m]",))  # bounds 0.449..1.346: part fails
    result = TPEOptimiser(n_trials=40, seed=0, progress=False).run(problem, space)
    assert result.trials == 40
    assert result.failed_trials > 0
    assert result.best_values["Electrode height [m]"] <= 1.0


def test_failing_trials_are_pruned_with_their_error_so_tpe_ranks_them_last(temi_params, tmp_path):
    import optuna
    from optuna.trial import TrialState

    storage = f"sqlite:///{tmp_path / 'fit.db'}"
    problem = _linear_problem(temi_params, fail_above=1.0)
    space = fit_space(temi_params, ("Electrode height [m]",))
    result = TPEOptimiser(n_trials=30, seed=0, storage=storage, progress=False).run(problem, space)
    trials = optuna.load_study(study_name=result.study_name, storage=storage).trials
    pruned = [t for t in trials if t.state == TrialState.PRUNED]
    assert len(pruned) == result.failed_trials > 0
    assert all(t.user_attrs["error"] == "solver failed (test)" for t in pruned)
    assert all(t.params["Electrode height [m]"] > 1.0 for t in pruned)


def test_initial_concentration_bounds_stay_below_the_electrode_maximum(temi_params):
    from dataclasses import replace

    table1 = replace(temi_params, fitted={})  # Chen2020 values: 29866 of 33133 mol/m3 in the negative electrode
    names = ("Initial concentration in negative electrode [mol.m-3]",
             "Initial concentration in positive electrode [mol.m-3]",
             "Maximum concentration in positive electrode [mol.m-3]")
    space = {p.name: p for p in fit_space(table1, names)}
    neg = space[names[0]]
    c_n_max = table1.value("Maximum concentration in negative electrode [mol.m-3]")
    assert neg.low == pytest.approx(0.5 * neg.initial) and neg.high == pytest.approx(0.99 * c_n_max)
    pos, pos_max = space[names[1]], space[names[2]]
    assert pos.high <= 0.99 * pos_max.low  # feasible for every maximum searched
    assert pos.low >= 0.01 * pos_max.high


def test_every_trial_failing_gives_a_clear_error(temi_params):
    problem = _linear_problem(temi_params, fail_above=0.0)
    space = fit_space(temi_params, ("Electrode height [m]",))
    with pytest.raises(SimulationError, match="every trial failed"):
        TPEOptimiser(n_trials=5, seed=0, progress=False).run(problem, space)


def test_stopped_fit_resumes_from_sqlite_storage(temi_params, tmp_path):
    import optuna

    storage = f"sqlite:///{tmp_path / 'fit.db'}"
    problem = _linear_problem(temi_params)
    space = fit_space(temi_params, ("Electrode height [m]",))
    first = TPEOptimiser(n_trials=8, seed=0, storage=storage, progress=False).run(problem, space)
    second = TPEOptimiser(n_trials=12, seed=0, storage=storage, progress=False).run(problem, space)
    assert first.trials == 8 and second.trials == 12
    assert (first.resumed_trials, second.resumed_trials) == (0, 8)
    study = optuna.load_study(study_name=second.study_name, storage=storage)
    assert len(study.trials) == 12


def test_a_fit_that_never_beats_its_start_says_so(temi_params):
    problem = _linear_problem(temi_params)
    space = fit_space(temi_params, ("Electrode height [m]",))
    one = TPEOptimiser(n_trials=1, seed=0, progress=False).run(problem, space)
    assert not one.improved and one.trials == 1


def test_same_seed_gives_same_fit(temi_params):
    problem = _linear_problem(temi_params)
    space = fit_space(temi_params, ("Electrode height [m]",))
    a = TPEOptimiser(n_trials=25, seed=7, progress=False).run(problem, space)
    b = TPEOptimiser(n_trials=25, seed=7, progress=False).run(problem, space)
    assert a.best_values == b.best_values


def test_default_bounds_follow_the_paper(temi_params):
    space = {p.name: p for p in fit_space(temi_params)}
    h = space["Electrode height [m]"]
    assert (h.low, h.high) == pytest.approx((0.5 * h.initial, 1.5 * h.initial))
    eps = space["Positive electrode active material volume fraction"]
    assert (eps.low, eps.high) == (0.3, 0.75)
    rc = space["r_c_ohm"]
    assert (rc.low, rc.high, rc.log) == (pytest.approx(0.1 * rc.initial), pytest.approx(10 * rc.initial), True)
