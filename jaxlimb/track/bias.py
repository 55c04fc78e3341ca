r"""Bias states per body: the part of the measurement error that the frames of one body share.

``locate``'s covariance of a frame is its noise (the Cramér--Rao bound) plus a model-error term (the
cluster-robust sandwich of the limb model against the image, :mod:`jaxlimb.model_error`).  The noise is
independent from frame to frame; the model error is not: the same body under slowly changing geometry is
mis-modelled the same way (a Hapke Moon fitted with a lunar-Lambert profile, a Lambert Earth against its
limb model), and a filter that takes it as independent averages it away and becomes overconfident.

Each imaged body ``b`` gets two states, estimated with the trajectory
(Bar-Shalom, Li & Kirubarajan 2001, §8.2, state augmentation with a bias; Tapley, Schutz & Born 2004,
§4.12, consider/solve-for parameters), each a constant and, when ``walk`` is set, a random walk (a bias that
follows the slowly changing geometry):

* ``sun_offset``: the centre moved along the Sun's direction in the image
  (:func:`~jaxlimb.track.measurement.sun_direction_px`) by ``b_sun`` times the apparent radius: the
  phase-dependent offset of a limb-profile mismatch, which scales with the disc (by symmetry about the
  Sun--body--observer plane there is none across it);
* ``scale``: the apparent size multiplied by ``1 + b_scale`` (an Earth range, a Moon radius).

Their prior is zero mean with the size of the model-error part of ``locate``'s own covariance
(``R - R_noise``): per frame the centre's model-error variance (the mean of the row and column variances)
over the squared apparent radius, and the size's over the squared size; the median over the body's frames
is the prior variance: all of the model error, an upper bound.  How much of it the frames share, as a constant
or as a walk, is estimated from the arc (:mod:`jaxlimb.track.variance`).  No constant is chosen: a frame set
without a noise/model split (``R_noise`` None) or without a model-error part gets no bias states, and the filter
is the plain one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .measurement import BODY_RADIUS_KM, Frames

#: The components of a body's bias, in the order of the state.
BIAS_COMPONENTS = ("sun_offset", "scale")


@dataclass(frozen=True)
class BiasModel:
    """The bias states of a sequence (module docstring).

    Attributes
    ----------
    names : ``"<body>.<component>"`` of each state.
    sigma : (n_b,) prior standard deviation of each state (dimensionless).
    select : (n, 2, n_b) maps the states to a frame's ``(b_sun, b_scale)``.
    walk : (n_b,) power spectral density (1/s) of each state's random walk, or ``None``: constant states.
    """

    names: tuple[str, ...]
    sigma: np.ndarray
    select: np.ndarray
    walk: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.names)

    def constant_part(self) -> BiasModel:
        """The constant part alone: the states with a constant prior, no walk."""
        keep = self.sigma > 0
        return BiasModel(tuple(np.asarray(self.names, dtype=object)[keep]), self.sigma[keep], self.select[..., keep])

    def to_json(self, value: np.ndarray, cov: np.ndarray) -> dict[str, dict[str, float]]:
        """Each state's estimate and sigma, with its prior sigma."""
        return {n: {"value": float(value[i]), "sigma": float(math.sqrt(max(cov[i, i], 0.0))),
                    "prior_sigma": float(self.sigma[i])} for i, n in enumerate(self.names)}


