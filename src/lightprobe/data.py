"""Where the shared real-world data lives (HDR maps and meshes of ``../shared/data``), and named maps.

The folder is found, in order, from the ``LIGHTPROBE_DATA`` environment variable, ``../shared/data`` relative to the
current directory, and ``../shared/data`` relative to the repository this package was installed from.  Nothing in
lightprobe requires it: the demo and the core tests use procedural maps and meshes.
"""

from __future__ import annotations

import os
from pathlib import Path

from .errors import ParameterError

__all__ = ["NAMED_ENVMAPS", "data_dir", "named_envmap_path"]

#: Short names used by experiments and benchmarks for files in ``data_dir()/envmaps``.
NAMED_ENVMAPS = {
    "overcast": "polyhaven_mud_road_puresky_1k.hdr",
    "sunrise": "blender_sunrise.exr",
    "studio": "blender_studio.exr",
    "city": "blender_city.exr",
    "interior": "blender_interior.exr",
    "courtyard": "blender_courtyard.exr",
    "forest": "blender_forest.exr",
    "sunset": "blender_sunset.exr",
    "night": "blender_night.exr",
    "beach": "usd_stinson_beach.hdr",
}


def data_dir() -> Path | None:
    """The shared data folder, or None when it is absent."""
    candidates = []
    if os.environ.get("LIGHTPROBE_DATA"):
        candidates.append(Path(os.environ["LIGHTPROBE_DATA"]))
    candidates.append(Path.cwd() / ".." / "shared" / "data")
    candidates.append(Path(__file__).resolve().parents[3] / "shared" / "data")
    for c in candidates:
        if (c / "envmaps").is_dir() or (c / "meshes").is_dir():
            return c.resolve()
    return None


def named_envmap_path(name: str) -> Path:
    """Path of a named real map (see :data:`NAMED_ENVMAPS`); a clear error if the data folder is missing."""
    if name not in NAMED_ENVMAPS:
        raise ParameterError(f"unknown environment map name {name!r}; known: {', '.join(NAMED_ENVMAPS)}")
    root = data_dir()
    if root is None:
        raise ParameterError(
            f"map {name!r} needs the shared data folder (../shared/data); set LIGHTPROBE_DATA to its location"
        )
    return root / "envmaps" / NAMED_ENVMAPS[name]
