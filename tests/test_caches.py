"""The caches that keep the tests (and every run) from redoing work: YAML parsed once per text."""

from __future__ import annotations

import pytest

from bound_env.params import load_gait
from bound_env.resources import gaits_dir, parse_yaml


def test_parsed_yaml_is_a_fresh_copy_each_time():
    a = parse_yaml("x: [1, 2]\ny: {z: 3}\n")
    a["x"].append(9)
    a["y"]["z"] = 0
    assert parse_yaml("x: [1, 2]\ny: {z: 3}\n") == {"x": [1, 2], "y": {"z": 3}}


def test_a_changed_gait_file_is_read_again(tmp_path):
    path = tmp_path / "g.yaml"
    text = (gaits_dir() / "default.yaml").read_text()
    path.write_text(text)
    assert load_gait(path).params.kc == 295.0
    load_gait(path).meta["eigenvalues"].clear()  # a caller's copy, not the cache's
    assert len(load_gait(path).meta["eigenvalues"]) == 6
    path.write_text(text.replace("kc: 295.0", "kc: 296.0"))  # same size, same second
    assert load_gait(path).params.kc == 296.0
    path.write_text(text.replace("kc: 295.0", "kc: [295.0"))
    with pytest.raises(ValueError, match="not valid YAML"):
        load_gait(path)