def walk_columns(E: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The random walk of each bias state as columns of unit-variance effects: ``(W, owner)`` with ``W``
    ``(n, 3, m)`` and ``owner`` ``(m,)`` the state of each column.  ``E`` ``(n, 3, n_b)`` the measurements' bias
    columns at the frames' times ``t``; state ``j``'s walk at frame ``k`` is the sum of the increments
    ``sqrt(t_i - t_{i-1}) e_i`` over the frames ``i <= k`` that see it (``t_{i-1}`` the previous such frame, for the
    first one ``t[0]``; seconds: multiplied by ``sqrt(walk_j)`` the columns are the walk of PSD ``walk_j``, started
    at the first frame as the filter's)."""
    cols, owner = [], []
    for j in range(E.shape[-1]):
        seen = np.flatnonzero(np.any(E[:, :, j] != 0, axis=1))
        for b, dt in zip(seen, np.diff(t[seen], prepend=t[0])):
            if dt > 0:
                cols.append(E[:, :, j] * (np.arange(len(t)) >= b)[:, None] * np.sqrt(dt))
                owner.append(j)
    W = np.stack(cols, -1) if cols else np.zeros((E.shape[0], 3, 0))
    return W, np.array(owner, int)


def walk_effects(E: np.ndarray, t: np.ndarray, bias: BiasModel) -> np.ndarray:
    """The walk of ``bias`` as unit-variance effects ``(n, 3, m)``: :func:`walk_columns` times ``sqrt(walk)``
    (no column without a walk)."""
    if bias.walk is None or not np.any(bias.walk > 0):
        return np.zeros((E.shape[0], 3, 0))
    Wk, owner = walk_columns(E, t)
    return Wk * np.sqrt(bias.walk[owner])[None, None, :]


def random_effects(E: np.ndarray, t: np.ndarray, bias: BiasModel) -> np.ndarray:
    """The bias states as unit-variance effects ``(n, 3, m)``: ``E sigma`` (constant part) beside the walk
    (:func:`walk_effects`); ``z = h + W u + e`` with ``u ~ N(0, I)``."""
    return np.concatenate([E * bias.sigma[None, None, :], walk_effects(E, t, bias)], -1)


def body_names(frames: Frames) -> list[str]:
    """The imaged body of each frame (by its radius)."""
    names = list(BODY_RADIUS_KM)
    radii = np.array([BODY_RADIUS_KM[n] for n in names])
    return [names[int(np.argmin(np.abs(radii - r)))] for r in frames.radius_km]


def apparent_radius_px(frames: Frames) -> np.ndarray:
    """The measured apparent radius (px) of each frame (a range turned back into it with ``locate``'s focal length)."""
    X = frames.z[:, 2]
    ratio = np.clip(frames.radius_km / np.where(frames.is_range > 0, X, np.inf), 0.0, 1.0)
    return np.where(frames.is_range > 0, frames.theta_locate[:, 0] * np.tan(np.arcsin(ratio)), X)


def bias_model(frames: Frames, enabled: bool = True) -> BiasModel:
    """The bias states of ``frames`` and their prior (module docstring); none when not ``enabled``, without a
    noise/model split or a Sun position."""
    n = len(frames)
    if not enabled or frames.R_noise is None or frames.sun_pos is None:
        return BiasModel((), np.zeros(0), np.zeros((n, 2, 0)))
    model = frames.R - frames.R_noise
    size = apparent_radius_px(frames)
    var_sun = np.maximum(0.5 * (model[:, 0, 0] + model[:, 1, 1]), 0.0) / size**2
    var_scale = np.maximum(model[:, 2, 2], 0.0) / frames.z[:, 2] ** 2
    bodies = np.array(body_names(frames))
    names, sigma, cols = [], [], []
    for b in dict.fromkeys(bodies):
        m = bodies == b
        for j, v in enumerate((var_sun, var_scale)):
            s = math.sqrt(float(np.median(v[m])))
            if s > 0:
                names.append(f"{b}.{BIAS_COMPONENTS[j]}")
                sigma.append(s)
                col = np.zeros((n, 2))
                col[m, j] = 1.0
                cols.append(col)
    select = np.stack(cols, -1) if cols else np.zeros((n, 2, 0))
    return BiasModel(tuple(names), np.array(sigma), select)


__all__ = ["BIAS_COMPONENTS", "BiasModel", "apparent_radius_px", "bias_model", "body_names", "random_effects", "walk_columns", "walk_effects"]
