"""The project configuration: one pydantic model per stage, YAML in and out.

``Config`` nests the per-stage models: ``slam``, ``detect`` (segmentation, fit,
tracker) and ``filter``. ``dynslam2d config dump`` prints the defaults as commented
YAML (:func:`dump_config`: each key's meaning and unit from its pydantic ``description``,
its hector_mapping parameter and its ``dynslam2d run`` option);
``dynslam2d run --config FILE.yaml`` reads a (partial) file of the same shape, where
hector_mapping's parameter names are accepted too (:data:`HECTOR_NAMES`), and
``config.yaml`` in every results folder holds the full effective values.

One family of names: a ``dynslam2d run`` option is its config key with ``-`` for ``_``
(``slam.map_update_distance_thresh`` ↔ ``--map-update-distance-thresh``,
``filter.mode`` ↔ ``--filter-mode``); :data:`RUN_OPTIONS` lists them with their short forms.
"""

from __future__ import annotations

import math
import os
from typing import Any

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from dynslam2d.detect.config import DetectConfig
from dynslam2d.errors import DynSlamError
from dynslam2d.filter import FilterConfig
from dynslam2d.laserconfig import LaserConfig
from dynslam2d.slam.cleanconfig import CleanConfig
from dynslam2d.slam.config import SlamConfig
from dynslam2d.slam.loopconfig import LoopConfig
from dynslam2d.yamlfile import read_yaml_mapping

#: hector_mapping ROS parameter → our ``slam`` key (hector_mapping's HectorMappingRos.cpp;
#: the list is in docs/slam.md). In ``--config`` these names are accepted inside ``slam:``
#: and, as in a hector_mapping parameter file, at the top level.
HECTOR_NAMES: dict[str, str] = {
    "map_resolution": "map_resolution",
    "map_multi_res_levels": "map_levels",
    "update_factor_free": "update_factor_free",
    "update_factor_occupied": "update_factor_occupied",
    "map_update_distance_thresh": "map_update_distance_thresh",
    "map_update_angle_thresh": "map_update_angle_thresh",
    "laser_min_dist": "laser_min_dist",
    "laser_max_dist": "laser_max_dist",
}

#: Keys whose value hector_mapping hard-codes (no ROS parameter): shown in ``config dump``.
HECTOR_HARD_CODED: dict[str, str] = {
    "slam.occupied_logodds_cap": "hector_mapping: hard-coded 50",
    "slam.iterations_coarse": "hector_mapping: hard-coded 1 + 3",
    "slam.iterations_finest": "hector_mapping: hard-coded 1 + 5",
    "slam.max_rotation_step": "hector_mapping: hard-coded ±0.2 rad",
}

