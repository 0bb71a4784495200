"""glTF materials and images: metallic-roughness materials, and their textures as PNGs (in the
buffer of a .glb, beside a .gltf as files its images name by URI), each image, sampler and
texture written once however many materials use it."""

from __future__ import annotations

import numpy as np

from ..asset import Material, Texture
from .compress import UvRange
from .gltf_buffer import Buffer
from .gltf_container import file_uri
from .texture_files import TextureFiles

REPEAT, CLAMP_TO_EDGE, LINEAR, LINEAR_MIPMAP_LINEAR = 10497, 33071, 9729, 9987
_WRAP = {"REPEAT": REPEAT, "CLAMP": CLAMP_TO_EDGE}


class Textures:
    """Images, samplers (one per wrap mode) and textures, each written once however many
    materials use them. An image's PNG goes into the buffer, or with `files` (a .gltf) to a
    file beside the document (texture_files names it; `prefix`: a forest's prototype), which
    the image names by URI: the form a .gltf's users edit and other tools write."""

    def __init__(self, buf: Buffer, files: TextureFiles | None = None):
        self.buf = buf
        self.files = files
        self.images: list[dict] = []
        self.samplers: list[dict] = []
        self.textures: list[dict] = []
        self._tex: dict = {}
        self._sampler: dict = {}
        self._image: dict = {}

    def index(self, t: Texture, prefix: str = "") -> int:
        if t not in self._tex:
            if t.wrap not in self._sampler:
                self._sampler[t.wrap] = len(self.samplers)
                self.samplers.append(
                    {
                        "magFilter": LINEAR,
                        "minFilter": LINEAR_MIPMAP_LINEAR,
                        "wrapS": _WRAP[t.wrap],
                        "wrapT": _WRAP[t.wrap],
                    }
                )
            self._tex[t] = len(self.textures)
            self.textures.append({"sampler": self._sampler[t.wrap], "source": self.image(t, prefix)})
        return self._tex[t]

    def image(self, t: Texture, prefix: str = "") -> int:
        """Index of `t`'s image, written once; an image no material samples (the impostor's
        normal + depth atlas) gets no texture."""
        if t not in self._image:
            where = (
                {"uri": file_uri(self.files.name(t, prefix))}
                if self.files is not None
                else {"bufferView": self.buf.view(np.frombuffer(t.png, dtype=np.uint8), None)}
            )
            self.images.append({"name": t.name, **where, "mimeType": "image/png"})
            self._image[t] = len(self.images) - 1
        return self._image[t]

    def fields(self, gltf: dict) -> None:
        if self.textures:
            gltf |= {"images": self.images, "samplers": self.samplers, "textures": self.textures}


def material_dict(m: Material, textures: Textures, uvs: UvRange | None = None, prefix: str = "") -> dict:
    """A Material as a glTF metallic-roughness material: base colour (and texture), normal map,
    MASK with its cutoff for alpha-tested leaves, double-sided leaves. `uvs`: the box of
    quantized UVs, undone by KHR_texture_transform on each texture reference."""
    pbr: dict = {
        "baseColorFactor": [float(c) for c in m.base_color],
        "metallicFactor": float(m.metallic),
        "roughnessFactor": float(m.roughness),
    }
    d: dict = {"name": m.name, "pbrMetallicRoughness": pbr}
    ext = {} if uvs is None or uvs.identity else {"extensions": uvs.transform()}
    if m.base_texture is not None:
        pbr["baseColorTexture"] = {"index": textures.index(m.base_texture, prefix), **ext}
    if m.normal_texture is not None:
        d["normalTexture"] = {"index": textures.index(m.normal_texture, prefix), **ext}
    if m.double_sided:
        d["doubleSided"] = True
    if m.alpha_cutoff is not None:
        d["alphaMode"] = "MASK"
        d["alphaCutoff"] = float(m.alpha_cutoff)
    return d
