"""Hints keys: an unknown key is ignored (docs/design.md); one that resembles a known key is an error naming it."""

from __future__ import annotations

import json
import warnings

import pytest

from jaxlimb.errors import ConfigError
from jaxlimb.geometry.hints import Hints


def test_a_misspelt_key_is_named_with_the_key_it_resembles():
    with pytest.raises(ConfigError, match="'sun_dir' \\(did you mean 'sun_dir_camera'\\?\\)"):
        Hints.from_dict({"body": "moon", "sun_dir": [1.0, 0.0, 0.0]})


def test_a_foreign_key_is_ignored_silently():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert Hints.from_dict({"body": "moon", "filter_epoch_label": "k=12"}).body == "moon"


def test_cli_refuses_the_misspelt_key_on_one_line_with_exit_2(tmp_path, capsys):
    from jaxlimb.cli import main

    import cv2
    import numpy as np

    y, x = np.mgrid[:96, :96]
    disc = 5.0 + 200.0 / (1.0 + np.exp(np.hypot(y - 50.0, x - 45.0) - 30.0))
    cv2.imwrite(str(tmp_path / "img.png"), disc.astype(np.uint8))
    (tmp_path / "h.json").write_text(json.dumps({"body": "moon", "range_prior": 3.0e5}))
    code = main(["locate", str(tmp_path / "img.png"), "--hints", str(tmp_path / "h.json")])
    err = capsys.readouterr().err.splitlines()
    assert code == 2, err
    assert err == ["jaxlimb: error: hints have unknown keys 'range_prior' (did you mean 'range_prior_km'?)"]


def test_a_camera_file_given_as_hints_is_refused():
    from jaxlimb.errors import ConfigError

    with pytest.raises(ConfigError, match="camera file"):
        Hints.from_dict({"focal_length_mm": 16.0, "pixel_pitch_mm": 0.0022, "rows": 1944, "cols": 2592})


def test_a_misspelt_camera_key_is_an_error_naming_the_key_it_resembles():
    from jaxlimb.errors import ConfigError
    from jaxlimb.geometry.camera import Camera

    with pytest.raises(ConfigError, match="'focal_length': did you mean 'focal_length_mm'"):
        Camera.from_dict({"focal_length": 16.0, "pixel_pitch_mm": 0.0022, "rows": 1944, "cols": 2592})
