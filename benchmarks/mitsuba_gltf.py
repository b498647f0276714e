"""glTF 2.0 assets in Mitsuba 3: a small GLB reader and the metallic-roughness BRDF as a Python BSDF plugin.

Mitsuba 3 has no BSDF equal to glTF's metallic-roughness material (its ``principled`` is Disney's, with other lobes
and Fresnel terms), so the benchmark suite's ``gltf`` scene needs one written for it.  This module is written from
the glTF 2.0 specification, appendix B ("BRDF Implementation"), not from lightprobe's code:

    f = mix(dielectric_brdf, metal_brdf, metallic)
    dielectric_brdf = mix(base / pi, V D, 0.04 + 0.96 (1 - |V.H|)^5)
    metal_brdf = (base + (1 - base) (1 - |V.H|)^5) V D
    D = alpha^2 chi(N.H) / (pi ((N.H)^2 (alpha^2 - 1) + 1)^2),   alpha = roughness^2
    V = chi(H.L) chi(H.V) / (2 (|N.V| s(N.L) + |N.L| s(N.V))),   s(x) = sqrt(alpha^2 + (1 - alpha^2) x^2)

(the height-correlated Smith visibility of the specification's "Specular BRDF" section; V is the direction toward
the eye, Mitsuba's ``si.wi``, and L toward the light, Mitsuba's ``wo``).  ``alpha`` is kept above 1e-4 so that the
distribution stays finite (a roughness below 0.01; the suite's asset has none).

Textures are Mitsuba ``bitmap`` textures: the base colour sRGB-decoded (``raw`` false: Mitsuba converts the 8-bit
texels to linear when it loads them, before filtering, as the glTF specification asks), the metallic-roughness
texture linear (``raw`` true; green = roughness, blue = metallic), with the sampler's wrap mode and filter (bilinear
unless ``magFilter`` is NEAREST).  Both renderers address a texture the same way: (u, v) = (0, 0) is the top-left
corner of the image's first row, texel centres at ((i + 1/2) / W, (j + 1/2) / H).

Sampling (any unbiased choice gives the same expected image): the specular lobe by Mitsuba's GGX visible-normal
distribution, the diffuse lobe by the cosine, the lobe picked with probability proportional to a Schlick estimate of
each lobe's albedo at N.V; the pdf is the mixture.

The reader takes what the suite's asset holds: triangle primitives with POSITION, NORMAL, TEXCOORD_0 and indices,
nodes without transforms, images in buffer views, and refuses anything else by name.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np

_COMPONENTS = {5121: np.uint8, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
_WRAP = {10497: "repeat", 33648: "mirror", 33071: "clamp"}
NEAREST = 9728


def read_glb(path) -> tuple[dict, bytes]:
    """(the JSON document, the binary chunk) of a GLB file."""
    raw = Path(path).read_bytes()
    magic, version, _ = struct.unpack_from("<4sII", raw, 0)
    if magic != b"glTF" or version != 2:
        raise ValueError(f"{path}: not a GLB 2 file")
    offset, doc, blob = 12, None, b""
    while offset + 8 <= len(raw):
        size, kind = struct.unpack_from("<II", raw, offset)
        chunk = raw[offset + 8 : offset + 8 + size]
        if kind == 0x4E4F534A:
            doc = json.loads(chunk)
        elif kind == 0x004E4942:
            blob = chunk
        offset += 8 + size + (-size % 4)
    if doc is None:
        raise ValueError(f"{path}: no JSON chunk")
    return doc, blob


def _accessor(doc: dict, blob: bytes, index: int) -> np.ndarray:
    acc = doc["accessors"][index]
    if "sparse" in acc or acc.get("normalized"):
        raise ValueError("sparse or normalized accessors are not read here")
    dtype = np.dtype(_COMPONENTS[acc["componentType"]])
    width = _WIDTH[acc["type"]]
    view = doc["bufferViews"][acc["bufferView"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    stride = view.get("byteStride", dtype.itemsize * width)
    count = acc["count"]
    rows = np.frombuffer(blob, np.uint8, count=(count - 1) * stride + dtype.itemsize * width, offset=start)
    out = np.lib.stride_tricks.as_strided(rows, (count, dtype.itemsize * width), (stride, 1))
    return np.ascontiguousarray(out).view(dtype).reshape(count, width)


def glb_primitives(path) -> tuple[list[dict], dict, bytes]:
    """(primitives as dicts of vertices, normals, uvs, faces and material index; the document; the binary chunk)."""
    doc, blob = read_glb(path)
    scene = doc["scenes"][doc.get("scene", 0)]
    out = []
    for n in scene["nodes"]:
        node = doc["nodes"][n]
        if any(key in node for key in ("matrix", "translation", "rotation", "scale", "children")):
            raise ValueError(f"{path}: node {n} has a transform or children, which this reader does not apply")
        for prim in doc["meshes"][node["mesh"]]["primitives"]:
            if prim.get("mode", 4) != 4:
                raise ValueError(f"{path}: only triangle primitives are read")
            a = prim["attributes"]
            out.append(
                {
                    "vertices": _accessor(doc, blob, a["POSITION"]).astype(np.float64),
                    "normals": _accessor(doc, blob, a["NORMAL"]).astype(np.float64) if "NORMAL" in a else None,
                    "uvs": _accessor(doc, blob, a["TEXCOORD_0"]).astype(np.float64) if "TEXCOORD_0" in a else None,
                    "faces": _accessor(doc, blob, prim["indices"]).reshape(-1, 3).astype(np.int64),
                    "material": prim.get("material"),
                }
            )
    return out, doc, blob


def _texture(doc: dict, blob: bytes, info: dict | None, folder: Path, *, srgb: bool) -> dict | None:
    """A Mitsuba bitmap texture dict for a glTF textureInfo (its image written to ``folder``), or None."""
    if info is None:
        return None
    if info.get("texCoord", 0) != 0 or "extensions" in info:
        raise ValueError("only TEXCOORD_0 without texture transforms is read")
    texture = doc["textures"][info["index"]]
    sampler = doc.get("samplers", [{}])[texture["sampler"]] if "sampler" in texture else {}
    wrap_s, wrap_t = sampler.get("wrapS", 10497), sampler.get("wrapT", 10497)
    if wrap_s != wrap_t:
        raise ValueError("Mitsuba's bitmap takes one wrap mode for both axes")
    image = doc["images"][texture["source"]]
    view = doc["bufferViews"][image["bufferView"]]
    data = blob[view.get("byteOffset", 0) : view.get("byteOffset", 0) + view["byteLength"]]
    file = folder / f"image{texture['source']}.png"
    file.write_bytes(data)
    return {
        "type": "bitmap",
        "filename": str(file),
        "raw": not srgb,
        "filter_type": "nearest" if sampler.get("magFilter") == NEAREST else "bilinear",
        "wrap_mode": _WRAP[wrap_s],
    }


def material_dict(doc: dict, blob: bytes, index: int | None, folder: Path) -> dict:
    """The ``gltf_metallic_roughness`` BSDF dict of material ``index`` (None: the specification's default)."""
    m = doc["materials"][index] if index is not None else {}
    if m.get("alphaMode", "OPAQUE") != "OPAQUE" or "normalTexture" in m or "emissiveFactor" in m:
        raise ValueError(f"material {index}: alpha modes, normal maps and emission are not read here")
    pbr = m.get("pbrMetallicRoughness", {})
    factor = pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])
    d = {
        "type": "gltf_metallic_roughness",
        "base_color_factor": {"type": "rgb", "value": [float(x) for x in factor[:3]]},
        "metallic_factor": float(pbr.get("metallicFactor", 1.0)),
        "roughness_factor": float(pbr.get("roughnessFactor", 1.0)),
    }
    base = _texture(doc, blob, pbr.get("baseColorTexture"), folder, srgb=True)
    if base is not None:
        d["base_color"] = base
    mr = _texture(doc, blob, pbr.get("metallicRoughnessTexture"), folder, srgb=False)
    if mr is not None:
        d["metallic_roughness"] = mr
    if m.get("doubleSided"):
        d = {"type": "twosided", "bsdf": d}
    return d


