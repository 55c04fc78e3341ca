"""Where the project's shared real data live (SDO images, shape models): ``../shared/data`` beside the checkout."""

from __future__ import annotations

import os
from pathlib import Path


def shared_data_dir() -> Path:
    """``$JAXLIMB_SHARED_DATA`` if set, else ``shared/data`` beside the repository checkout."""
    env = os.environ.get("JAXLIMB_SHARED_DATA")
    return Path(env) if env else Path(__file__).resolve().parents[2] / "shared" / "data"
