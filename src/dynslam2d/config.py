"""The project configuration: one pydantic model per stage, YAML in and out.

``Config`` nests the per-stage models (today: ``slam``; detection, tracking and
filtering join it as they land). ``dynslam2d config dump`` prints the defaults;
``dynslam2d run --config FILE.yaml`` reads a (partial) file of the same shape,
and ``config.yaml`` in every results folder holds the full effective values.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from dynslam2d.errors import DynSlamError
from dynslam2d.slam.config import SlamConfig


class Config(BaseModel):
    """Every tunable of a dynslam2d run, grouped by stage."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    slam: SlamConfig = Field(default_factory=SlamConfig, description="Hector-style SLAM (map, matcher, processor).")


def _describe(err: ValidationError) -> str:
    parts = []
    for e in err.errors():
        where = ".".join(str(p) for p in e["loc"]) or "(top level)"
        parts.append(f"{where}: {e['msg']}")
    return "; ".join(parts)


def config_from_dict(data: dict[str, Any], origin: str = "<config>") -> Config:
    """Validate a (partial) nested dict into a Config; errors name ``origin`` and the key."""
    try:
        return Config.model_validate(data)
    except ValidationError as exc:
        raise DynSlamError(f"{origin}: invalid configuration: {_describe(exc)}") from exc


def load_config(path: str | os.PathLike[str]) -> Config:
    """Read a YAML configuration file (any subset of the keys ``config dump`` prints)."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise DynSlamError(f"{path}: configuration file not found") from exc
    except (OSError, yaml.YAMLError) as exc:
        raise DynSlamError(f"{path}: cannot read configuration ({exc})") from exc
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise DynSlamError(f"{path}: configuration must be a YAML mapping, got {type(data).__name__}")
    return config_from_dict(data, origin=str(path))


def with_overrides(config: Config, overrides: dict[str, dict[str, Any]]) -> Config:
    """A copy of ``config`` with ``{stage: {field: value}}`` replaced (None values ignored)."""
    data = config.model_dump()
    for stage, fields in overrides.items():
        for key, value in fields.items():
            if value is not None:
                data[stage][key] = value
    return config_from_dict(data, origin="command-line options")


def dump_config(config: Config) -> str:
    """The full configuration as YAML text (stable key order: the models' field order)."""
    return yaml.safe_dump(config.model_dump(mode="json"), sort_keys=False)
