"""Configuration: defaults, YAML round trip, partial files, clear errors."""

from __future__ import annotations

import pytest
import yaml

from dynslam2d.config import Config, dump_config, load_config, with_overrides
from dynslam2d.errors import DynSlamError


def test_dump_then_load_gives_the_same_config(tmp_path):
    cfg = Config()
    p = tmp_path / "c.yaml"
    p.write_text(dump_config(cfg))
    assert load_config(p) == cfg
    data = yaml.safe_load(dump_config(cfg))
    assert data["slam"]["map_resolution"] == 0.05  # hector_mapping names and the reference defaults
    assert data["slam"]["map_update_distance_thresh"] == 0.4


def test_partial_file_keeps_other_defaults(tmp_path):
    p = tmp_path / "c.yaml"
    p.write_text("slam:\n  map_resolution: 0.1\n")
    cfg = load_config(p)
    assert cfg.slam.map_resolution == 0.1
    assert cfg.slam.map_levels == Config().slam.map_levels


@pytest.mark.parametrize(
    "text, match",
    [
        ("slam:\n  map_resolutoin: 0.1\n", r"c.yaml: invalid configuration: slam.map_resolutoin"),
        ("slam:\n  map_resolution: -1\n", r"slam.map_resolution: Input should be greater than 0"),
        ("- 1\n- 2\n", "must be a YAML mapping"),
        ("slam: [\n", "cannot read configuration"),
    ],
)
def test_bad_files_name_the_file_and_key(tmp_path, text, match):
    p = tmp_path / "c.yaml"
    p.write_text(text)
    with pytest.raises(DynSlamError, match=match):
        load_config(p)


def test_overrides_apply_and_validate():
    cfg = with_overrides(Config(), {"slam": {"map_resolution": 0.025, "map_levels": None}})
    assert cfg.slam.map_resolution == 0.025 and cfg.slam.map_levels == 3
    with pytest.raises(DynSlamError, match="command-line options"):
        with_overrides(Config(), {"slam": {"laser_min_dist": 50.0, "laser_max_dist": 10.0}})
