"""Batch jobs: which (input, setting) pairs a batch runs, and the folder name of each.

``--set filter.mode=none,box --set slam.map_resolution=0.05,0.025`` is a grid of
settings: every combination of the listed values (the first key varies slowest), and
every input is run with every combination. The list of jobs is in a fixed order —
inputs in the order given, then the settings grid — and every job has a readable,
deterministic folder name: ``<input>__<key>=<value>__…`` (``parallel__filter.mode=none``).
"""

from __future__ import annotations

import hashlib
import itertools
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from dynslam2d.config import Config, check_key, config_from_dict, set_key
from dynslam2d.errors import DynSlamError


@dataclass(frozen=True)
class Setting:
    """One ``--set`` option: a dotted config key and the values to try, as given and as parsed."""

    key: str
    texts: tuple[str, ...]
    values: tuple[Any, ...]


@dataclass
class Job:
    """One run of a batch: an input with one combination of settings.

    ``config`` is the full effective configuration as a plain dict (it travels to the
    worker as an object; the worker never reads the ``--config`` file). ``options`` are
    the source options of ``dynslam2d run`` (topic, odom, imu, seed, duration, skip_bad).
    """

    name: str
    input: str
    settings: dict[str, str]
    config: dict[str, Any]
    options: dict[str, Any] = field(default_factory=dict)


def parse_setting(spec: str) -> Setting:
    """Parse ``KEY=V1,V2,…`` (KEY dotted as in ``config dump``; values read as YAML scalars)."""
    key, sep, rest = spec.partition("=")
    key = key.strip()
    if not sep or not key or not rest.strip():
        raise DynSlamError(f"--set {spec}: expected KEY=VALUE[,VALUE…], e.g. filter.mode=none,box")
    check_key(key, spec)
    texts = tuple(t.strip() for t in rest.split(","))
    if any(not t for t in texts):
        raise DynSlamError(f"--set {spec}: an empty value; separate values with single commas")
    if len(set(texts)) != len(texts):
        raise DynSlamError(f"--set {spec}: a value is listed twice")
    return Setting(key, texts, tuple(yaml.safe_load(t) for t in texts))


def settings_grid(settings: list[Setting]) -> list[list[tuple[str, str, Any]]]:
    """Every combination of the settings' values, first setting slowest: [(key, text, value), …] each."""
    keys = [s.key for s in settings]
    if len(set(keys)) != len(keys):
        raise DynSlamError(f"--set: a key is given twice ({', '.join(sorted(k for k in keys if keys.count(k) > 1))}); "
                           f"list all its values in one --set KEY=V1,V2")
    axes = [[(s.key, t, v) for t, v in zip(s.texts, s.values)] for s in settings]
    return [list(combo) for combo in itertools.product(*axes)]


def _safe(text: str) -> str:
    """A file-name-safe version of ``text`` (letters, digits and ``._=+-`` kept)."""
    return re.sub(r"[^A-Za-z0-9._=+-]+", "-", text).strip("-") or "x"


def input_labels(inputs: list[str]) -> list[str]:
    """A short readable label per input: ``sim:paper-1`` → ``sim-paper-1``, ``/d/parallel.bag`` → ``parallel``.

    Labels that would collide get their parent folder's name in front, and then, if still
    equal, 8 hex digits of the absolute path's SHA-1.
    """
    def base(inp: str) -> str:
        if inp.startswith("sim:"):
            return _safe("sim-" + inp[4:])
        p = Path(inp.rstrip("/"))
        name = p.name
        for suffix in (".gz", ".zip"):
            if name.endswith(suffix):
                name = name[: -len(suffix)]
        return _safe(Path(name).stem if "." in name else name)

    labels = [base(i) for i in inputs]
    for pass_ in range(2):
        seen: dict[str, int] = {}
        for lab in labels:
            seen[lab] = seen.get(lab, 0) + 1
        for i, inp in enumerate(inputs):
            if seen[labels[i]] > 1 and not inp.startswith("sim:"):
                if pass_ == 0:
                    labels[i] = _safe(f"{Path(os.path.abspath(inp)).parent.name}-{labels[i]}")
                else:
                    digest = hashlib.sha1(os.path.abspath(inp).encode()).hexdigest()[:8]
                    labels[i] = f"{labels[i]}-{digest}"
    return labels


def make_jobs(
    inputs: list[str],
    settings: list[Setting],
    base: Config | None = None,
    options: dict[str, Any] | None = None,
) -> list[Job]:
    """The batch's jobs in their fixed order: each input (as given) × each settings combination.

    Every combination is validated here (a bad value fails before any run). An input given
    twice is an error (its two runs would be the same folder).
    """
    if not inputs:
        raise DynSlamError("batch: give at least one INPUT")
    dup = sorted({i for i in inputs if inputs.count(i) > 1})
    if dup:
        raise DynSlamError(f"batch: input {dup[0]} is given twice; give each input once")
    base = base or Config()
    grid = settings_grid(settings)
    labels = input_labels(inputs)
    jobs: list[Job] = []
    cache: dict[tuple[str, ...], dict[str, Any]] = {}
    for inp, label in zip(inputs, labels):
        for combo in grid:
            sig = tuple(t for _, t, _ in combo)
            if sig not in cache:
                data = base.model_dump()
                for key, _, value in combo:
                    set_key(data, key, value)
                spec = ", ".join(f"{k}={t}" for k, t, _ in combo)
                cache[sig] = config_from_dict(data, origin=f"--set {spec}").model_dump(mode="json")
            name = "__".join([label] + [_safe(f"{k}={t}") for k, t, _ in combo])
            jobs.append(Job(name=name, input=inp, settings={k: t for k, t, _ in combo},
                            config=cache[sig], options=dict(options or {})))
    return jobs


__all__ = ["Job", "Setting", "input_labels", "make_jobs", "parse_setting", "settings_grid"]
