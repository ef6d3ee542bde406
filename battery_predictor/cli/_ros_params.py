"""Checks of node parameter files shared by ``run``, ``replay`` and ``demo``."""

from __future__ import annotations

from pathlib import Path

from battery_predictor.config import read_yaml_mapping, yaml_number
from battery_predictor.errors import ParamsError
from battery_predictor.params import PackParams

#: Node names the params files configure.
NODE_NAMES = ("battery_monitor", "predictor")


def check_node_params_file(path: str, *, pack: str | None = None) -> PackParams | None:
    """Check a ``node_name: ros__parameters:`` YAML whose settings fit the pack it names; returns that pack.

    Clear errors for a pack params file, a typo'd layout, a pack params file that cannot be
    found (``predictor.params_file``, or ``pack`` when given), and node settings that contradict
    the pack (:func:`check_nodes_against_pack`). Returns the pack params the predictor loads
    (``pack`` when given), or None when the file names none.
    """
    p = Path(path)
    if not p.is_file():
        raise ParamsError(f"{p}: node params file not found")
    p, data = read_yaml_mapping(p, not_mapping="expected a mapping of node names to ros__parameters")
    if "pack" in data and "cell" in data:
        raise ParamsError(f"{p}: this is a pack params file; pass node params such as params/ros/temi_nodes.yaml "
                          f"(with predictor.ros__parameters.params_file pointing to it) or use --pack {p}")
    for name, section in data.items():
        key = str(name).lstrip("/")
        if key != "**" and key.split("/")[-1] not in NODE_NAMES:
            raise ParamsError(f"{p}: unknown node '{name}' (expected {', '.join(NODE_NAMES)} or /**)")
        if not isinstance(section, dict) or "ros__parameters" not in section:
            raise ParamsError(f"{p}: '{name}' has no ros__parameters section")
    return check_nodes_against_pack(p, _node_parameters(data, "battery_monitor"), _node_parameters(data, "predictor"),
                                    pack=pack)


def _node_parameters(data: dict, node: str) -> dict:
    """The parameters a node gets from the file: ``/**`` first, then its own section."""
    out: dict = {}
    for name, section in data.items():
        key = str(name).lstrip("/")
        if key == "**" or key.split("/")[-1] == node:
            out.update(section.get("ros__parameters") or {})
    return out


def check_nodes_against_pack(source: Path, monitor: dict, predictor: dict, *,
                             pack: str | None = None) -> PackParams | None:
    """Raise :class:`ParamsError` when the nodes' settings cannot work with the pack the predictor loads.

    The pack params file must load; the monitor's ``min_voltage_v..max_voltage_v`` must cover the pack's
    voltage window; the predictor's non-zero ``cutoff_voltage_v`` and ``route_min_voltage_v`` must lie in it.
    Returns the loaded pack params (``pack`` when given), or None when no pack is named.
    """
    from battery_predictor.config import resolve_params_file
    from battery_predictor.params import load_params
    from battery_predictor.params_checks import check_monitor_range, check_node_voltages

    name = pack or str(predictor.get("params_file", "") or "")
    if not name:
        return None
    resolved = Path(resolve_params_file(name))
    if not resolved.is_file():
        where = "--pack" if pack else f"{source}: predictor.params_file"
        raise ParamsError(f"{where} {name!r}: pack params file not found (a path, or a bundled name such as "
                          "temi.yaml)")
    params = load_params(resolved)
    if "min_voltage_v" in monitor or "max_voltage_v" in monitor:
        low, high = (yaml_number(monitor.get(key, default), source, f"battery_monitor.{key}", allow_nan=True)
                     for key, default in (("min_voltage_v", 0.0), ("max_voltage_v", 100.0)))
        check_monitor_range(low, high, params, str(source))
    check_node_voltages(str(source), params, {
        f"predictor.{key}": yaml_number(predictor.get(key, 0.0) or 0.0, source, f"predictor.{key}", allow_nan=True)
        for key in ("cutoff_voltage_v", "route_min_voltage_v")})
    return params
