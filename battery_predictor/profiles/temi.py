"""Stochastic load profiles of the Temi information service robot (seed paper 5.1.1-5.1.4).

A curve point is generated in three steps (section 5.1.4):

1. draw the usage state (``idling``, ``information`` or ``navigation``) with
   the probabilities derived from the passenger survey
   (:func:`derive_usage_probabilities`, 10.0 % / 57.6 % / 32.4 %);
2. draw its duration: idling and information from a Gaussian KDE over the
   observed interaction times (clipped to their range), navigation
   uniformly between the shortest and longest trip time
   (1-60 m at 0.90 m/s, i.e. 1.1-66.7 s);
3. draw its current from the KDE of that state's current samples.

All numbers come from ``params/temi_usage.yaml`` (:func:`load_usage_config`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from battery_predictor.config import (
    as_float,
    as_float_list,
    check_unknown,
    default_params_file,
    read_yaml_mapping,
    require,
)
from battery_predictor.errors import ParamsError, ProfileError
from battery_predictor.profiles.kde import BoundedKde
from battery_predictor.profiles.load_profile import LoadProfile

IDLING = "idling"
INFORMATION = "information"
NAVIGATION = "navigation"
#: Usage states in the order used for drawing (and in every returned mapping).
STATES = (IDLING, INFORMATION, NAVIGATION)

#: How the paper maps survey answers to usage states (section 5.1.2).
PAPER_ASSIGNMENT: Mapping[str, str] = {
    "information_services": INFORMATION,
    "navigation_services": NAVIGATION,
    "other_services": INFORMATION,
    "other_purposes": INFORMATION,
}

#: Default params file shipped with the package.
DEFAULT_CONFIG_FILE = "temi_usage.yaml"

#: Points are drawn in chunks of this size, so a profile is a prefix of any
#: longer profile generated with the same seed and config.
CHUNK_POINTS = 256
#: Safety limit on the number of generated points.
MAX_GENERATED_POINTS = 5_000_000


def derive_usage_probabilities(
    response_counts: Mapping[str, int],
    idle_share: float = 0.10,
    *,
    assignment: Mapping[str, str] = PAPER_ASSIGNMENT,
    share_resolution: float | None = 0.01,
    residual_state: str = INFORMATION,
) -> dict[str, float]:
    """Usage-state probabilities of a curve point from survey answer counts.

    Follows section 5.1.2: the counts are normalised to the total number of
    selections, each answer is added to the usage state it is assigned to,
    the resulting service shares are scaled by ``1 - idle_share`` and
    ``idle_share`` is the idling probability.

    Parameters
    ----------
    response_counts : mapping of str to int
        Number of passengers who selected each answer (multiple selections
        allowed), e.g. ``{"information_services": 78, "navigation_services":
        56, "other_services": 17, "other_purposes": 1}``.
    idle_share : float
        Probability of an idling point, in ``[0, 1)`` (paper: 0.10).
    assignment : mapping of str to str
        Usage state (``information`` or ``navigation``) of each answer.
    share_resolution : float or None
        The paper quotes the service shares as "around 64 %" and "around
        36 %" although exact normalisation gives 63.2 % / 36.8 %. With a
        resolution (0.01 = whole percent) every state except
        ``residual_state`` is rounded *down* to it and ``residual_state``
        gets the rest, which reproduces the paper's 57.6 % / 32.4 %. ``None``
        keeps the exact shares (56.8 % / 33.2 % for the paper's survey).
    residual_state : str
        State that receives the remainder when rounding.

    Returns
    -------
    dict
        ``{"idling": p, "information": p, "navigation": p}``, summing to 1.

    Raises
    ------
    ProfileError
        For negative or non-integer counts, no selections at all, an answer
        without assignment, an unknown state, or an idle share outside
        ``[0, 1)``.
    """
    idle_share = float(idle_share)
    if not 0.0 <= idle_share < 1.0:
        raise ProfileError(f"survey: idle_share is {idle_share} (must be in [0, 1))")
    service_states = (INFORMATION, NAVIGATION)
    if residual_state not in service_states:
        raise ProfileError(f"survey: residual_state {residual_state!r} is not one of {service_states}")
    totals = dict.fromkeys(service_states, 0)
    for answer, count in response_counts.items():
        if isinstance(count, bool) or not isinstance(count, int | np.integer) or count < 0:
            raise ProfileError(f"survey: count of {answer!r} is {count!r} (must be a non-negative integer)")
        if answer not in assignment:
            raise ProfileError(f"survey: answer {answer!r} has no usage state assigned")
        state = assignment[answer]
        if state not in service_states:
            raise ProfileError(f"survey: answer {answer!r} is assigned to {state!r}, not one of {service_states}")
        totals[state] += int(count)
    n_selections = sum(totals.values())
    if n_selections == 0:
        raise ProfileError("survey: no selections (all counts are 0)")
    shares = {state: totals[state] / n_selections for state in service_states}
    if share_resolution is not None:
        resolution = float(share_resolution)
        if not 0.0 < resolution < 1.0:
            raise ProfileError(f"survey: share_resolution is {resolution} (must be in (0, 1) or None)")
        for state in service_states:
            if state != residual_state:
                shares[state] = math.floor(shares[state] / resolution + 1e-9) * resolution
        shares[residual_state] = 1.0 - sum(s for state, s in shares.items() if state != residual_state)
    scale = 1.0 - idle_share
    return {IDLING: idle_share, INFORMATION: scale * shares[INFORMATION], NAVIGATION: scale * shares[NAVIGATION]}


class UniformDuration:
    """Uniform distribution on ``[lower, upper]`` with the interface of :class:`BoundedKde`."""

    def __init__(self, lower: float, upper: float, name: str = "uniform") -> None:
        if not 0.0 < lower < upper:
            raise ProfileError(f"{name}: uniform range [{lower}, {upper}] must satisfy 0 < lower < upper")
        self.name = name
        self.lower = float(lower)
        self.upper = float(upper)
        self.mean = 0.5 * (self.lower + self.upper)
        self.std = (self.upper - self.lower) / math.sqrt(12.0)

    def sample(self, size: int, rng: np.random.Generator) -> np.ndarray:
        """Draw ``size`` values using ``rng``."""
        return rng.uniform(self.lower, self.upper, size=int(size))

    def __repr__(self) -> str:
        return f"UniformDuration({self.name!r}, [{self.lower:.4g}, {self.upper:.4g}])"


@dataclass(frozen=True, eq=False)
class TemiUsageConfig:
    """Everything the Temi generator needs, as read from ``temi_usage.yaml``.

    Attributes
    ----------
    probabilities : dict
        Probability of each usage state per curve point (keys :data:`STATES`).
    interaction_samples_s : numpy.ndarray
        Observed interaction durations in s (KDE for idling and information).
    navigation_duration_range_s : tuple of float
        Shortest and longest navigation trip in s.
    current_samples_a : dict
        Pack current samples in A (discharge positive) per usage state.
    stop_voltage_v : float
        Terminal voltage in V at which a discharge with this profile ends.
    source : str
        File the config was read from (or ``"<memory>"``).
    survey : dict
        The survey inputs the probabilities were derived from (provenance).
    """

    probabilities: dict[str, float]
    interaction_samples_s: np.ndarray
    navigation_duration_range_s: tuple[float, float]
    current_samples_a: dict[str, np.ndarray]
    stop_voltage_v: float = 13.30
    source: str = "<memory>"
    survey: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if set(self.probabilities) != set(STATES):
            raise ProfileError(f"{self.source}: probabilities must have exactly the states {STATES}")
        p = np.array([self.probabilities[s] for s in STATES], dtype=float)
        if not np.all(np.isfinite(p)) or np.any(p < 0) or abs(p.sum() - 1.0) > 1e-9:
            raise ProfileError(f"{self.source}: state probabilities {p.tolist()} must be >= 0 and sum to 1")
        if set(self.current_samples_a) != set(STATES):
            raise ProfileError(f"{self.source}: current samples must be given for exactly the states {STATES}")
        for state in STATES:
            if np.any(np.asarray(self.current_samples_a[state], dtype=float) <= 0.0):
                raise ProfileError(f"{self.source}: current samples of {state} must be > 0 A (discharge)")
        interaction = BoundedKde(self.interaction_samples_s, name=f"{self.source}: interaction durations", mode="clip")
        if interaction.lower <= 0.0:
            raise ProfileError(f"{self.source}: interaction durations must be > 0 s")
        low, high = self.navigation_duration_range_s
        durations = {
            IDLING: interaction,
            INFORMATION: interaction,
            NAVIGATION: UniformDuration(low, high, name=f"{self.source}: navigation durations"),
        }
        currents = {
            state: BoundedKde(self.current_samples_a[state], name=f"{self.source}: {state} currents") for state in STATES
        }
        object.__setattr__(self, "_durations", durations)
        object.__setattr__(self, "_currents", currents)

    def duration_distribution(self, state: str) -> BoundedKde | UniformDuration:
        """Distribution the durations (s) of ``state`` points are drawn from."""
        return self._durations[_check_state(state)]  # type: ignore[attr-defined]

    def current_distribution(self, state: str) -> BoundedKde:
        """Distribution the currents (A) of ``state`` points are drawn from."""
        return self._currents[_check_state(state)]  # type: ignore[attr-defined]

    def expected_mean_current_a(self) -> float:
        """Long-run time-weighted mean current in A of generated profiles."""
        charge = sum(
            self.probabilities[s] * self.duration_distribution(s).mean * self.current_distribution(s).mean for s in STATES
        )
        duration = sum(self.probabilities[s] * self.duration_distribution(s).mean for s in STATES)
        return charge / duration


def _check_state(state: str) -> str:
    if state not in STATES:
        raise ProfileError(f"unknown Temi usage state {state!r} (expected one of {STATES})")
    return state


def default_config_path() -> Path:
    """Path of the shipped ``temi_usage.yaml``."""
    return default_params_file(DEFAULT_CONFIG_FILE)


def load_usage_config(path: str | Path | None = None) -> TemiUsageConfig:
    """Read and validate a Temi usage YAML (default: the shipped ``temi_usage.yaml``).

    Raises
    ------
    ParamsError
        If the file cannot be read, a key is missing or unknown, or a value
        is invalid; the message names the file and the dotted key.
    """
    path, data = read_yaml_mapping(default_config_path() if path is None else path)
    check_unknown(data, {"robot", "stop_voltage_v", "survey", "durations", "navigation", "currents_a"}, path, "")
    stop_voltage_v = as_float(require(data, "stop_voltage_v", path, ""), path, "stop_voltage_v", minimum=0.0, strict=True)
    probabilities, survey = _survey_from(data, path)
    interaction = _interaction_samples_from(data, path)
    d_min, d_max, speed = _navigation_from(data, path)
    current_samples = _current_samples_from(data, path)
    try:
        return TemiUsageConfig(
            probabilities=probabilities,
            interaction_samples_s=np.array(interaction),
            navigation_duration_range_s=navigation_duration_range_s(d_min, d_max, speed),
            current_samples_a=current_samples,
            stop_voltage_v=stop_voltage_v,
            source=str(path),
            survey=survey,
        )
    except ProfileError as exc:
        raise ParamsError(str(exc)) from None


def _survey_from(data: dict[str, Any], path: Path) -> tuple[dict[str, float], dict[str, Any]]:
    """The ``survey`` section: the state probabilities it gives (:func:`derive_usage_probabilities`) and the
    survey itself as the config keeps it (answer counts, idle share, share resolution)."""
    survey = require(data, "survey", path, "")
    check_unknown(survey, {"response_counts", "assignment", "idle_share", "share_resolution", "residual_state"}, path, "survey")
    counts = require(survey, "response_counts", path, "survey")
    if not isinstance(counts, dict) or not counts:
        raise ParamsError(f"{path}: survey.response_counts must be a non-empty mapping of answer to count")
    for answer, count in counts.items():
        if isinstance(count, bool) or not isinstance(count, int) or count < 0:
            raise ParamsError(f"{path}: survey.response_counts.{answer} must be a non-negative integer, got {count!r}")
    assignment = require(survey, "assignment", path, "survey")
    if not isinstance(assignment, dict):
        raise ParamsError(f"{path}: survey.assignment must be a mapping of answer to usage state")
    for answer in counts:
        if answer not in assignment:
            raise ParamsError(f"{path}: survey.assignment.{answer} is missing")
        if assignment[answer] not in (INFORMATION, NAVIGATION):
            raise ParamsError(f"{path}: survey.assignment.{answer} must be information or navigation, got {assignment[answer]!r}")
    idle_share = as_float(require(survey, "idle_share", path, "survey"), path, "survey.idle_share", minimum=0.0)
    if idle_share >= 1.0:
        raise ParamsError(f"{path}: survey.idle_share must be < 1, got {idle_share:g}")
    resolution = survey.get("share_resolution", None)
    if resolution is not None:
        resolution = as_float(resolution, path, "survey.share_resolution", minimum=0.0, strict=True)
        if resolution >= 1.0:
            raise ParamsError(f"{path}: survey.share_resolution must be < 1 or null, got {resolution:g}")
    residual = survey.get("residual_state", INFORMATION)
    if residual not in (INFORMATION, NAVIGATION):
        raise ParamsError(f"{path}: survey.residual_state must be information or navigation, got {residual!r}")
    try:
        probabilities = derive_usage_probabilities(
            counts, idle_share, assignment=assignment, share_resolution=resolution, residual_state=residual
        )
    except ProfileError as exc:
        raise ParamsError(f"{path}: {exc}") from None
    return probabilities, {"response_counts": dict(counts), "idle_share": idle_share, "share_resolution": resolution}


def _interaction_samples_from(data: dict[str, Any], path: Path) -> list[float]:
    """``durations.interaction_samples_s``: the measured interaction durations (s) of every service point, pooled."""
    durations = require(data, "durations", path, "")
    check_unknown(durations, {"interaction_samples_s"}, path, "durations")
    groups = require(durations, "interaction_samples_s", path, "durations")
    if not isinstance(groups, dict) or not groups:
        raise ParamsError(f"{path}: durations.interaction_samples_s must map a service point to a list of durations")
    interaction: list[float] = []
    for group, values in groups.items():
        interaction += as_float_list(
            values, path, f"durations.interaction_samples_s.{group}", minimum=0.0, strict=True, min_length=1
        )
    if len(set(interaction)) < 2:
        raise ParamsError(f"{path}: durations.interaction_samples_s needs at least two distinct durations")
    return interaction


def _navigation_from(data: dict[str, Any], path: Path) -> tuple[float, float, float]:
    """The ``navigation`` section: (shortest trip m, longest trip m, speed m/s)."""
    navigation = require(data, "navigation", path, "")
    check_unknown(navigation, {"distance_min_m", "distance_max_m", "speed_m_s"}, path, "navigation")
    d_min = as_float(require(navigation, "distance_min_m", path, "navigation"), path, "navigation.distance_min_m",
                     minimum=0.0, strict=True)
    d_max = as_float(require(navigation, "distance_max_m", path, "navigation"), path, "navigation.distance_max_m",
                     minimum=0.0, strict=True)
    speed = as_float(require(navigation, "speed_m_s", path, "navigation"), path, "navigation.speed_m_s",
                     minimum=0.0, strict=True)
    if d_max <= d_min:
        raise ParamsError(f"{path}: navigation.distance_max_m ({d_max:g}) must exceed distance_min_m ({d_min:g})")
    return d_min, d_max, speed


def _current_samples_from(data: dict[str, Any], path: Path) -> dict[str, np.ndarray]:
    """``currents_a``: the measured pack currents (A) of each usage state."""
    currents = require(data, "currents_a", path, "")
    check_unknown(currents, set(STATES), path, "currents_a")
    current_samples: dict[str, np.ndarray] = {}
    for state in STATES:
        values = as_float_list(require(currents, state, path, "currents_a"), path, f"currents_a.{state}",
                               minimum=0.0, strict=True)
        if len(set(values)) < 2:
            raise ParamsError(f"{path}: currents_a.{state} needs at least two distinct currents")
        current_samples[state] = np.array(values)
    return current_samples


def navigation_duration_range_s(distance_min_m: float, distance_max_m: float, speed_m_s: float) -> tuple[float, float]:
    """Shortest and longest trip time in s for trips of ``distance_min_m``-``distance_max_m`` at ``speed_m_s``.

    For the paper's 1-60 m at 0.90 m/s this is (1.11 s, 66.67 s), quoted as
    "approximately between 1 and 67 s".
    """
    if not (0.0 < distance_min_m < distance_max_m and speed_m_s > 0.0):
        raise ProfileError(
            f"navigation: need 0 < distance_min_m < distance_max_m and speed_m_s > 0, "
            f"got {distance_min_m}, {distance_max_m}, {speed_m_s}"
        )
    return distance_min_m / speed_m_s, distance_max_m / speed_m_s


def _check_limit(name: str, value: float | None) -> float | None:
    if value is None:
        return None
    value = float(value)
    if not math.isfinite(value) or value <= 0.0:
        raise ProfileError(f"temi profile: {name} is {value} (must be finite and > 0)")
    return value


def generate_usage_profile(
    config: TemiUsageConfig | str | Path | None = None,
    seed: int | np.random.Generator | None = None,
    *,
    max_duration_s: float | None = None,
    max_charge_ah: float | None = None,
    max_points: int | None = None,
) -> LoadProfile:
    """Generate a stochastic Temi load profile (section 5.1.4).

    Parameters
    ----------
    config : TemiUsageConfig, path or None
        The usage model, or a YAML path for :func:`load_usage_config`
        (``None``: the shipped ``temi_usage.yaml``).
    seed : int, numpy.random.Generator or None
        Seed or generator; the same seed and config give the same profile.
    max_duration_s : float, optional
        Stop once the profile lasts this long (s). The last point is
        shortened so that the total is exactly ``max_duration_s``.
    max_charge_ah : float, optional
        Stop once this much charge (Ah) is drawn; the last point is
        shortened so that the charge is exactly ``max_charge_ah``.
    max_points : int, optional
        Stop after this many curve points.

    Returns
    -------
    LoadProfile
        Labels are the usage state of each point. Metadata holds the robot,
        seed, config path, state probabilities and ``stop_voltage_v``.

    Raises
    ------
    ProfileError
        If no stop condition is given or a limit is not finite and > 0.

    Notes
    -----
    Whichever limit is reached first ends the profile. Points are drawn in
    chunks of :data:`CHUNK_POINTS`, so with the same seed a shorter profile
    is a prefix of a longer one (apart from the shortened last point).
    """
    if config is None or isinstance(config, str | Path):
        config = load_usage_config(config)
    max_duration_s = _check_limit("max_duration_s", max_duration_s)
    max_charge_ah = _check_limit("max_charge_ah", max_charge_ah)
    max_points = _check_max_points(max_points)
    if max_duration_s is None and max_charge_ah is None and max_points is None:
        raise ProfileError("temi profile: give at least one of max_duration_s, max_charge_ah, max_points")

    rng = np.random.default_rng(seed)
    probabilities = np.array([config.probabilities[s] for s in STATES])
    states_parts, duration_parts, current_parts = [], [], []
    n_total, t_total, q_total = 0, 0.0, 0.0
    while True:
        index, durations, currents = _draw_chunk(config, probabilities, rng)
        states_parts.append(index)
        duration_parts.append(durations)
        current_parts.append(currents)
        n_total += CHUNK_POINTS
        t_total += float(durations.sum())
        q_total += float(durations @ currents) / 3600.0
        if (
            (max_points is not None and n_total >= max_points)
            or (max_duration_s is not None and t_total >= max_duration_s)
            or (max_charge_ah is not None and q_total >= max_charge_ah)
        ):
            break
        if n_total >= MAX_GENERATED_POINTS:
            raise ProfileError(f"temi profile: more than {MAX_GENERATED_POINTS} points needed; lower the limits")

    index = np.concatenate(states_parts)
    durations = np.concatenate(duration_parts)
    currents = np.concatenate(current_parts)
    n_keep, last_duration = _cut(durations, currents, max_duration_s, max_charge_ah, max_points)
    durations = durations[:n_keep].copy()
    if last_duration is not None:
        durations[-1] = last_duration
    labels = tuple(STATES[k] for k in index[:n_keep])
    metadata = {
        "robot": "temi",
        "generator": "temi_usage",
        "seed": int(seed) if isinstance(seed, int | np.integer) else None,
        "config": config.source,
        "probabilities": dict(config.probabilities),
        "limits": {"max_duration_s": max_duration_s, "max_charge_ah": max_charge_ah, "max_points": max_points},
        "stop_voltage_v": config.stop_voltage_v,
    }
    return LoadProfile(durations, currents[:n_keep], labels, metadata)


def _check_max_points(max_points: int | None) -> int | None:
    """``max_points`` as an int, or None; raises :class:`ProfileError` unless it is an integer >= 1."""
    if max_points is None:
        return None
    if isinstance(max_points, bool) or not isinstance(max_points, int | np.integer) or max_points < 1:
        raise ProfileError(f"temi profile: max_points is {max_points!r} (must be an integer >= 1)")
    return int(max_points)


def _draw_chunk(config: TemiUsageConfig, probabilities: np.ndarray,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:data:`CHUNK_POINTS` usage points: state indices into :data:`STATES` (drawn with ``probabilities``, in
    :data:`STATES` order), durations (s) and currents (A).

    The states are drawn first, then every state's durations, then every state's currents (this order fixes what
    a seed gives).
    """
    index = rng.choice(len(STATES), size=CHUNK_POINTS, p=probabilities)
    durations = np.empty(CHUNK_POINTS)
    currents = np.empty(CHUNK_POINTS)
    masks = [index == k for k in range(len(STATES))]
    for k, state in enumerate(STATES):
        durations[masks[k]] = config.duration_distribution(state).sample(int(masks[k].sum()), rng)
    for k, state in enumerate(STATES):
        currents[masks[k]] = config.current_distribution(state).sample(int(masks[k].sum()), rng)
    return index, durations, currents


def _cut(
    durations: np.ndarray,
    currents: np.ndarray,
    max_duration_s: float | None,
    max_charge_ah: float | None,
    max_points: int | None,
) -> tuple[int, float | None]:
    """Number of points to keep and the shortened duration of the last one (None: unchanged)."""
    candidates: list[tuple[int, float]] = []
    if max_points is not None:
        candidates.append((max_points, math.inf))
    for limit, per_point in ((max_duration_s, durations), (max_charge_ah, durations * currents / 3600.0)):
        if limit is None:
            continue
        cumulative = np.cumsum(per_point)
        i = int(np.searchsorted(cumulative, limit, side="left"))
        if i >= len(cumulative):
            continue
        before = cumulative[i - 1] if i else 0.0
        fraction = (limit - before) / per_point[i]
        candidates.append((i + 1, float(durations[i] * fraction)))
    n_keep, last = min(candidates)
    if math.isinf(last):
        return n_keep, None
    return n_keep, min(last, float(durations[n_keep - 1]))
