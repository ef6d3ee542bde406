"""Paths stored in artefacts (bag metadata, reports): relative, never absolute paths of the machine that wrote them.

Rule of :func:`portable_path`: an absolute path below the repository or the working directory becomes
relative to it; any other absolute path that exists on this machine is reduced to its file name
(``sqlite:///`` URLs likewise); every other string, such as the ROS topic ``/battery_state``, is kept.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

#: The repository (source tree) this package lives in.
REPO_ROOT = Path(__file__).resolve().parents[2]
_URL_PREFIXES = ("sqlite:///",)


def portable_path(text: str, roots: Sequence[Path] | None = None) -> str:
    """``text`` with an absolute path made relative (see the module docstring); other text unchanged."""
    prefix = next((p for p in _URL_PREFIXES if text.startswith(p)), "")
    path_text = text[len(prefix):]
    if not path_text.startswith("/") or "\n" in path_text:
        return text
    path = Path(path_text)
    for root in roots if roots is not None else (REPO_ROOT, Path.cwd()):
        if path.is_relative_to(root) and path != root:
            return prefix + str(path.relative_to(root))
    if path.exists() and path.name:
        return prefix + path.name
    return text


def portable_paths(value: Any, roots: Sequence[Path] | None = None) -> Any:
    """:func:`portable_path` applied to every string (and dict key) in nested dicts, lists and tuples."""
    if isinstance(value, str):
        return portable_path(value, roots)
    if isinstance(value, dict):
        return {portable_paths(k, roots): portable_paths(v, roots) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(portable_paths(v, roots) for v in value)
    return value
