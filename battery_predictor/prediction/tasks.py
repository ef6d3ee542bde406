"""Feasible tasks of the information robot (issue 14, item 2), without ROS.

The information robot (temi) returns to its charger when it measures 13.30 V (seed paper 5.1).
Before it accepts a passenger's request it asks: can it do this task now and still walk back to
the charger before 13.30 V? A task is information (standing, talking: the information current)
or navigation (a guided walk to a destination on the robot's map at the navigation current;
paper 5.1.1-5.1.3), with an optional current profile of its own.

From the calibrated present state (:meth:`PredictorCore.calibration`), each task is simulated on
the pack model (the SPM engine where it covers the params), followed by the walk from where the
task ends to the charger at a high navigation current (the 0.9 quantile of the measured
navigation currents, :data:`RETURN_CURRENT_QUANTILE`). A task is feasible when no simulated
voltage of the task and of that walk falls below the cut-off; it errs toward "no": a walk
without a destination is assumed to end at the map's node farthest from the charger. With a
:class:`TaskRisk` (the predictor's ``decision_risk``), the lowest voltage must stay above the
cut-off with probability ``1 - risk`` (:mod:`.uncertainty`: the model's voltage error, the
calibrated state's, a task current left to the usage model drawn from its distribution, the
parameters'); each answer gives that probability.

Policies (:data:`POLICIES`):

``independent``
    every task alone from the present state (which of these could the robot do next?);
``ordered``
    the tasks in the given order, one after the other; after the first infeasible task the rest
    are not done (and answered so);
``greedy``
    in the given order, each task done when it fits after the ones already accepted; an
    infeasible task is skipped and a later, smaller one may still fit.

The summary a robot can say counts guided walks (to the map's farthest destination from the
robot and back, at the mean navigation current) and minutes of information (at the mean
information current) from the present state, each keeping the walk back to the charger; both are
rounded down, and both are the median answer ("about").
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from battery_predictor.errors import BatteryPredictorError, RequestError
from battery_predictor.prediction.runtime import MAX_HORIZON_S, time_to_voltage_s
from battery_predictor.prediction.uncertainty import UncertaintyModel, route_spread
from battery_predictor.profiles.station import Station
from battery_predictor.profiles.temi import INFORMATION, NAVIGATION, TemiUsageConfig

if TYPE_CHECKING:
    from battery_predictor.prediction.core import PredictorCore
    from battery_predictor.prediction.pack_model import PackModel, RunStart
    from battery_predictor.simulation.base import SegmentRun

#: Task kinds.
KINDS = (INFORMATION, NAVIGATION)
#: Evaluation policies (see the module docstring).
POLICY_INDEPENDENT = "independent"
POLICY_ORDERED = "ordered"
POLICY_GREEDY = "greedy"
POLICIES = (POLICY_INDEPENDENT, POLICY_ORDERED, POLICY_GREEDY)
#: Most tasks in one request.
MAX_TASKS = 100
#: Most points of one task's current profile.
MAX_PROFILE_POINTS = 256
#: Longest task, s.
MAX_TASK_S = 12 * 3600.0
#: Largest task current, A (far above any robot of this kind; a larger number is a unit error).
MAX_TASK_CURRENT_A = 100.0
#: Quantile of the measured navigation currents the walk back to the charger is simulated at.
RETURN_CURRENT_QUANTILE = 0.9
#: Resolution of the summary's time searches, s.
SEARCH_TOLERANCE_S = 10.0


@dataclass(frozen=True)
class Task:
    """A candidate task.

    Attributes
    ----------
    name : str
        Free text, echoed in answers.
    kind : str
        ``information`` or ``navigation``.
    duration_s : float
        Expected duration in s (> 0). Required for information; for navigation, NaN means the
        walk to ``destination`` at the robot's speed.
    destination : str
        Navigation only: a node of the robot's map ("" = unknown: the walk is assumed to end at
        the node farthest from the charger).
    current_a : float
        Pack current during the task in A (> 0); NaN = the kind's mean measured current.
    profile : tuple of (float, float)
        Optional current profile ``((duration_s, current_a), ...)``: replaces ``duration_s`` and
        ``current_a`` when given.
    """

    name: str
    kind: str
    duration_s: float = math.nan
    destination: str = ""
    current_a: float = math.nan
    profile: tuple[tuple[float, float], ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        where = f"task {self.name!r}"
        if self.kind not in KINDS:
            raise RequestError(f"{where}: kind {self.kind!r} is not one of {', '.join(KINDS)}")
        for attr in ("duration_s", "current_a"):
            value = getattr(self, attr)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise RequestError(f"{where}: {attr} is {value!r} (must be a number)") from None
            object.__setattr__(self, attr, value)
        if len(self.profile) > MAX_PROFILE_POINTS:
            raise RequestError(f"{where}: current profile has {len(self.profile)} points (at most "
                               f"{MAX_PROFILE_POINTS})")
        profile = []
        for k, point in enumerate(self.profile):
            try:
                d, i = (float(v) for v in point)
            except (TypeError, ValueError):
                raise RequestError(f"{where}: profile point {k} is {point!r} (must be (duration_s, current_a))") from None
            if not (math.isfinite(d) and 0.0 < d <= MAX_TASK_S):
                raise RequestError(f"{where}: profile point {k} lasts {d!r} s (must be > 0 and <= "
                                   f"{MAX_TASK_S:.0f} s)")
            if not (math.isfinite(i) and 0.0 <= i <= MAX_TASK_CURRENT_A):
                raise RequestError(f"{where}: profile point {k} draws {i!r} A (must be 0..{MAX_TASK_CURRENT_A:g} A, "
                                   "positive while discharging)")
            profile.append((d, i))
        object.__setattr__(self, "profile", tuple(profile))
        if profile:
            total = sum(d for d, _ in profile)
            if total > MAX_TASK_S:
                raise RequestError(f"{where}: current profile lasts {total:.0f} s (at most {MAX_TASK_S:.0f} s)")
            return
        d = self.duration_s
        if not math.isnan(d) and not (math.isfinite(d) and 0.0 < d <= MAX_TASK_S):
            raise RequestError(f"{where}: duration_s is {d!r} (must be > 0 and <= {MAX_TASK_S:.0f} s)")
        if math.isnan(d) and (self.kind == INFORMATION or not self.destination):
            raise RequestError(f"{where}: needs a duration_s" + (" or a destination" if self.kind == NAVIGATION else ""))
        i = self.current_a
        if not math.isnan(i) and not (math.isfinite(i) and 0.0 < i <= MAX_TASK_CURRENT_A):
            raise RequestError(f"{where}: current_a is {i!r} (must be > 0 and <= {MAX_TASK_CURRENT_A:g} A, or NaN "
                               "for the kind's mean)")


@dataclass(frozen=True)
class TaskLoads:
    """The currents and speed tasks are simulated with.

    Attributes
    ----------
    information_current_a, navigation_current_a : float
        Mean pack current of each kind, A (the usage model's KDE means).
    return_current_a : float
        Current of the walk back to the charger, A (a high quantile of the navigation currents).
    speed_m_s : float
        Walking speed, m/s (paper: 0.90 m/s).
    information_std_a, navigation_std_a : float
        Standard deviation of the measured currents of each kind, A: the usage model draws one
        current per interaction, so a task's mean current is one such draw.
    """

    information_current_a: float
    navigation_current_a: float
    return_current_a: float
    speed_m_s: float
    information_std_a: float = 0.0
    navigation_std_a: float = 0.0

    @classmethod
    def from_usage(cls, config: TemiUsageConfig, speed_m_s: float) -> TaskLoads:
        """From the information robot's usage model (``temi_usage.yaml``) and its speed (m/s)."""
        nav = np.asarray(config.current_samples_a[NAVIGATION], dtype=float)
        info = np.asarray(config.current_samples_a[INFORMATION], dtype=float)
        return cls(config.current_distribution(INFORMATION).mean, config.current_distribution(NAVIGATION).mean,
                   float(np.quantile(nav, RETURN_CURRENT_QUANTILE)), float(speed_m_s),
                   float(np.std(info, ddof=1)), float(np.std(nav, ddof=1)))


@dataclass(frozen=True)
class TaskRisk:
    """How sure a feasible answer must be.

    Attributes
    ----------
    risk : float
        Accepted probability that the lowest voltage falls below the cut-off (0.5 = the median).
    model : UncertaintyModel
        Spreads of the params.
    state_voltage_sigma_v : float
        Pack-voltage error of the calibrated state, V.
    """

    risk: float
    model: UncertaintyModel
    state_voltage_sigma_v: float


@dataclass(frozen=True)
class TaskOutcome:
    """The answer for one task.

    Attributes
    ----------
    name, kind : str
        As requested.
    feasible : bool
        True when the task (after the accepted ones, per policy) still leaves the walk back to
        the charger above the cut-off.
    duration_s : float
        Task duration, s (NaN when not evaluated).
    current_a : float
        Mean task current, A.
    end_voltage_v : float
        Predicted pack voltage at the end of the task under its current, V (NaN when not evaluated).
    return_voltage_v : float
        Predicted pack voltage at the charger after walking back, V.
    margin_v : float
        Lowest predicted voltage over the task and the walk back minus the cut-off, V.
    remaining_after_s : float
        Time from the end of the task until the cut-off at the present average current, s (NaN when not
        evaluated; the model's longest horizon when beyond it).
    end_location : str
        Where the task ends ("" when unknown).
    reason : str
        Why, in one line.
    probability_feasible : float
        Probability that the lowest voltage stays at or above the cut-off (NaN without a :class:`TaskRisk`
        or when not evaluated).
    """

    name: str
    kind: str
    feasible: bool
    duration_s: float = math.nan
    current_a: float = math.nan
    end_voltage_v: float = math.nan
    return_voltage_v: float = math.nan
    margin_v: float = math.nan
    remaining_after_s: float = math.nan
    end_location: str = ""
    reason: str = ""
    probability_feasible: float = math.nan


@dataclass(frozen=True)
class TaskPlan:
    """The answer to a feasible-tasks request.

    Attributes
    ----------
    valid : bool
        True when the answer rests on a usable pack state (else nothing is feasible; see reason).
    policy : str
        The policy applied.
    outcomes : tuple of TaskOutcome
        One per task, in request order.
    more_guided_walks : int
        Guided walks (``walk_length_m`` there and back) the pack still allows, rounded down.
    walk_length_m : float
        One way of the guided walk counted, m.
    more_information_s : float
        Time of information the pack still allows, s (whole minutes, rounded down).
    summary : str
        A sentence the robot can say.
    state_of_charge : float
        The calibrated present SOC (NaN when unknown).
    cutoff_voltage_v : float
        The cut-off, V.
    reason : str
        What was assumed, or why the answer is not valid.
    """

    valid: bool
    policy: str
    outcomes: tuple[TaskOutcome, ...]
    more_guided_walks: int = 0
    walk_length_m: float = math.nan
    more_information_s: float = 0.0
    summary: str = ""
    state_of_charge: float = math.nan
    cutoff_voltage_v: float = math.nan
    reason: str = ""

    @property
    def feasible_count(self) -> int:
        """Number of feasible tasks."""
        return sum(o.feasible for o in self.outcomes)


def invalid_plan(tasks: Sequence[Task], policy: str, reason: str, cutoff_v: float = math.nan) -> TaskPlan:
    """An answer that declares nothing feasible, with the reason for every task."""
    outcomes = tuple(TaskOutcome(t.name, t.kind, False, reason=reason) for t in tasks)
    return TaskPlan(False, policy, outcomes, summary="I cannot tell how much charge is left right now.",
                    cutoff_voltage_v=cutoff_v, reason=reason)


class TaskPlanner:
    """Evaluates tasks on a pack model from a calibrated state (ROS-free; see module docstring).

    Parameters
    ----------
    runner : PackModel
        The pack model (``run``, ``soc_of``, ``soc_bounds``, ``capacity_ah``).
    station : Station
        The robot's map (``minden_information_map.yaml``).
    charger : str
        Node of the charger on ``station``.
    loads : TaskLoads
        Task currents and walking speed.
    cutoff_voltage_v : float
        Pack voltage at which the robot returns to the charger, V (13.30 V).
    temperature_k : float
        Temperature assumed, K.
    average_current_a : float
        Present cycle's average load, A (for the remaining time after a task).
    risk : TaskRisk, optional
        Decide at this risk (default: on the median voltages).
    """

    def __init__(self, runner: PackModel, station: Station, charger: str, loads: TaskLoads, cutoff_voltage_v: float,
                 temperature_k: float, average_current_a: float, risk: TaskRisk | None = None) -> None:
        self.runner = runner
        self.risk = risk
        self.station = station
        self.charger = station.check_node(charger)
        self.loads = loads
        self.cutoff_voltage_v = float(cutoff_voltage_v)
        self.temperature_k = float(temperature_k)
        self.average_current_a = float(average_current_a)
        self._far_node, self._far_m = station.farthest_from(self.charger)

    # ------------------------------------------------------------- pieces
    def return_m(self, location: str) -> float:
        """Walk from ``location`` to the charger, m ("" = unknown: from the farthest node)."""
        return self._far_m if not location else self.station.distance_m(location, self.charger)

    def _return_segments(self, location: str) -> list[tuple[float, float]]:
        d = self.return_m(location)
        return [(d / self.loads.speed_m_s, self.loads.return_current_a)] if d > 0 else []

    def task_segments(self, task: Task, location: str) -> tuple[list[tuple[float, float]], str]:
        """Constant-current segments ``(duration_s, current_a)`` of ``task`` from ``location``, and where it ends.

        Raises
        ------
        RequestError
            When the destination is not on the map.
        """
        if task.kind == NAVIGATION:
            if task.destination:
                if task.destination not in self.station.nodes:
                    raise RequestError(f"task {task.name!r}: destination {task.destination!r} is not on the map "
                                       f"(known: {', '.join(sorted(self.station.nodes))})")
                end = task.destination
            else:
                end = ""
        else:
            end = location
        if task.profile:
            return list(task.profile), end
        current = task.current_a if math.isfinite(task.current_a) else (
            self.loads.navigation_current_a if task.kind == NAVIGATION else self.loads.information_current_a)
        duration = task.duration_s
        if math.isnan(duration):  # a walk to the destination
            d = self.station.distance_m(location, end) if location else self._far_m
            duration = max(d / self.loads.speed_m_s, 1.0)
        return [(duration, current)], end

    def _ok(self, run: SegmentRun) -> tuple[bool, float]:
        """(no cut-off reached and every voltage >= cut-off, lowest voltage)."""
        if run.reached_cutoff:
            return False, math.nan
        low = float(np.min(run.pack_voltage_v))
        return low >= self.cutoff_voltage_v, low

    def _remaining_s(self, state: RunStart) -> float:
        avg = self.average_current_a
        if not (math.isfinite(avg) and avg > 0):
            return math.nan
        soc = self.runner.soc_of(state)
        charge_left_ah = max(soc - self.runner.soc_bounds[0], 0.02) * self.runner.capacity_ah
        horizon_s = min(MAX_HORIZON_S, 1.5 * charge_left_ah * 3600.0 / avg + 3600.0)
        run = self.runner.run(state, [(horizon_s, avg)], self.temperature_k)
        t = time_to_voltage_s(run.time_s, run.pack_voltage_v, self.cutoff_voltage_v)
        if t is not None:
            return t
        return float(run.end_time_s) if run.reached_cutoff else horizon_s

    def try_task(self, start: RunStart, location: str, task: Task) -> tuple[TaskOutcome, RunStart | None, str]:
        """Simulate ``task`` from ``start`` at ``location``: (outcome, state after the task or None, end location)."""
        try:
            segments, end = self.task_segments(task, location)
        except BatteryPredictorError as exc:
            return TaskOutcome(task.name, task.kind, False, reason=f"invalid task: {exc}"), None, location
        duration = sum(d for d, _ in segments)
        mean_a = sum(d * i for d, i in segments) / duration
        run = self.runner.run(start, segments, self.temperature_k)
        base: dict[str, Any] = dict(name=task.name, kind=task.kind, duration_s=duration, current_a=mean_a,
                                    end_location=end)
        if run.reached_cutoff or run.final_state is None:
            t_low = time_to_voltage_s(run.time_s, run.pack_voltage_v, self.cutoff_voltage_v)
            when = f"the pack falls to {self.cutoff_voltage_v:.2f} V {t_low / 60:.1f} min" if t_low is not None \
                else f"a cell reaches its cut-off {run.end_time_s / 60:.1f} min"
            return TaskOutcome(**base, feasible=False, reason=f"not feasible: {when} into the task "
                                                              f"({duration / 60:.1f} min at {mean_a:.2f} A)"), None, end
        ok_task, low_task = self._ok(run)
        v_end = float(run.pack_voltage_v[-1])
        state = run.final_state
        ret = self._return_segments(end)
        if ret:
            back = self.runner.run(state, ret, self.temperature_k)
            ok_back, low_back = self._ok(back)
            v_back = float(back.pack_voltage_v[-1]) if not back.reached_cutoff else math.nan
        else:
            ok_back, low_back, v_back = True, v_end, v_end
        low = min(low_task, low_back) if math.isfinite(low_back) else math.nan
        margin = low - self.cutoff_voltage_v
        remaining = self._remaining_s(state)
        walk = self.return_m(end)
        where = end or f"an unknown place (assumed {self._far_node})"
        feasible = ok_task and ok_back
        probability, risk_note = math.nan, ""
        if self.risk is not None and feasible:
            after = back.final_state if ret and back.final_state is not None else state
            probability, at_risk_v = self._at_risk(start, after, task, duration, segments + ret, low)
            feasible = at_risk_v >= self.cutoff_voltage_v
            risk_note = (f"; probability above the cut-off {probability:.3f}, P{100 * self.risk.risk:.0f} lowest "
                         f"voltage {at_risk_v:.2f} V (accepted risk {self.risk.risk:.2f})")
        verdict = "feasible" if feasible else "not feasible"
        reason = (f"{verdict}: {duration / 60:.1f} min at {mean_a:.2f} A ends at {v_end:.2f} V; the {walk:.0f} m walk "
                  f"back to the {self.charger} from {where} at {self.loads.return_current_a:.2f} A ends at "
                  + (f"{v_back:.2f} V" if math.isfinite(v_back) else "a cell cut-off")
                  + f", cut-off {self.cutoff_voltage_v:.2f} V, margin "
                  + (f"{margin:+.2f} V" if math.isfinite(margin) else "none") + risk_note)
        return (TaskOutcome(**base, feasible=feasible, end_voltage_v=v_end, return_voltage_v=v_back, margin_v=margin,
                            remaining_after_s=remaining, reason=reason, probability_feasible=probability), state, end)

    def _at_risk(self, start: RunStart, after: RunStart, task: Task, task_s: float,
                 segments: list[tuple[float, float]], low_v: float) -> tuple[float, float]:
        """(probability that the lowest voltage stays above the cut-off, the lowest voltage at the risk), V."""
        risk = self.risk
        assert risk is not None  # asked only with a risk
        soc0 = self.runner.soc_of(start) if not isinstance(start, (int, float)) else float(start)
        charge_ah = sum(d * i for d, i in segments) / 3600.0
        std_a = 0.0
        if not task.profile and not math.isfinite(task.current_a):  # the usage model's current: one draw
            std_a = self.loads.navigation_std_a if task.kind == NAVIGATION else self.loads.information_std_a
        charge_sigma_ah = task_s / 3600.0 * std_a

        def lowest_at(temperature_k: float) -> float:
            run = self.runner.run(start, segments, temperature_k)
            return math.nan if run.reached_cutoff else float(np.min(run.pack_voltage_v))

        spread = route_spread(self.runner, soc0, self.runner.soc_of(after), charge_ah, charge_sigma_ah,
                              self.temperature_k, risk.model, risk.state_voltage_sigma_v, lowest_at)
        return spread.probability_above(low_v - self.cutoff_voltage_v), spread.voltage_at_risk_v(low_v, risk.risk)

    def max_time_s(self, start: RunStart, location: str, current_a: float) -> float:
        """Longest time (s) at ``current_a`` from ``start`` that still leaves the walk back (to
        :data:`SEARCH_TOLERANCE_S`, rounded down; the model's horizon when beyond it)."""
        ret = self._return_segments(location)

        def ok(t_s: float) -> bool:
            return self._ok(self.runner.run(start, [(t_s, current_a), *ret], self.temperature_k))[0]

        if not ok(1.0):
            return 0.0
        soc = self.runner.soc_of(start) if not isinstance(start, (int, float)) else float(start)
        charge_left_ah = max(soc - self.runner.soc_bounds[0], 0.02) * self.runner.capacity_ah
        hi = min(MAX_HORIZON_S, 1.5 * charge_left_ah * 3600.0 / current_a + 3600.0)
        if ok(hi):
            return hi
        lo = 1.0
        while hi - lo > SEARCH_TOLERANCE_S:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if ok(mid) else (lo, mid)
        return lo

    # ------------------------------------------------------------- answers
    def evaluate(self, start: RunStart, location: str, tasks: Sequence[Task], policy: str) -> TaskPlan:
        """Answer a request from the calibrated ``start`` (SOC or model state) at ``location``.

        Raises
        ------
        RequestError
            For an unknown policy or location, or too many tasks.
        BatteryPredictorError
            When the model fails.
        """
        if policy not in POLICIES:
            raise RequestError(f"policy {policy!r} is not one of {', '.join(POLICIES)}")
        if len(tasks) > MAX_TASKS:
            raise RequestError(f"{len(tasks)} tasks (at most {MAX_TASKS})")
        if location:
            if location not in self.station.nodes:
                raise RequestError(f"location {location!r} is not on the map (known: "
                                   f"{', '.join(sorted(self.station.nodes))})")
        outcomes: list[TaskOutcome] = []
        state, here, blocked = start, location, ""
        for task in tasks:
            if policy == POLICY_INDEPENDENT:
                outcomes.append(self.try_task(start, location, task)[0])
                continue
            if blocked:
                outcomes.append(TaskOutcome(task.name, task.kind, False,
                                            reason=f"not done: it follows the infeasible task {blocked!r} (ordered)"))
                continue
            outcome, after, end = self.try_task(state, here, task)
            if outcome.feasible:
                assert after is not None  # a feasible task ends in a state
                state, here = after, end
            elif policy == POLICY_ORDERED:
                blocked = task.name
            else:
                outcome = replace(outcome, reason=outcome.reason + "; skipped (greedy)")
            outcomes.append(outcome)
        walks, walk_m, info_s, summary = self.summary(start, location)
        soc = self.runner.soc_of(start) if not isinstance(start, (int, float)) else float(start)
        n_ok = sum(o.feasible for o in outcomes)
        reason = (f"{n_ok} of {len(outcomes)} tasks feasible ({policy}); each keeps the walk back to the "
                  f"{self.charger} at {self.loads.return_current_a:.2f} A above {self.cutoff_voltage_v:.2f} V")
        return TaskPlan(True, policy, tuple(outcomes), walks, walk_m, info_s, summary, soc, self.cutoff_voltage_v,
                        reason)

    def summary(self, start: RunStart, location: str) -> tuple[int, float, float, str]:
        """(guided walks, one-way walk length in m, information time in s, sentence) from ``start``."""
        if location:
            others = [(self.station.distance_m(location, n), n) for n in self.station.nodes if n != location]
            walk_m, goal = max(others) if others else (0.0, location)
        else:
            walk_m, goal = self._far_m, self.charger
        walk_s = 2.0 * walk_m / self.loads.speed_m_s
        nav_s = self.max_time_s(start, location, self.loads.navigation_current_a)
        info_s = self.max_time_s(start, location, self.loads.information_current_a)
        walks = int(nav_s // walk_s) if walk_s > 0 else 0
        info_s = 60.0 * math.floor(info_s / 60.0)
        sentence = (f"I have charge for about {walks} more guided walks ({walk_m:.0f} m to the {goal} and back) "
                    f"or {info_s / 60:.0f} minutes of information before I return to my charger.")
        if walks == 0 and info_s == 0:
            sentence = "I need to return to my charger now."
        return walks, walk_m, info_s, sentence


def feasible_tasks(core: PredictorCore, tasks: Sequence[Task], location: str, policy: str, now_s: float, station: Station,
                   charger: str, loads: TaskLoads, fallback_current_a: float) -> TaskPlan:
    """Answer a request from a :class:`~battery_predictor.prediction.core.PredictorCore`'s present state.

    Never raises for bad input, unknown or stale state or a failing model: the answer is then
    invalid (nothing feasible) with the reason. Like routes, nothing is feasible when the latest
    measured voltage is already at the cut-off, and the answer is invalid when the calibrated
    model does not reproduce the measurement within the core's state tolerance.

    Parameters
    ----------
    core : PredictorCore
        The predictor's core (state, calibration, pack model, cut-off).
    tasks, location, policy :
        The request (see :meth:`TaskPlanner.evaluate`).
    now_s : float
        Present time on the core's time base, s.
    station, charger, loads :
        The robot's map, its charger node and the task currents (see :class:`TaskPlanner`).
    fallback_current_a : float
        Average load assumed for the remaining time when the present cycle has none yet, A.
    """
    cutoff = core.cutoff_voltage_v
    if core.runner is None:
        return invalid_plan(tasks, policy, f"no usable pack model: {core.model_error}", cutoff)
    state = core.latest_state()
    if state is None:
        return invalid_plan(tasks, policy, "state unknown: no pack state received yet", cutoff)
    age = now_s - state[0]
    if age > core.config.stale_after_s:
        return invalid_plan(tasks, policy, f"state unknown: pack state is stale ({age:.1f} s old, limit "
                                           f"{core.config.stale_after_s:.0f} s)", cutoff)
    _, v, i, t_k = state
    temp = t_k if math.isfinite(t_k) and 200.0 < t_k < 400.0 else core.default_temperature_k
    try:
        if v <= cutoff:
            plan = invalid_plan(tasks, policy, f"measured {v:.2f} V at {i:.2f} A is at or below the cut-off "
                                               f"{cutoff:.2f} V: return to the charger now", cutoff)
            return replace(plan, valid=True, summary="I need to return to my charger now.")
        cal = core.calibration(temp)
        if cal.clipped == "below_empty":
            return invalid_plan(tasks, policy, f"pack voltage {v:.2f} V at {i:.2f} A is below the model's empty "
                                               "state", cutoff)
        if cal.clipped != "above_full" and not abs(cal.latest_residual_v) <= core.state_tolerance_v:
            return invalid_plan(tasks, policy, f"the model cannot reproduce the measured {v:.2f} V (off by "
                                               f"{cal.latest_residual_v:+.2f} V after calibration, tolerance "
                                               f"{core.state_tolerance_v:.2f} V): state uncertain", cutoff)
        runtime = core.remaining_runtime(now_s)
        average = runtime.assumed_current_a
        load_note = f"present average current {average:.2f} A"
        if not (math.isfinite(average) and average > 0):
            average = fallback_current_a
            load_note = f"no discharge load in the present cycle yet: the usage model's mean {average:.2f} A"
        risk = TaskRisk(core.config.decision_risk, core.uncertainty, core.state_voltage_sigma_v(cal))
        planner = TaskPlanner(core.runner, station, charger, loads, cutoff, temp, average, risk)
        plan = planner.evaluate(cal.start, location, tasks, policy)
    except BatteryPredictorError as exc:
        return invalid_plan(tasks, policy, f"invalid request: {exc}" if isinstance(exc, RequestError)
                            else f"model failed: {exc}", cutoff)
    return replace(plan, reason=f"{plan.reason}; remaining time after each at the {load_note}")
