"""The train station as a graph of locations and paths (seed paper sections 3 and 5.2.2).

Nodes are named locations (``charger``, ``platform11_south``...), edges are
undirected barrier-free paths made of segments with a length in m and a slope
(``flat``, ``uphill`` or ``downhill`` in the edge's ``from -> to``
direction). The luggage robot's routes follow shortest paths
(:meth:`Station.shortest_path`, Dijkstra) or the paths of least cost under any
per-segment cost (:meth:`Station.least_cost_path`, e.g. the charge a payload
draws). Nodes may carry a position (``x_m``, ``y_m`` in a local frame, m), so
that a robot's position maps to the nearest node (:meth:`Station.nearest_node`).
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from battery_predictor.config import (
    as_float,
    check_unknown,
    default_params_file,
    read_yaml_mapping,
    require,
)
from battery_predictor.errors import ParamsError, ProfileError

FLAT = "flat"
UPHILL = "uphill"
DOWNHILL = "downhill"
#: Slope classes, as measured on the CITEC test track (section 5.2.1).
SLOPES = (FLAT, UPHILL, DOWNHILL)
_REVERSED_SLOPE = {FLAT: FLAT, UPHILL: DOWNHILL, DOWNHILL: UPHILL}

#: Default params file shipped with the package.
DEFAULT_STATION_FILE = "minden_station.yaml"


def check_slope(slope: str) -> str:
    """Return ``slope`` if it is one of :data:`SLOPES`, else raise ProfileError."""
    if slope not in SLOPES:
        raise ProfileError(f"unknown slope {slope!r} (expected one of {', '.join(SLOPES)})")
    return slope


@dataclass(frozen=True)
class Segment:
    """A stretch of path with one slope.

    Attributes
    ----------
    length_m : float
        Length in m, > 0.
    slope : str
        ``flat``, ``uphill`` or ``downhill`` in the direction of travel.
    """

    length_m: float
    slope: str

    def __post_init__(self) -> None:
        check_slope(self.slope)
        try:
            length = float(self.length_m)
        except (TypeError, ValueError):
            raise ProfileError(f"segment length_m is {self.length_m!r} (must be a number)") from None
        if not length > 0.0 or length == float("inf"):
            raise ProfileError(f"segment length_m is {self.length_m!r} (must be finite and > 0)")
        object.__setattr__(self, "length_m", length)

    def reversed(self) -> Segment:
        """The same segment travelled the other way (uphill and downhill swap)."""
        return Segment(self.length_m, _REVERSED_SLOPE[self.slope])


@dataclass(frozen=True)
class Edge:
    """An undirected path between two nodes; ``segments`` run from ``start`` to ``end``."""

    start: str
    end: str
    segments: tuple[Segment, ...]
    source: str = ""

    @property
    def length_m(self) -> float:
        """Total length in m."""
        return sum(segment.length_m for segment in self.segments)

    def segments_from(self, node: str) -> tuple[Segment, ...]:
        """Segments in the direction of travel when leaving ``node``."""
        if node == self.start:
            return self.segments
        if node == self.end:
            return tuple(segment.reversed() for segment in reversed(self.segments))
        raise ProfileError(f"edge {self.start}-{self.end} does not touch {node!r}")

    def other(self, node: str) -> str:
        """The node at the other end from ``node``."""
        return self.end if node == self.start else self.start


@dataclass(frozen=True)
class StationPath:
    """A path through the station.

    Attributes
    ----------
    nodes : tuple of str
        Visited nodes, first is the start, last the destination.
    segments : tuple of Segment
        Segments in the direction of travel; consecutive segments of equal
        slope (also across edges) are merged into one.
    """

    nodes: tuple[str, ...]
    segments: tuple[Segment, ...]

    @property
    def length_m(self) -> float:
        """Total length in m."""
        return sum(segment.length_m for segment in self.segments)

    def length_by_slope_m(self) -> dict[str, float]:
        """Length in m per slope class (every class present, possibly 0)."""
        totals = dict.fromkeys(SLOPES, 0.0)
        for segment in self.segments:
            totals[segment.slope] += segment.length_m
        return totals


class Station:
    """Station graph with shortest-path queries.

    Parameters
    ----------
    nodes : dict
        Node name -> description.
    edges : sequence of Edge
        Paths between nodes; both ends must be known nodes.
    source : str
        Where the graph came from (used in messages).
    positions : dict, optional
        Node name -> ``(x_m, y_m)`` in a local frame, m; nodes without one are never the nearest
        node of a position.
    """

    def __init__(self, nodes: dict[str, str], edges: tuple[Edge, ...] | list[Edge], source: str = "<memory>",
                 positions: dict[str, tuple[float, float]] | None = None) -> None:
        self.nodes = dict(nodes)
        self.edges = tuple(edges)
        self.source = source
        self.positions: dict[str, tuple[float, float]] = {}
        for name, xy in (positions or {}).items():
            if name not in self.nodes:
                raise ProfileError(f"{source}: position given for unknown node {name!r}")
            x, y = (float(v) for v in xy)
            if not (math.isfinite(x) and math.isfinite(y)):
                raise ProfileError(f"{source}: position of {name!r} is not finite")
            self.positions[name] = (x, y)
        self._adjacent: dict[str, list[Edge]] = {name: [] for name in self.nodes}
        for edge in self.edges:
            for node in (edge.start, edge.end):
                if node not in self.nodes:
                    raise ProfileError(f"{source}: edge {edge.start}-{edge.end} uses unknown node {node!r}")
            if edge.start == edge.end:
                raise ProfileError(f"{source}: edge {edge.start}-{edge.end} is a loop")
            self._adjacent[edge.start].append(edge)
            self._adjacent[edge.end].append(edge)

    def check_node(self, node: str) -> str:
        """Return ``node`` if it exists, else raise ProfileError listing the known nodes."""
        if node not in self.nodes:
            raise ProfileError(f"{self.source}: unknown location {node!r} (known: {', '.join(sorted(self.nodes))})")
        return node

    def shortest_path(self, start: str, goal: str) -> StationPath:
        """Shortest path from ``start`` to ``goal`` (Dijkstra on edge lengths).

        Raises
        ------
        ProfileError
            If a node is unknown or ``goal`` cannot be reached.
        """
        return self.least_cost_path(start, goal, lambda segment: segment.length_m)

    def least_cost_path(self, start: str, goal: str, segment_cost: Callable[[Segment], float]) -> StationPath:
        """Path of least total cost from ``start`` to ``goal`` (Dijkstra).

        Parameters
        ----------
        start, goal : str
            Node names.
        segment_cost : callable
            Cost of one segment in the direction of travel (``Segment -> float``, >= 0; e.g. its
            length in m, or the charge in Ah a payload draws on it). Ties go to the first path found.

        Raises
        ------
        ProfileError
            If a node is unknown, ``goal`` cannot be reached, or a cost is negative or not finite.
        """
        self.check_node(start)
        self.check_node(goal)
        best = {start: 0.0}
        previous: dict[str, tuple[str, Edge]] = {}
        queue: list[tuple[float, int, str]] = [(0.0, 0, start)]
        pushed = 1
        done: set[str] = set()
        while queue:
            distance, _, node = heapq.heappop(queue)
            if node in done:
                continue
            done.add(node)
            if node == goal:
                break
            for edge in self._adjacent[node]:
                neighbour = edge.other(node)
                cost = 0.0
                for segment in edge.segments_from(node):
                    c = float(segment_cost(segment))
                    if not (math.isfinite(c) and c >= 0.0):
                        raise ProfileError(f"{self.source}: segment cost {c!r} on {node}-{neighbour} "
                                           "(must be finite and >= 0)")
                    cost += c
                candidate = distance + cost
                if candidate < best.get(neighbour, float("inf")):
                    best[neighbour] = candidate
                    previous[neighbour] = (node, edge)
                    heapq.heappush(queue, (candidate, pushed, neighbour))
                    pushed += 1
        if goal not in done:
            raise ProfileError(f"{self.source}: no path from {start} to {goal}")
        hops: list[tuple[str, Edge]] = []
        node = goal
        while node != start:
            node, edge = previous[node]
            hops.append((node, edge))
        hops.reverse()
        nodes = [start] + [edge.other(node) for node, edge in hops]
        segments: list[Segment] = []
        for node, edge in hops:
            for segment in edge.segments_from(node):
                if segments and segments[-1].slope == segment.slope:
                    segments[-1] = Segment(segments[-1].length_m + segment.length_m, segment.slope)
                else:
                    segments.append(segment)
        return StationPath(tuple(nodes), tuple(segments))

    def nearest_node(self, x_m: float, y_m: float) -> tuple[str, float]:
        """The node nearest to the position ``(x_m, y_m)`` (m, the graph's frame) and its distance in m.

        Raises
        ------
        ProfileError
            If the position is not finite or the graph gives no node positions.
        """
        if not (math.isfinite(x_m) and math.isfinite(y_m)):
            raise ProfileError(f"position ({x_m}, {y_m}) is not finite")
        if not self.positions:
            raise ProfileError(f"{self.source}: the station gives no node positions (x_m, y_m), so a position "
                               "cannot be mapped to a node; name the node instead")
        name, (x, y) = min(self.positions.items(), key=lambda kv: math.hypot(kv[1][0] - x_m, kv[1][1] - y_m))
        return name, math.hypot(x - x_m, y - y_m)

    def farthest_from(self, goal: str) -> tuple[str, float]:
        """The node whose shortest path to ``goal`` is longest, and that length in m (reachable nodes only)."""
        self.check_node(goal)
        far, far_m = goal, 0.0
        for node in self.nodes:
            try:
                d = self.distance_m(node, goal)
            except ProfileError:
                continue
            if d > far_m:
                far, far_m = node, d
        return far, far_m

    def distance_m(self, start: str, goal: str) -> float:
        """Length in m of the shortest path from ``start`` to ``goal``."""
        return self.shortest_path(start, goal).length_m

    def __repr__(self) -> str:
        return f"Station({self.source!r}, {len(self.nodes)} nodes, {len(self.edges)} edges)"


def default_station_path() -> Path:
    """Path of the shipped ``minden_station.yaml``."""
    return default_params_file(DEFAULT_STATION_FILE)


def load_station(path: str | Path | None = None) -> Station:
    """Read a station YAML (default: the shipped ``minden_station.yaml``).

    Raises
    ------
    ParamsError
        If a key is missing or unknown, a node is undefined, a length is not
        > 0 or a slope unknown; the message names the file and the key.
    """
    path, data = read_yaml_mapping(default_station_path() if path is None else path)
    check_unknown(data, {"nodes", "edges"}, path, "")
    nodes_data = require(data, "nodes", path, "")
    if not isinstance(nodes_data, dict) or not nodes_data:
        raise ParamsError(f"{path}: nodes must be a non-empty mapping of name to description")
    nodes: dict[str, str] = {}
    positions: dict[str, tuple[float, float]] = {}
    for name, value in nodes_data.items():
        where = f"nodes.{name}"
        if isinstance(value, dict):  # {description, x_m, y_m}
            check_unknown(value, {"description", "x_m", "y_m"}, path, where)
            nodes[str(name)] = str(value.get("description", ""))
            if ("x_m" in value) != ("y_m" in value):
                raise ParamsError(f"{path}: {where} needs both x_m and y_m (or neither)")
            if "x_m" in value:
                positions[str(name)] = (as_float(value["x_m"], path, f"{where}.x_m"),
                                        as_float(value["y_m"], path, f"{where}.y_m"))
        else:
            nodes[str(name)] = str(value)
    edges_data = require(data, "edges", path, "")
    if not isinstance(edges_data, list):
        raise ParamsError(f"{path}: edges must be a list")
    edges: list[Edge] = []
    for i, item in enumerate(edges_data):
        where = f"edges[{i}]"
        if not isinstance(item, dict):
            raise ParamsError(f"{path}: {where} must be a mapping")
        check_unknown(item, {"from", "to", "segments", "source"}, path, where)
        ends = []
        for key in ("from", "to"):
            node = require(item, key, path, where)
            if node not in nodes:
                raise ParamsError(f"{path}: {where}.{key} is {node!r}, not a node defined under nodes")
            ends.append(node)
        if ends[0] == ends[1]:
            raise ParamsError(f"{path}: {where} connects {ends[0]} to itself")
        segments_data = require(item, "segments", path, where)
        if not isinstance(segments_data, list) or not segments_data:
            raise ParamsError(f"{path}: {where}.segments must be a non-empty list")
        segments = []
        for j, seg in enumerate(segments_data):
            seg_where = f"{where}.segments[{j}]"
            if not isinstance(seg, dict):
                raise ParamsError(f"{path}: {seg_where} must be a mapping with length_m and slope")
            check_unknown(seg, {"length_m", "slope"}, path, seg_where)
            length = as_float(require(seg, "length_m", path, seg_where), path, f"{seg_where}.length_m",
                              minimum=0.0, strict=True)
            slope = require(seg, "slope", path, seg_where)
            if slope not in SLOPES:
                raise ParamsError(f"{path}: {seg_where}.slope is {slope!r}, expected one of {', '.join(SLOPES)}")
            segments.append(Segment(length, slope))
        edges.append(Edge(ends[0], ends[1], tuple(segments), str(item.get("source", ""))))
    return Station(nodes, edges, source=str(path), positions=positions)
