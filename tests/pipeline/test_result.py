"""The measurement's covariance as arrays (:func:`~jaxlimb.pipeline.result.covariance_block`): the nested form of
``locate``'s answer and of its JSON, read back in any order of names."""

from __future__ import annotations

import json

import numpy as np

from jaxlimb.pipeline import CENTER_NAMES, LimbMeasurement, covariance_block

_COV = {"center_r": {"center_r": 0.04, "center_c": -0.01, "radius": 0.002},
        "center_c": {"center_r": -0.01, "center_c": 0.09, "radius": 0.003},
        "radius": {"center_r": 0.002, "center_c": 0.003, "radius": 0.25}}


def test_the_centre_block_and_any_other_in_the_order_asked():
    assert CENTER_NAMES == ("center_r", "center_c")
    np.testing.assert_array_equal(covariance_block(_COV), [[0.04, -0.01], [-0.01, 0.09]])
    np.testing.assert_array_equal(covariance_block(_COV, ("radius", "center_c")), [[0.25, 0.003], [0.003, 0.09]])


def test_the_measurement_and_its_json_give_the_same_array():
    m = LimbMeasurement(center_rc=(60.3, 80.7), radius_px=30.0, ellipse=None, k=2.0, ymax=200.0, ymin=20.0,
                        covariance=_COV, iterations=3, solver="lm", front_end="gradient", n_pixels=500)
    back = json.loads(json.dumps(m.to_json()))
    np.testing.assert_array_equal(m.center_covariance, covariance_block(back["covariance"]))
    assert m.center_covariance.shape == (2, 2)
