"""Synthetic body images with exact truth for the front-end tests (numpy + OpenCV only).

A sphere of apparent radius ``radius`` px centred at ``center_rc`` with
Lommel-Seeliger shading (the Moon's photometry to first order: a hard limb at
every phase, a soft terminator), area-integrated by ``ss x ss`` supersampling,
then optional Gaussian blur (PSF), additive Gaussian noise, stars / hot pixels,
and quantisation.  The Sun direction is given by the phase angle and the image
direction ``sun_dir_rc`` (row, col) toward which the lit limb faces.

Camera frame (docs/design.md): +x -> +col, +y -> +row, +z boresight; the visible
hemisphere's normal at image offset (dr, dc)/R is n = (dc/R, dr/R, -sqrt(1 - ...)).
"""

from __future__ import annotations

import math

import cv2
import numpy as np


def sun_vector(phase_deg: float, sun_dir_rc=(0.0, 1.0)) -> np.ndarray:
    """Unit body->Sun vector (camera frame) for a phase angle and an image direction of the Sun."""
    a = math.radians(phase_deg)
    d = np.asarray(sun_dir_rc, float)
    d = d / np.linalg.norm(d)
    return np.array([math.sin(a) * d[1], math.sin(a) * d[0], -math.cos(a)])


def render_disk(
    shape=(400, 400),
    center_rc=(200.0, 200.0),
    radius=150.0,
    *,
    phase_deg: float = 0.0,
    sun_dir_rc=(0.0, 1.0),
    amplitude: float = 200.0,
    background: float = 10.0,
    blur_sigma: float = 0.0,
    noise_sigma: float = 0.0,
    n_stars: int = 0,
    n_hot: int = 0,
    ss: int = 5,
    albedo_variation: float = 0.0,
    quantize_bits: int | None = None,
    seed: int = 0,
) -> np.ndarray:
    """Render the body (float64 image). See the module docstring."""
    rng = np.random.default_rng(seed)
    R, C = shape
    img = np.zeros(shape, dtype=np.float64)
    pad = 3
    r0 = max(0, int(math.floor(center_rc[0] - radius)) - pad)
    r1 = min(R, int(math.ceil(center_rc[0] + radius)) + pad + 1)
    c0 = max(0, int(math.floor(center_rc[1] - radius)) - pad)
    c1 = min(C, int(math.ceil(center_rc[1] + radius)) + pad + 1)
    s = sun_vector(phase_deg, sun_dir_rc)
    if r1 > r0 and c1 > c0:
        off = (np.arange(ss) + 0.5) / ss - 0.5
        rr = (np.arange(r0, r1)[:, None] + off[None, :]).ravel()
        cc = (np.arange(c0, c1)[:, None] + off[None, :]).ravel()
        y = (rr[:, None] - center_rc[0]) / radius
        x = (cc[None, :] - center_rc[1]) / radius
        q = 1.0 - x * x - y * y
        inside = q > 0
        w = np.sqrt(np.where(inside, q, 0.0))
        cos_i = x * s[0] + y * s[1] - w * s[2]
        cos_e = w
        with np.errstate(invalid="ignore", divide="ignore"):
            ls = np.where(inside & (cos_i > 0), 2.0 * cos_i / (cos_i + cos_e), 0.0)
        ls = np.nan_to_num(ls)
        if albedo_variation > 0:
            alb = np.ones_like(ls)
            for _ in range(4):
                k = rng.normal(0, 6, 2)
                ph = rng.uniform(0, 2 * math.pi)
                alb += albedo_variation / 4 * np.sin(k[0] * x + k[1] * y + ph)
            ls = ls * alb
        sub = ls.reshape(r1 - r0, ss, c1 - c0, ss).mean(axis=(1, 3))
        img[r0:r1, c0:c1] = amplitude * sub
    if blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_sigma, borderType=cv2.BORDER_REFLECT)
    img += background
    for _ in range(n_stars):
        pr, pc = rng.uniform(0, R), rng.uniform(0, C)
        if math.hypot(pr - center_rc[0], pc - center_rc[1]) < radius + 10:
            continue
        a = rng.uniform(0.5, 1.5) * amplitude
        rs = np.arange(max(0, int(pr) - 4), min(R, int(pr) + 5))
        cs = np.arange(max(0, int(pc) - 4), min(C, int(pc) + 5))
        img[np.ix_(rs, cs)] += a * np.exp(-((rs[:, None] - pr) ** 2 + (cs[None, :] - pc) ** 2) / (2 * 0.8**2))
    for _ in range(n_hot):
        img[rng.integers(0, R), rng.integers(0, C)] += 1.5 * amplitude
    if noise_sigma > 0:
        img += rng.normal(0.0, noise_sigma, img.shape)
    if quantize_bits:
        img = np.clip(np.round(img), 0, 2**quantize_bits - 1)
    return img
