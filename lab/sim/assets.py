"""Assets for the PyBullet worlds: seeded procedural textures and textured box meshes.

Textures are drawn with OpenCV from a seed, so that they are rich in SIFT features and the same on
every machine; the PNGs are committed under ``worlds/textures`` and rebuilt with::

    python -m lab.sim.assets            # rewrites worlds/textures/*.png

Meshes (OBJ + MTL with ``map_Kd``, which both TinyRenderer and EGL honour) are written on demand into
a cache folder, named by a hash of their content, by :func:`box_mesh`.

A plain PyBullet box shows the same part of its texture on every face, so a box whose faces differ
needs a mesh whose UVs point into a texture *atlas*: 3 x 2 cells of ``FACE_PX`` pixels, one per face,
in the order of :data:`FACES`.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import cv2
import numpy as np

from lab.errors import AssetError, ConfigError
from lab.io import write_bytes_atomic, write_text_atomic
from lab.paths import cache_dir, worlds_dir

__all__ = [
    "FACES",
    "FACE_PX",
    "atlas",
    "box_mesh",
    "magazine_texture",
    "tile_texture",
    "write_png_atomic",
    "main",
]

#: Face order in a texture atlas: cell (col, row) = (k % 3, k // 3), row 0 at the top of the image.
FACES = ("+X", "-X", "+Y", "-Y", "+Z", "-Z")
FACE_PX = 256

_FONTS = (
    cv2.FONT_HERSHEY_SIMPLEX,
    cv2.FONT_HERSHEY_DUPLEX,
    cv2.FONT_HERSHEY_TRIPLEX,
    cv2.FONT_HERSHEY_COMPLEX,
)


def _color(rng: np.random.Generator, palette: np.ndarray | None) -> tuple[int, int, int]:
    if palette is None:
        c = rng.integers(0, 256, 3)
    else:
        c = palette[rng.integers(0, len(palette))] + rng.integers(-25, 26, 3)
    return tuple(int(v) for v in np.clip(c, 0, 255))


def magazine_texture(
    seed: int, size: int = FACE_PX, palette=None, label: str | None = None, n_shapes: int = 28
) -> np.ndarray:
    """A "magazine page": colour blocks, circles, lines and words drawn from ``seed``.

    Parameters
    ----------
    seed : int
        The same seed gives the same image, pixel for pixel.
    size : int [px]
        Side of the square image.
    palette : array_like, shape (k, 3), optional
        RGB colours to draw from (with jitter); random colours when omitted.
    label : str, optional
        A large caption drawn across the middle (a model's name on its unique face).

    Returns
    -------
    img : ndarray, shape (size, size, 3), uint8, RGB
    """
    rng = np.random.default_rng(seed)
    pal = None if palette is None else np.asarray(palette, dtype=int).reshape(-1, 3)
    img = np.empty((size, size, 3), np.uint8)
    img[:] = _color(rng, pal)
    s = size / 256.0
    for _ in range(n_shapes):
        kind = rng.integers(0, 4)
        c = _color(rng, pal)
        x0, y0 = (int(v) for v in rng.integers(0, size, 2))
        if kind == 0:
            w, h = (int(v) for v in rng.integers(int(12 * s), int(90 * s), 2))
            cv2.rectangle(img, (x0, y0), (x0 + w, y0 + h), c, -1)
        elif kind == 1:
            cv2.circle(img, (x0, y0), int(rng.integers(int(6 * s), int(40 * s))), c, -1, cv2.LINE_AA)
        elif kind == 2:
            x1, y1 = (int(v) for v in rng.integers(0, size, 2))
            cv2.line(img, (x0, y0), (x1, y1), c, int(rng.integers(2, max(3, int(8 * s)))), cv2.LINE_AA)
        else:
            pts = rng.integers(0, size, (3, 2)).astype(np.int32)
            cv2.fillPoly(img, [pts], c, cv2.LINE_AA)
    for _ in range(7):
        # words of random letters: textures share no vocabulary, so their SIFT features do not alias
        word = "".join(chr(65 + int(c)) for c in rng.integers(0, 26, int(rng.integers(3, 8))))
        c = _color(rng, pal)
        ink = tuple(255 - v for v in c)
        x0, y0 = int(rng.integers(0, int(size * 0.55))), int(rng.integers(int(20 * s), size))
        cv2.putText(
            img,
            word,
            (x0, y0),
            _FONTS[rng.integers(0, len(_FONTS))],
            0.45 * s + rng.uniform(0, 0.4 * s),
            ink,
            max(1, int(2 * s)),
            cv2.LINE_AA,
        )
    if label:
        font = cv2.FONT_HERSHEY_DUPLEX
        scale = 2.6 * s
        (tw, th), _ = cv2.getTextSize(label, font, scale, int(5 * s))
        org = ((size - tw) // 2, (size + th) // 2)
        cv2.putText(img, label, org, font, scale, (255, 255, 255), int(9 * s), cv2.LINE_AA)
        cv2.putText(img, label, org, font, scale, (10, 10, 10), int(4 * s), cv2.LINE_AA)
    return img


def tile_texture(seed: int, size: int = 256, base=(150, 150, 150), contrast: int = 60) -> np.ndarray:
    """A low-contrast speckled tile (floor, walls): texture for dense stereo without strong SIFT features."""
    rng = np.random.default_rng(seed)
    noise = rng.normal(0.0, 1.0, (size // 8, size // 8))
    noise = cv2.resize(noise, (size, size), interpolation=cv2.INTER_CUBIC)
    fine = rng.normal(0.0, 0.5, (size, size))
    n = (noise + fine) / 1.5
    img = np.asarray(base, dtype=float)[None, None, :] + contrast * n[..., None] * np.array([1.0, 0.95, 0.9])
    img = np.clip(img, 0, 255).astype(np.uint8)
    cv2.rectangle(img, (0, 0), (size - 1, size - 1), tuple(int(0.6 * b) for b in base), 2)
    return img


def atlas(faces: dict[str, np.ndarray], fill=(200, 200, 200)) -> np.ndarray:
    """Assemble six face images (keys from :data:`FACES`; missing faces plain ``fill``) into an atlas."""
    px = next(iter(faces.values())).shape[0] if faces else FACE_PX
    out = np.empty((2 * px, 3 * px, 3), np.uint8)
    out[:] = fill
    for k, name in enumerate(FACES):
        if name in faces:
            img = faces[name]
            if img.shape[:2] != (px, px):
                raise ConfigError(
                    f"face {name} is {img.shape[1]}x{img.shape[0]} px, atlas cells are {px}x{px}"
                )
            r, c = divmod(k, 3)
            out[r * px : (r + 1) * px, c * px : (c + 1) * px] = img
    return out


def write_png_atomic(path: Path, img_rgb: np.ndarray) -> None:
    """Write an RGB image as PNG through a temporary file and a rename (never a half-written file)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ok, buf = cv2.imencode(".png", cv2.cvtColor(img_rgb, cv2.COLOR_RGB2BGR))
    if not ok:
        raise AssetError(f"could not encode {path}")
    write_bytes_atomic(path, buf.tobytes())


def _face_frames(size):
    """For each face: (outward normal, right, up, half width, half height) in the box frame."""
    sx, sy, sz = (0.5 * v for v in size)
    ex, ey, ez = np.eye(3)
    return {
        # vertical faces: up is +z, right = up x n (so a texture reads upright, unmirrored, from outside)
        "+X": (ex, ey, ez, sy, sz, sx),
        "-X": (-ex, -ey, ez, sy, sz, sx),
        "+Y": (ey, -ex, ez, sx, sz, sy),
        "-Y": (-ey, ex, ez, sx, sz, sy),
        "+Z": (ez, -ey, ex, sy, sx, sz),
        "-Z": (-ez, ey, ex, sy, sx, sz),
    }


def box_obj_text(
    size, uv_mode: str = "atlas", tile_m: float = 1.0, texture_name: str = "texture.png"
) -> tuple[str, str]:
    """OBJ and MTL text of a box of ``size`` (x, y, z) [m] centred on its origin, 24 vertices.

    ``uv_mode="atlas"``: each face's UVs cover its cell of a 3 x 2 atlas (:data:`FACES` order).
    ``uv_mode="tiled"``: UVs in metres / ``tile_m`` on every face, so the texture repeats.
    ``uv_mode="stretch"``: every face shows the whole texture once (posters).
    """
    if uv_mode not in ("atlas", "tiled", "stretch"):
        raise ConfigError(f"uv_mode {uv_mode!r} is not one of 'atlas', 'tiled', 'stretch'")
    size = np.asarray(size, dtype=float)
    if size.shape != (3,) or np.any(size <= 0) or not np.all(np.isfinite(size)):
        raise ConfigError(f"box size must be three positive lengths [m], got {size.tolist()}")
    v_lines, vt_lines, vn_lines, f_lines = [], [], [], []
    inset = 0.5 / (3 * FACE_PX)  # half a texel, so nearest-neighbour sampling never reads the next cell
    for k, name in enumerate(FACES):
        n, right, up, hw, hh, hd = _face_frames(size)[name]
        centre = n * hd
        corners = [
            centre - right * hw - up * hh,
            centre + right * hw - up * hh,
            centre + right * hw + up * hh,
            centre - right * hw + up * hh,
        ]
        if uv_mode == "atlas":
            r, c = divmod(k, 3)
            u0, u1 = c / 3 + inset, (c + 1) / 3 - inset
            v_top, v_bot = 1 - r / 2 - inset, 1 - (r + 1) / 2 + inset
            uvs = [(u0, v_bot), (u1, v_bot), (u1, v_top), (u0, v_top)]
        elif uv_mode == "stretch":
            uvs = [(0, 0), (1, 0), (1, 1), (0, 1)]
        else:
            w, h = 2 * hw / tile_m, 2 * hh / tile_m
            uvs = [(0, 0), (w, 0), (w, h), (0, h)]
        base = 4 * k
        for p, (u, v) in zip(corners, uvs, strict=True):
            v_lines.append(f"v {p[0]:.6f} {p[1]:.6f} {p[2]:.6f}")
            vt_lines.append(f"vt {u:.6f} {v:.6f}")
        vn_lines.append(f"vn {n[0]:.1f} {n[1]:.1f} {n[2]:.1f}")
        a, b, c_, d = (base + i + 1 for i in range(4))
        nk = k + 1
        f_lines.append(f"f {a}/{a}/{nk} {b}/{b}/{nk} {c_}/{c_}/{nk}")
        f_lines.append(f"f {a}/{a}/{nk} {c_}/{c_}/{nk} {d}/{d}/{nk}")
    obj = "\n".join(
        [
            "# lab box mesh",
            "mtllib box.mtl",
            "o box",
            *v_lines,
            *vt_lines,
            *vn_lines,
            "usemtl textured",
            "s off",
            *f_lines,
            "",
        ]
    )
    mtl = "\n".join(
        [
            "newmtl textured",
            "Ka 1 1 1",
            "Kd 1 1 1",
            "Ks 0 0 0",
            "d 1",
            "illum 1",
            f"map_Kd {texture_name}",
            "",
        ]
    )
    return obj, mtl


def box_mesh(size, texture: Path, uv_mode: str = "atlas", tile_m: float = 1.0) -> Path:
    """Path of a cached OBJ (with its MTL and a copy of the texture) for a textured box.

    The folder name is a hash of the mesh text and the texture bytes, so a changed texture or size
    gives a new mesh and a stale one is never reused. Files are written atomically.
    """
    texture = Path(texture)
    if not texture.is_file():
        raise AssetError(f"texture file {texture} does not exist (rebuild with `python -m lab.sim.assets`)")
    tex_bytes = texture.read_bytes()
    obj, mtl = box_obj_text(size, uv_mode, tile_m, "texture.png")
    key = hashlib.sha256(obj.encode() + mtl.encode() + tex_bytes).hexdigest()[:16]
    folder = cache_dir() / "meshes" / key
    obj_path = folder / "box.obj"
    if obj_path.is_file():
        return obj_path
    folder.mkdir(parents=True, exist_ok=True)
    tex_path = folder / "texture.png"
    write_bytes_atomic(tex_path, tex_bytes)
    write_text_atomic(folder / "box.mtl", mtl)
    write_text_atomic(obj_path, obj)  # last: its presence means the folder is complete
    return obj_path


# --- the committed textures ------------------------------------------------------------------------

#: The identification paper's database: 4 boxes, three vertical faces share one page, one is unique.
BOX_MODELS = 4
SHARED_SEED = 1000
UNIQUE_FACE = "+X"
SHARED_FACES = ("-X", "+Y", "-Y")

#: Searchable objects of the lab room: name -> (seed, RGB palette). Their colours give the global
#: search something to find; the distractors in the scene share some of them.
OBJECT_PALETTES = {
    "cereal_box": (2001, [(200, 30, 30), (240, 200, 40), (250, 250, 240)]),
    "book": (2002, [(30, 60, 170), (230, 230, 240), (20, 20, 40)]),
    "toy_block": (2003, [(40, 160, 60), (240, 220, 60), (20, 60, 20)]),
}


def build_textures(out: Path | None = None) -> list[Path]:
    """(Re)draw every committed texture into ``out`` (default ``worlds/textures``)."""
    out = Path(out) if out else worlds_dir() / "textures"
    written = []
    shared = magazine_texture(SHARED_SEED)
    top = np.full((FACE_PX, FACE_PX, 3), (205, 200, 190), np.uint8)
    for k in range(BOX_MODELS):
        unique = magazine_texture(100 + k, label=("ALPHA", "BRAVO", "DELTA", "KILO")[k])
        faces = {UNIQUE_FACE: unique, "+Z": top, "-Z": top}
        faces.update({f: shared for f in SHARED_FACES})
        p = out / f"box{k}.png"
        write_png_atomic(p, atlas(faces))
        written.append(p)
    for name, (seed, pal) in OBJECT_PALETTES.items():
        faces = {f: magazine_texture(seed * 10 + i, palette=pal, n_shapes=34) for i, f in enumerate(FACES)}
        p = out / f"{name}.png"
        write_png_atomic(p, atlas(faces))
        written.append(p)
    for name, seed, base, contrast in (
        ("floor", 3001, (150, 140, 125), 45),
        ("wall", 3002, (205, 205, 195), 30),
        ("wood", 3003, (140, 95, 60), 35),
        ("metal", 3004, (120, 125, 130), 25),
    ):
        p = out / f"{name}.png"
        write_png_atomic(p, tile_texture(seed, base=base, contrast=contrast))
        written.append(p)
    for k in range(3):
        p = out / f"poster{k}.png"
        write_png_atomic(p, magazine_texture(4000 + k, size=FACE_PX, n_shapes=20))
        written.append(p)
    for k in range(3, 3 + GREY_POSTERS):
        p = out / f"poster{k}.png"
        write_png_atomic(p, grey_texture(magazine_texture(4000 + k, size=FACE_PX, n_shapes=28)))
        written.append(p)
    return written


#: Posters 3, 4, ... are grey: landmarks for localization that hold no colour the global search could
#: take for an object's (its back-projection scores grey near zero, like the walls).
GREY_POSTERS = 9


def grey_texture(img: np.ndarray) -> np.ndarray:
    """``img`` (H, W, 3) RGB in grey levels only (luma), still three channels: texture without colour."""
    g = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    return np.repeat(g[:, :, None], 3, axis=2)


def main() -> None:
    for p in build_textures():
        print(p)


if __name__ == "__main__":
    main()
