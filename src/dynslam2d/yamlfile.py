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
    except UnicodeDecodeError as exc:
        raise DynSlamError(
            f"{path}: {what} file is not UTF-8 text (byte {exc.start}: {exc.object[exc.start:exc.start + 1]!r}); "
            f"save it as UTF-8"
        ) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        where = f":{mark.line + 1}:{mark.column + 1}" if mark is not None else ""
        problem = exc.problem or exc.context or "syntax error"
        raise DynSlamError(f"{path}{where}: cannot read {what}: not valid YAML ({problem}); fix the syntax "
                           f"there") from None
    except (OSError, yaml.YAMLError) as exc:
        text = " ".join(str(getattr(exc, "strerror", None) or exc).split())
        raise DynSlamError(f"{path}: cannot read {what} ({text})") from exc
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise DynSlamError(f"{path}: {what} must be a YAML mapping, got {type(data).__name__}")
    return data
