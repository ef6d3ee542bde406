"""Checks of node parameter files shared by ``run``, ``replay`` and ``demo``."""

from __future__ import annotations

from pathlib import Path

import yaml

from battery_predictor.errors import ParamsError

#: Node names the params files configure.
NODE_NAMES = ("battery_monitor", "predictor")


def check_node_params_file(path: str) -> Path:
    """A readable ``node_name: ros__parameters:`` YAML; a clear error for a pack params file or a typo'd layout."""
    p = Path(path)
    if not p.is_file():
        raise ParamsError(f"{p}: node params file not found")
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise ParamsError(f"{p}: not valid YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(data, dict):
        raise ParamsError(f"{p}: expected a mapping of node names to ros__parameters")
    if "pack" in data and "cell" in data:
        raise ParamsError(f"{p}: this is a pack params file; pass node params such as params/ros/temi_nodes.yaml "
                          f"(with predictor.ros__parameters.params_file pointing to it) or use --pack {p}")
    for name, section in data.items():
        key = str(name).lstrip("/")
        if key != "**" and key.split("/")[-1] not in NODE_NAMES:
            raise ParamsError(f"{p}: unknown node '{name}' (expected {', '.join(NODE_NAMES)} or /**)")
        if not isinstance(section, dict) or "ros__parameters" not in section:
            raise ParamsError(f"{p}: '{name}' has no ros__parameters section")
    return p