#: ``dynslam2d run`` options that set a config key: key → (option, its short form or None).
#: The option is always the key's last part with ``-`` for ``_`` (``filter.mode``: ``--filter-mode``).
RUN_OPTIONS: dict[str, tuple[str, str | None]] = {
    "slam.map_resolution": ("--map-resolution", None),
    "slam.map_levels": ("--map-levels", None),
    "slam.map_update_distance_thresh": ("--map-update-distance-thresh", "--update-distance"),
    "slam.map_update_angle_thresh": ("--map-update-angle-thresh", "--update-angle"),
    "slam.laser_min_dist": ("--laser-min-dist", None),
    "slam.laser_max_dist": ("--laser-max-dist", None),
    "slam.constant_velocity": ("--constant-velocity", None),
    "slam.correlative_mode": ("--correlative-mode", "--correlative"),
    "filter.mode": ("--filter-mode", "--filter"),
    "laser.range_scale": ("--laser-range-scale", "--range-scale"),
}


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
    laser: LaserConfig = Field(
        default_factory=LaserConfig, description="The lidar itself: range scale (docs/slam.md)."
    )
    loop: LoopConfig = Field(
        default_factory=LoopConfig, description="Loop closure and pose-graph optimisation behind the front end "
        "(docs/slam.md, \"Loop closure\")."
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


def _with_hector_names(data: dict[str, Any], origin: str) -> dict[str, Any]:
    """``data`` with hector_mapping parameter names (top level or in ``slam:``) moved onto our
    ``slam`` keys; a value given under both names is an error naming both."""
    if not isinstance(data, dict) or not isinstance(data.get("slam", {}), dict):
        return data
    out = dict(data)
    slam = dict(out.get("slam", {}))
    moves = [(k, out, f"{k} (top level)") for k in list(out) if k in HECTOR_NAMES]
    moves += [(k, slam, f"slam.{k}") for k in list(slam) if k in HECTOR_NAMES and HECTOR_NAMES[k] != k]
    for key, where, label in moves:
        value = where.pop(key)
        ours = HECTOR_NAMES[key]
        if ours in slam:
            raise DynSlamError(f"{origin}: {label} is hector_mapping's name of slam.{ours}, which is given too; "
                               f"keep one of them")
        slam[ours] = value
    if moves:
        out["slam"] = slam
    return out


def config_from_dict(data: dict[str, Any], origin: str = "<config>") -> Config:
    """Validate a (partial) nested dict into a Config; errors name ``origin`` and the key.

    hector_mapping's parameter names (:data:`HECTOR_NAMES`) are accepted for the ``slam`` keys.
    """
    data = _with_hector_names(data, origin)
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


def check_key(key: str, spec: str) -> None:
    """Raise DynSlamError unless the dotted ``key`` (as in ``config dump``) names a value of :class:`Config`
    (``spec`` is the option as the user wrote it, for the message)."""
    parts = key.split(".")
    model: type[BaseModel] = Config
    for i, part in enumerate(parts):
        fields = model.model_fields
        if part not in fields:
            where = ".".join(parts[:i]) or "the configuration"
            raise DynSlamError(
                f"--set {spec}: {where} has no key {part!r}; keys: {', '.join(sorted(fields))} "
                f"(see 'dynslam2d config dump')"
            )
        ann = fields[part].annotation
        if i < len(parts) - 1:
            if not (isinstance(ann, type) and issubclass(ann, BaseModel)):
                raise DynSlamError(f"--set {spec}: {'.'.join(parts[: i + 1])} is a value, not a section")
            model = ann
        elif isinstance(ann, type) and issubclass(ann, BaseModel):
            raise DynSlamError(f"--set {spec}: {'.'.join(parts)} is a section; name one of its keys")


def set_key(data: dict[str, Any], key: str, value: Any) -> None:
    """Set the dotted ``key`` in a ``Config.model_dump()``-shaped dict."""
    parts = key.split(".")
    node = data
    for part in parts[:-1]:
        node = node[part]
    node[parts[-1]] = value


def parse_assignment(spec: str) -> tuple[str, Any]:
    """``KEY=VALUE`` (KEY dotted as in ``config dump``, VALUE read as YAML: ``0.05``, ``off``, ``[1, 2]``)."""
    key, sep, text = spec.partition("=")
    key = key.strip()
    if not sep or not key or not text.strip():
        raise DynSlamError(f"--set {spec}: expected KEY=VALUE, e.g. slam.map_resolution=0.025")
    check_key(key, spec)
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError as err:
        problem = getattr(err, "problem", None) or "unreadable"
        raise DynSlamError(f"--set {spec}: the value is not valid YAML ({problem}); quote it or fix the "
                           f"brackets") from None
    return key, value


def with_assignments(config: Config, specs: list[str]) -> Config:
    """A copy of ``config`` with every ``KEY=VALUE`` of ``specs`` applied in order (``run --set``)."""
    if not specs:
        return config
    data = config.model_dump()
    for spec in specs:
        key, value = parse_assignment(spec)
        set_key(data, key, value)
    return config_from_dict(data, origin="--set " + " ".join(specs))


_DUMP_HEADER = """\
# dynslam2d configuration (dynslam2d config dump). Give any part of it to
# `dynslam2d run --config FILE.yaml`; missing keys keep their defaults.
# Above each key: its meaning and unit (and the paper's equation where one applies);
# "hector_mapping: NAME" = the ROS parameter of the reference hector_mapping node (NAME is
# accepted in --config too, also at the top level); "option: --NAME" = the `dynslam2d run`
# option that overrides it.
"""


def _comment(text: str, pad: str, width: int = 100) -> list[str]:
    import textwrap

    return textwrap.wrap(" ".join(text.split()), width=max(40, width - len(pad)), initial_indent=f"{pad}# ",
                         subsequent_indent=f"{pad}# ", break_long_words=False, break_on_hyphens=False)


def _dump_model(model: BaseModel, data: dict[str, Any], path: str, pad: str, lines: list[str]) -> None:
    hector = {ours: theirs for theirs, ours in HECTOR_NAMES.items()}
    for name, field in type(model).model_fields.items():
        key = f"{path}{name}"
        value = getattr(model, name)
        if isinstance(value, BaseModel):
            lines.append("")
            lines += _comment(field.description or "", pad)
            lines.append(f"{pad}{name}:")
            _dump_model(value, data[name], f"{key}.", pad + "  ", lines)
            continue
        notes = []
        if path == "slam." and name in hector:
            notes.append(f"hector_mapping: {hector[name]}")
        if key in HECTOR_HARD_CODED:
            notes.append(HECTOR_HARD_CODED[key])
        if key in RUN_OPTIONS:
            flag, short = RUN_OPTIONS[key]
            notes.append(f"option: {flag}" + (f" (or {short})" if short else ""))
        lines += _comment((field.description or "") + (f" [{'; '.join(notes)}]" if notes else ""), pad)
        v = data[name]
        if isinstance(v, (list, dict)):
            item = f"{name}: " + yaml.safe_dump(v, default_flow_style=True, width=10_000, allow_unicode=True).strip()
        else:
            item = yaml.safe_dump({name: v}, default_flow_style=False, width=10_000, allow_unicode=True).strip()
        lines += [pad + line for line in item.splitlines()]


def dump_config(config: Config, comments: bool = True) -> str:
    """The full configuration as YAML text (stable key order: the models' field order).

    With ``comments`` (the default) every key is preceded by its description (meaning, unit,
    the paper's equation where one applies), its hector_mapping parameter name and its
    ``dynslam2d run`` option; :func:`load_config` reads the text back to the same Config.
    """
    if not comments:
        return yaml.safe_dump(config.model_dump(mode="json"), sort_keys=False)
    lines = _DUMP_HEADER.splitlines()
    _dump_model(config, config.model_dump(mode="json"), "", "", lines)
    return "\n".join(lines) + "\n"
