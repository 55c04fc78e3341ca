"""The real-frame gallery of ``docs/validation/real-frames.md``: one picture per kind of frame, made by the command a
user types (``jaxlimb locate FRAME ... --figure PNG``): the frame with the fitted pixels, limb and centre, a zoom on
the lit limb, and the image's own edge along the fitted limb's normals against that limb
(:func:`jaxlimb.pipeline.edge_residuals`).  Pictures are shrunk to ``WIDTH_PX`` wide for the documentation."""

from __future__ import annotations

import tempfile
from pathlib import Path

#: One frame of each kind (a refused EPIC frame answered without the centre tolerance among them).
GALLERY = ("enceladus_1", "jupiter", "voyager_C1636902", "sun__HMI_continuum_png", "sun_resampled_hmi_fits",
           "sun_aia_171_level1_fits",
           "epic_20220310_png_any_sigma", "epic_20221110_png")
#: Width (px) of the pictures kept.
WIDTH_PX = 1400


def gallery(frames: list[dict], rows: dict[str, dict], out_dir: Path, run) -> dict[str, str]:  # noqa: ANN001
    """Write the pictures of the :data:`GALLERY` frames that were answered into ``out_dir``.

    Parameters
    ----------
    frames : list of dict
        The benchmark's frames (``name``, ``path``, ``args``, optional ``command``).
    rows : dict
        Their results by name (``exit_code``).
    out_dir : Path
        Folder of the pictures (created).
    run : callable
        ``run(argv) -> (exit code, answer, seconds)``: the ``jaxlimb`` command in this process.

    Returns
    -------
    dict of str to str
        Picture file name by frame name.
    """
    import cv2

    out_dir.mkdir(parents=True, exist_ok=True)
    made = {}
    for fr in frames:
        if fr["name"] not in GALLERY or rows.get(fr["name"], {}).get("exit_code") != 0:
            continue
        with tempfile.TemporaryDirectory() as d:
            tmp = Path(d) / "fig.png"
            code, _, _ = run([fr.get("command", "locate"), str(fr["path"]), *fr["args"], "--figure", str(tmp)])
            img = cv2.imread(str(tmp)) if code == 0 and tmp.exists() else None
            if img is None:
                continue
            h, w = img.shape[:2]
            small = cv2.resize(img, (WIDTH_PX, round(h * WIDTH_PX / w)), interpolation=cv2.INTER_AREA)
            name = f"{fr['name']}.jpg"
            cv2.imwrite(str(out_dir / name), small, [cv2.IMWRITE_JPEG_QUALITY, 88])
            made[fr["name"]] = name
        print(f"gallery: {fr['name']}", flush=True)
    return made
