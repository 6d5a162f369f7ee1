"""Reading YAML mappings with errors that name the file."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml

from dynslam2d.errors import DynSlamError


def read_yaml_mapping(path: str | os.PathLike[str], what: str) -> dict[str, Any]:
    """Parse ``path`` as a YAML mapping (an empty file gives ``{}``).

    ``what`` names the file's role in error messages ("configuration", "map YAML").
    """
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise DynSlamError(f"{path}: {what} file not found") from exc
    except (OSError, yaml.YAMLError) as exc:
        raise DynSlamError(f"{path}: cannot read {what} ({exc})") from exc
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise DynSlamError(f"{path}: {what} must be a YAML mapping, got {type(data).__name__}")
    return data
