"""Argument checks shared by the env classes: each bad argument raises a Python exception
naming it, before anything reaches Rust."""

from __future__ import annotations

import json
import numbers
import os
from pathlib import Path


def check_setup(setup) -> str:
    if not isinstance(setup, str):
        raise TypeError(
            f"setup: expected a string N.M_K (robots.machines_storages, e.g. '14.10_4'), "
            f"got {type(setup).__name__}"
        )
    return setup


def check_seed(seed, name: str = "seed") -> int:
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise TypeError(f"{name}: expected an integer, got {type(seed).__name__}")
    seed = int(seed)
    if not 0 <= seed < 2**64:
        raise ValueError(f"{name}: {seed} is outside 0..2**64")
    return seed


def config_args(config) -> tuple[str | None, str | None]:
    """(TOML text, JSON text) for the Rust side from ``config``: None (the defaults of
    sim/src/config.rs), a dict of sections ({"task": {"k_speed": 0.4}}), TOML text, or a
    path to a TOML file (str ending in .toml or os.PathLike)."""
    if config is None:
        return None, None
    if isinstance(config, dict):
        try:
            return None, json.dumps(config)
        except TypeError as e:
            raise TypeError(f"config: the dict is not plain data: {e}") from None
    if isinstance(config, os.PathLike) or (
        isinstance(config, str) and "\n" not in config and config.strip().endswith(".toml")
    ):
        path = Path(config)
        if not path.is_file():
            raise FileNotFoundError(f"config: no such file: {path}")
        return path.read_text(), None
    if isinstance(config, str):
        return config, None
    raise TypeError(
        "config: expected None, a dict, TOML text or a path to a .toml file, "
        f"got {type(config).__name__}"
    )
