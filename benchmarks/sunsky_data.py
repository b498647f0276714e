#!/usr/bin/env python3
"""Extract the Hosek-Wilkie RGB sky and sun tables that lightprobe's sun and sky read:
``src/lightprobe/emitters/data/sunsky_rgb.npz``.

    python benchmarks/sunsky_data.py [path/to/mitsuba/data/sunsky]      # the RGB response: needs Mitsuba 3.9.1

Where the numbers come from: the Hosek-Wilkie sky model (Hosek & Wilkie 2012, "An Analytic Model for Full Spectral
Sky-Dome Radiance") and its solar radiance function (Hosek & Wilkie 2013, "Adding a Solar-Radiance Function to the
Hosek-Wilkie Skylight Model") publish their fitted coefficients as data (``ArHosekSkyModelData_RGB.h``,
BSD-3-clause, (c) 2012-2013 Lukas Hosek and Alexander Wilkie; the notice is shipped beside the tables as
``LICENSE-hosek-wilkie.txt``).  Mitsuba 3.9.1 ships the same tables re-packed in its wheel as
``mitsuba/data/sunsky/sunsky_datasets.bin``, a Mitsuba ``TensorFile``: that is the file read here, because
lightprobe matches Mitsuba's ``sunsky`` emitter, so it must use exactly the numbers Mitsuba uses (including its RGB
sun table, whose limb darkening is baked into the polynomial).  The file is parsed here without Mitsuba: a 12-byte
magic ``tensor_file\\0``, a uint16 version, a uint32 field count, then per field a uint16-prefixed name, a uint16
rank, a uint8 dtype (11 = float64), a uint64 byte offset and rank uint64 extents; the values are little-endian.

Kept (float32: Mitsuba's LLVM RGB variant converts the float64 tables to float32 when it loads them, so these are
the values its kernels read):

``sky_params``  (10 turbidities, 2 albedos, 6 Bezier control points over the sun's elevation, 3 channels, 9 params)
``sky_radiance`` (10, 2, 6, 3): the overall radiance scale of each channel
``sun_radiance`` (10 turbidities, 45 elevation segments, 3 channels, 4 powers of the elevation offset, 6 powers of
                  the limb-darkening cosine)
``sun_irradiance`` (10 turbidities, 30 sun elevations 2, 5, ..., 89 degrees, 11 wavelengths 320, 360, ..., 720 nm):
                  the sun's spectral irradiance, from ``sampling_data.bin`` (Mitsuba's uniform sun, ``complex_sun =
                  false``, is its RGB over the disc's solid angle)
``rgb_response`` (11 wavelengths, 3): Mitsuba's linear sRGB colour matching functions (``linear_rgb_rec``, from its
                  CIE tables) at those wavelengths, which it averages the spectrum against (``spectrum_to_srgb``):
                  read from Mitsuba itself, the one part of this script that imports it
"""

from __future__ import annotations

import glob
import struct
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "src" / "lightprobe" / "emitters" / "data" / "sunsky_rgb.npz"
FIELDS = {"sky_params_rgb": "sky_params", "sky_rad_rgb": "sky_radiance", "sun_rad_rgb": "sun_radiance"}
DTYPES = {11: np.float64, 10: np.float32}
WAVELENGTHS = 320.0 + 40.0 * np.arange(11)  # nm: the spectral model's


def read_tensor_file(path: Path) -> dict[str, np.ndarray]:
    """Every field of a Mitsuba ``TensorFile`` as a NumPy array."""
    blob = path.read_bytes()
    if blob[:12] != b"tensor_file\0":
        raise SystemExit(f"{path}: not a Mitsuba tensor file")
    _version, count = struct.unpack_from("<HI", blob, 12)
    at = 18
    fields = {}
    for _ in range(count):
        (length,) = struct.unpack_from("<H", blob, at)
        name = blob[at + 2 : at + 2 + length].decode()
        at += 2 + length
        rank, dtype, offset = struct.unpack_from("<HBQ", blob, at)
        at += 11
        shape = struct.unpack_from(f"<{rank}Q", blob, at)
        at += 8 * rank
        kind = np.dtype(DTYPES[dtype]).newbyteorder("<")
        fields[name] = np.frombuffer(blob, kind, count=int(np.prod(shape)), offset=offset).reshape(shape)
    return fields


def rgb_response() -> np.ndarray:
    """Mitsuba's linear sRGB response (11, 3) at the model's wavelengths."""
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    return np.array([list(mi.linear_rgb_rec(float(w))) for w in WAVELENGTHS], np.float32)


def main() -> int:
    if len(sys.argv) > 1:
        folder = Path(sys.argv[1])
    else:
        hits = glob.glob(str(Path(sys.prefix) / "lib" / "python3*" / "site-packages" / "mitsuba" / "data" / "sunsky"))
        if not hits:
            raise SystemExit("give the path of Mitsuba 3.9.1's mitsuba/data/sunsky folder")
        folder = Path(hits[0])
    source = folder / "sunsky_datasets.bin"
    fields = read_tensor_file(source)
    tables = {ours: fields[theirs].astype(np.float32) for theirs, ours in FIELDS.items()}
    tables["sun_irradiance"] = read_tensor_file(folder / "sampling_data.bin")["sun_irradiance"].astype(np.float32)
    tables["rgb_response"] = rgb_response()
    assert tables["sun_irradiance"].shape == (10, 30, 11), tables["sun_irradiance"].shape
    assert tables["sky_params"].shape == (10, 2, 6, 3, 9), tables["sky_params"].shape
    assert tables["sky_radiance"].shape == (10, 2, 6, 3), tables["sky_radiance"].shape
    assert tables["sun_radiance"].shape == (10, 45, 3, 4, 6), tables["sun_radiance"].shape
    np.savez_compressed(OUT, **tables)
    print(f"{OUT}: {', '.join(f'{k} {v.shape}' for k, v in tables.items())} from {source}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
