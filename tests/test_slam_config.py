"""SlamConfig: reference defaults, validation, schema and YAML round trip."""

from __future__ import annotations

import math

import pytest
import yaml
from pydantic import ValidationError

from dynslam2d.slam import SlamConfig


def test_reference_defaults() -> None:
    c = SlamConfig()
    # hector_mapping's mapping_default.launch (values where the node default is unusable)
    assert (c.map_resolution, c.map_levels) == (0.05, 3)
    assert (c.update_factor_free, c.update_factor_occupied) == (0.4, 0.9)
    assert (c.map_update_distance_thresh, c.map_update_angle_thresh) == (0.4, 0.06)
    assert (c.laser_min_dist, c.laser_max_dist) == (0.4, 30.0)
    assert (c.iterations_coarse, c.iterations_finest) == (4, 6)
    assert c.max_rotation_step == 0.2
    assert c.hector_gradient_bug is False and c.clear_no_return_dist == 0.0 and c.constant_velocity is False
    assert c.logodds_free == pytest.approx(-0.405465, abs=1e-6)
    assert c.logodds_occupied == pytest.approx(2.197225, abs=1e-6)


def test_validation() -> None:
    with pytest.raises(ValidationError):
        SlamConfig(laser_min_dist=5.0, laser_max_dist=4.0)
    with pytest.raises(ValidationError):
        SlamConfig(update_factor_free=0.6)
    with pytest.raises(ValidationError):
        SlamConfig(map_levels=0)
    with pytest.raises(ValidationError):
        SlamConfig(no_such_option=1)  # typos are errors, not silently ignored
    with pytest.raises(ValidationError):
        SlamConfig(correlative_mode="sometimes")


def test_schema_documents_every_field_and_yaml_round_trip() -> None:
    schema = SlamConfig.model_json_schema()
    props = schema["properties"]
    assert set(props) == set(SlamConfig.model_fields)
    for name, p in props.items():
        assert p.get("description"), name
    c = SlamConfig(map_resolution=0.025, correlative_mode="always", covariance_sigma=0.1)
    text = yaml.safe_dump(c.model_dump())
    back = SlamConfig(**yaml.safe_load(text))
    assert back == c
    assert math.isclose(back.map_resolution, 0.025)
