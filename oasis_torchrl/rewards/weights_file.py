"""The reward networks' weights files (the small depth network's, the motion network's): one
``torch.save`` dict with a ``format`` tag, the network's config, its weights and how it was
trained (``meta``), read back with the tag and every weight's shape checked.

Example:
    >>> import tempfile
    >>> net = torch.nn.Linear(2, 1)
    >>> path = write_weights(f"{tempfile.mkdtemp()}/w.pt", "doc 1", net, {"in": 2}, {"seed": 0})
    >>> payload = read_weights(path, "doc 1")
    >>> payload["config"], payload["meta"]
    ({'in': 2}, {'seed': 0})
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import torch


def write_weights(
    path: str | os.PathLike[str],
    file_format: str,
    net: torch.nn.Module,
    config: dict[str, Any],
    meta: dict[str, Any] | None = None,
    **extra: Any,
) -> Path:
    """Write ``net``'s weights with ``config``, ``meta`` and ``extra`` entries to ``path`` (its
    folder made), tagged ``file_format``; returns the path."""
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "format": file_format,
        "config": config,
        **extra,
        "state_dict": {key: value.detach().cpu() for key, value in net.state_dict().items()},
        "meta": dict(meta or {}),
    }
    torch.save(payload, target)
    return target


def read_weights(path: str | os.PathLike[str], file_format: str) -> dict[str, Any]:
    """The dict :func:`write_weights` wrote to ``path``; a ValueError when it is not tagged
    ``file_format`` (the caller turns any failure into its one-line error).

    >>> import tempfile
    >>> path = write_weights(f"{tempfile.mkdtemp()}/w.pt", "a 1", torch.nn.Linear(1, 1), {})
    >>> read_weights(path, "b 1")
    Traceback (most recent call last):
    ...
    ValueError: not a weights file of 'b 1'
    """
    payload = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(payload, dict) or payload.get("format") != file_format:
        raise ValueError(f"not a weights file of {file_format!r}")
    return payload


def check_fits(net: torch.nn.Module, state: dict[str, torch.Tensor]) -> None:
    """Refuse a state dict whose names or shapes differ from ``net``'s, naming the first misfit.

    >>> check_fits(torch.nn.Linear(2, 1), {"weight": torch.zeros(1, 3), "bias": torch.zeros(1)})
    Traceback (most recent call last):
    ...
    ValueError: the weights do not fit their config: weight is [1, 3], not [1, 2]
    """
    expected = net.state_dict()
    for name in sorted(expected.keys() | state.keys()):
        if name not in state or name not in expected:
            where = "missing from the file" if name not in state else "not in the network"
            problem = f"{name} is {where}"
        elif state[name].shape != expected[name].shape:
            problem = f"{name} is {list(state[name].shape)}, not {list(expected[name].shape)}"
        else:
            continue
        raise ValueError(f"the weights do not fit their config: {problem}")