def register(mi, dr) -> None:
    """Register the ``gltf_metallic_roughness`` BSDF with Mitsuba (after ``mi.set_variant``)."""

    class GltfMetallicRoughness(mi.BSDF):
        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            factor = props.get("base_color_factor")  # an RGB given as {"type": "rgb"} arrives as a colour
            self.factor = mi.Color3f(factor[0], factor[1], factor[2])
            self.base = props.get("base_color") if props.has_property("base_color") else None
            self.mr = props.get("metallic_roughness") if props.has_property("metallic_roughness") else None
            self.metallic_factor = props.get("metallic_factor", 1.0)
            self.roughness_factor = props.get("roughness_factor", 1.0)
            glossy = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            diffuse = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [glossy, diffuse]
            self.m_flags = glossy | diffuse

        def _params(self, si, active):
            """(base colour, metallic, alpha) at the hit."""
            base = mi.Color3f(self.factor)
            if self.base is not None:
                base = base * self.base.eval(si, active)
            metallic = mi.Float(self.metallic_factor)
            roughness = mi.Float(self.roughness_factor)
            if self.mr is not None:
                texel = self.mr.eval(si, active)
                roughness = roughness * texel[1]
                metallic = metallic * texel[2]
            alpha = dr.maximum(roughness * roughness, 1e-4)
            return base, metallic, alpha

        @staticmethod
        def _specular_probability(base, metallic, cos_v):
            """The chance of sampling the specular lobe: its Schlick albedo estimate at N.V against the diffuse's."""
            w = (1.0 - dr.clip(cos_v, 0.0, 1.0)) ** 5
            mean = (base[0] + base[1] + base[2]) / 3.0
            f_dielectric = 0.04 + 0.96 * w
            spec = (1.0 - metallic) * f_dielectric + metallic * (mean + (1.0 - mean) * w)
            diff = (1.0 - metallic) * (1.0 - f_dielectric) * mean
            return dr.select(spec + diff > 0.0, spec / (spec + diff), 1.0)

        def _brdf(self, base, metallic, alpha, wi, wo):
            """f(V = wi, L = wo), the specification's appendix B, without the cosine."""
            cos_v, cos_l = mi.Frame3f.cos_theta(wi), mi.Frame3f.cos_theta(wo)
            h = dr.normalize(wi + wo)
            cos_h = mi.Frame3f.cos_theta(h)
            v_dot_h = dr.dot(wi, h)
            l_dot_h = dr.dot(wo, h)
            a2 = alpha * alpha
            d = a2 / (dr.pi * dr.square(cos_h * cos_h * (a2 - 1.0) + 1.0))
            d = dr.select(cos_h > 0.0, d, 0.0)
            vis = 0.5 / (
                dr.abs(cos_v) * dr.sqrt(a2 + (1.0 - a2) * cos_l * cos_l)
                + dr.abs(cos_l) * dr.sqrt(a2 + (1.0 - a2) * cos_v * cos_v)
            )
            vis = dr.select((v_dot_h > 0.0) & (l_dot_h > 0.0), vis, 0.0)
            specular = vis * d
            w = (1.0 - dr.abs(v_dot_h)) ** 5
            f_dielectric = 0.04 + 0.96 * w
            dielectric = (1.0 - f_dielectric) * base * dr.inv_pi + f_dielectric * specular
            metal = (base + (1.0 - base) * w) * specular
            return (1.0 - metallic) * dielectric + metallic * metal

        def _pdf(self, base, metallic, alpha, wi, wo):
            cos_v, cos_l = mi.Frame3f.cos_theta(wi), mi.Frame3f.cos_theta(wo)
            distr = mi.MicrofacetDistribution(mi.MicrofacetType.GGX, alpha, True)
            h = dr.normalize(wi + wo)
            p_spec = distr.pdf(wi, h) / (4.0 * dr.abs(dr.dot(wo, h)))
            p_spec = dr.select(mi.Frame3f.cos_theta(h) > 0.0, p_spec, 0.0)
            p_diff = mi.warp.square_to_cosine_hemisphere_pdf(wo)
            ps = self._specular_probability(base, metallic, cos_v)
            pdf = ps * p_spec + (1.0 - ps) * p_diff
            return dr.select((cos_v > 0.0) & (cos_l > 0.0), pdf, 0.0)

        def eval(self, ctx, si, wo, active=True):
            base, metallic, alpha = self._params(si, active)
            cos_v, cos_l = mi.Frame3f.cos_theta(si.wi), mi.Frame3f.cos_theta(wo)
            value = self._brdf(base, metallic, alpha, si.wi, wo) * cos_l
            return dr.select(active & (cos_v > 0.0) & (cos_l > 0.0), value, 0.0)

        def pdf(self, ctx, si, wo, active=True):
            base, metallic, alpha = self._params(si, active)
            return dr.select(active, self._pdf(base, metallic, alpha, si.wi, wo), 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            base, metallic, alpha = self._params(si, active)
            cos_v, cos_l = mi.Frame3f.cos_theta(si.wi), mi.Frame3f.cos_theta(wo)
            ok = active & (cos_v > 0.0) & (cos_l > 0.0)
            value = self._brdf(base, metallic, alpha, si.wi, wo) * cos_l
            return dr.select(ok, value, 0.0), dr.select(ok, self._pdf(base, metallic, alpha, si.wi, wo), 0.0)

        def sample(self, ctx, si, sample1, sample2, active=True):
            base, metallic, alpha = self._params(si, active)
            cos_v = mi.Frame3f.cos_theta(si.wi)
            ps = self._specular_probability(base, metallic, cos_v)
            specular = sample1 < ps
            distr = mi.MicrofacetDistribution(mi.MicrofacetType.GGX, alpha, True)
            m, _ = distr.sample(si.wi, sample2)
            reflected = mi.reflect(si.wi, m)
            diffuse = mi.warp.square_to_cosine_hemisphere(sample2)
            wo = dr.select(specular, reflected, diffuse)
            bs = mi.BSDFSample3f()
            bs.wo = wo
            bs.pdf = self._pdf(base, metallic, alpha, si.wi, wo)
            bs.eta = 1.0
            bs.sampled_component = dr.select(specular, mi.UInt32(0), mi.UInt32(1))
            bs.sampled_type = dr.select(
                specular, mi.UInt32(+mi.BSDFFlags.GlossyReflection), mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
            )
            cos_l = mi.Frame3f.cos_theta(wo)
            ok = active & (cos_v > 0.0) & (cos_l > 0.0) & (bs.pdf > 0.0)
            value = self._brdf(base, metallic, alpha, si.wi, wo) * cos_l / dr.maximum(bs.pdf, 1e-30)
            return bs, dr.select(ok, value, 0.0)

        def traverse(self, callback):
            pass

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            return "GltfMetallicRoughness[]"

    mi.register_bsdf("gltf_metallic_roughness", lambda props: GltfMetallicRoughness(props))
