"""Tests of the sharded batch fit on 2 forced host devices (jaxlimb.analysis.sharding)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent(
    """
    import json, os
    import jax
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    from jaxlimb.analysis.posterior import synthetic_circle
    from jaxlimb.analysis.sharding import sharded_fit_batch
    from jaxlimb.fitting import fit_batch
    from jaxlimb.models import CIRCLE

    B = 5  # odd: exercises the padding to a multiple of the device count
    s = synthetic_circle(radius=30.0, annulus=3.0, seed=0)
    clean = np.asarray(CIRCLE.intensity(s.truth, s.coords))
    z = clean[None] + 10 * np.random.default_rng(0).standard_normal((B, clean.size))
    coords = np.broadcast_to(s.coords, (B,) + s.coords.shape)
    v0 = np.asarray(s.truth.replace(r0=s.truth.r0 + 0.5).to_vector())
    init = CIRCLE.params_type.from_vector(np.repeat(v0[None], B, 0))
    sh = sharded_fit_batch(CIRCLE, coords, z, init, fixed=("k",))
    ref = fit_batch(CIRCLE, coords, z, init, fixed=("k",))
    full = sharded_fit_batch(CIRCLE, coords[:4], z[:4], CIRCLE.params_type.from_vector(np.repeat(v0[None], 4, 0)))
    print(json.dumps({
        "n_devices": jax.device_count(),
        "max_diff": float(np.abs(np.asarray(sh.params.to_vector()) - np.asarray(ref.params.to_vector())).max()),
        "cov_diff": float(np.abs(np.asarray(sh.covariance) - np.asarray(ref.covariance)).max()),
        "converged": np.asarray(sh.converged).tolist(),
        "shape": list(np.shape(sh.params.r0)),
        "spread": len(full.params.r0.sharding.device_set),
    }))
    """
)


def test_sharded_fit_equals_fit_batch_on_two_host_devices():
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    out = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=170)
    assert out.returncode == 0, out.stderr[-3000:]
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert res["n_devices"] == 2
    assert res["shape"] == [5]
    assert res["spread"] == 2  # the result lives on both devices
    assert all(res["converged"])
    assert res["max_diff"] < 1e-9 and res["cov_diff"] < 1e-12
