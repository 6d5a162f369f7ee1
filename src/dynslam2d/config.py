"""The project configuration: one pydantic model per stage, YAML in and out.

``Config`` nests the per-stage models: ``slam``, ``detect`` (segmentation, fit,
tracker) and ``filter``. ``dynslam2d config dump`` prints the defaults;
``dynslam2d run --config FILE.yaml`` reads a (partial) file of the same shape,
and ``config.yaml`` in every results folder holds the full effective values.
"""

from __future__ import annotations

import math
import os
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from dynslam2d.errors import DynSlamError
from dynslam2d.io.yamlfile import read_yaml_mapping
from dynslam2d.detect.config import DetectConfig
from dynslam2d.filter import FilterConfig
from dynslam2d.slam.config import SlamConfig
from dynslam2d.slam.cleanconfig import CleanConfig


class Config(BaseModel):
    """Every tunable of a dynslam2d run, grouped by stage."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)

    slam: SlamConfig = Field(default_factory=SlamConfig, description="Hector-style SLAM (map, matcher, processor).")
    detect: DetectConfig = Field(
        default_factory=DetectConfig, description="Segmentation, shape fit, tracking and the dynamic set M."
    )
    filter: FilterConfig = Field(default_factory=FilterConfig, description="Dynamic-point filter (paper Eq. 4-8).")
    clean: CleanConfig = Field(
        default_factory=CleanConfig, description="Offline map clean-up after the run (docs/maps.md)."
    )


def _describe(err: ValidationError) -> str:
    parts = []
    for e in err.errors():
        where = ".".join(str(p) for p in e["loc"]) or "(top level)"
        value = e.get("input")
        if isinstance(value, float) and not math.isfinite(value):
            parts.append(f"{where}: must be a finite number, got {value}")
            continue
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
    data = read_yaml_mapping(path, "configuration")
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
