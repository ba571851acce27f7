"""Writes the textured OBJ/MTL/PNG meshes of the tools (run once; the outputs are committed).

The tools carry high-contrast checker textures so that a corner detector finds trackable
corners on them (the paper tracked corners on the held rod). Usage:
``python models/generate_assets.py`` (needs numpy and opencv, both project dependencies).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

HERE = Path(__file__).resolve().parent / "meshes"

# The 6 faces of an axis-aligned box: (outward normal axis, sign, u axis, v axis).
_FACES = [
    (0, +1, 1, 2), (0, -1, 1, 2),
    (1, +1, 0, 2), (1, -1, 0, 2),
    (2, +1, 0, 1), (2, -1, 0, 1),
]


def checker(width: int, height: int, cols: int, rows: int, colors) -> np.ndarray:
    """An RGB checker image with ``cols x rows`` cells alternating between two colours."""
    img = np.empty((height, width, 3), np.uint8)
    for r in range(rows):
        for c in range(cols):
            img[r * height // rows:(r + 1) * height // rows,
                c * width // cols:(c + 1) * width // cols] = colors[(r + c) % 2]
    return img


# The rod (hand_eye.yaml): 50 mm square, 0.3 m long. Each side face is black with a two-column
# yellow checker of 18 mm x 25 mm cells between 7 mm plain margins, so that every image corner on
# it is a checker saddle on the face's centre line or a cell corner 7 mm inside the face's edge: a
# point fixed on the rod's surface. The long edges are plain black (a silhouette against the
# background is a straight edge, no corner), and so are the rod's ends. A 25 mm checker bar (the
# first version) was ~7 px wide at 320x240: its corners were silhouette corners that slid along the
# bar and onto the background, and the depth there mixed rod and background
# (bench/bench_hand_eye_candidates.py).
ROD_WIDTH = 0.050  # m
ROD_LENGTH = 0.300  # m
ROD_TEXEL = 0.0005  # m per texture pixel
ROD_MARGIN = 0.007  # m
ROD_CELL = 0.018  # m across
ROD_ROW = 0.025  # m along


def rod_texture(light, dark) -> np.ndarray:
    """One side face of the rod (u across, v along it): a two-column checker of ROD_CELL cells
    between plain dark margins of ROD_MARGIN."""
    width, height = round(ROD_WIDTH / ROD_TEXEL), round(ROD_LENGTH / ROD_TEXEL)
    img = np.empty((height, width, 3), np.uint8)
    img[:] = dark
    margin, cell = round(ROD_MARGIN / ROD_TEXEL), round(ROD_CELL / ROD_TEXEL)
    row = round(ROD_ROW / ROD_TEXEL)
    for r in range(height // row):
        c = r % 2
        u0 = margin + c * cell
        img[r * row:(r + 1) * row, u0:u0 + cell] = light
    return img


# The backdrop (scenario key ``backdrop``): posters on the back wall, so the static scene has corners
# of its own (a camera that turns sees them all move together; a plain wall shows none). Each poster
# is a light sheet with a few dark blocks; seen from the head, 4 m away at 320x240 (14 mm per pixel),
# the blocks are 7-25 px.
BACKDROP_SIZE = (6.0, 2.0)  # m, width (world y) x height (world z)
BACKDROP_TEXEL = 0.005  # m per texture pixel


def backdrop_texture(seed: int = 0) -> np.ndarray:
    """A wall of posters (u along the wall, v up), drawn from a fixed seed."""
    rng = np.random.default_rng(seed)
    width, height = (round(x / BACKDROP_TEXEL) for x in BACKDROP_SIZE)
    img = np.empty((height, width, 3), np.uint8)
    img[:] = (200, 198, 190)
    posters = 0
    while posters < 28:
        w, h = (int(rng.integers(60, 110)), int(rng.integers(70, 130)))
        u, v = int(rng.integers(0, width - w)), int(rng.integers(0, height - h))
        if (img[v - 10 if v >= 10 else 0:v + h + 10, max(u - 10, 0):u + w + 10] != img[0, 0]).any():
            continue  # keep posters apart: each corner belongs to one
        sheet = tuple(int(x) for x in rng.integers(215, 250, 3))
        img[v:v + h, u:u + w] = sheet
        for _ in range(int(rng.integers(2, 5))):
            bw, bh = int(rng.integers(12, w // 2)), int(rng.integers(12, h // 2))
            bu, bv = u + int(rng.integers(4, w - bw - 4)), v + int(rng.integers(4, h - bh - 4))
            img[bv:bv + bh, bu:bu + bw] = tuple(int(x) for x in rng.integers(10, 140, 3))
        posters += 1
    return np.ascontiguousarray(img[::-1])  # image rows run down, v up


def box_obj(name: str, size, center=(0.0, 0.0, 0.0), plain_axis: int | None = None,
            plain_uv=(0.0, 0.0)) -> str:
    """An OBJ box whose every face maps the whole texture (u along the first in-face axis).

    The two faces normal to ``plain_axis`` (if given) take the single texel at ``plain_uv``
    instead: a plain colour (the ends of a rod; squeezing the whole texture onto them would put
    corners there)."""
    half = np.asarray(size, float) / 2
    center = np.asarray(center, float)
    v_lines, vt_lines, vn_lines, f_lines = [], [], [], []
    for i, (n, s, ua, va) in enumerate(_FACES):
        corners = []
        for du, dv in [(-1, -1), (1, -1), (1, 1), (-1, 1)]:
            p = np.zeros(3)
            p[n], p[ua], p[va] = s * half[n], du * half[ua], dv * half[va]
            corners.append(center + p)
        # Keep the winding counter-clockwise seen from outside.
        normal = np.zeros(3)
        normal[n] = s
        if np.dot(np.cross(corners[1] - corners[0], corners[2] - corners[0]), normal) < 0:
            corners = corners[::-1]
            uvs = [(0, 1), (1, 1), (1, 0), (0, 0)]
        else:
            uvs = [(0, 0), (1, 0), (1, 1), (0, 1)]
        if n == plain_axis:
            uvs = [plain_uv] * 4
        for p, uv in zip(corners, uvs, strict=True):
            v_lines.append("v {:.6f} {:.6f} {:.6f}".format(*p))
            vt_lines.append("vt {} {}".format(*uv))
        vn_lines.append("vn {:.0f} {:.0f} {:.0f}".format(*normal))
        k = 4 * i
        f_lines.append(
            "f " + " ".join(f"{k + j + 1}/{k + j + 1}/{i + 1}" for j in range(4)))
    return "\n".join(
        ["# generated by generate_assets.py", f"mtllib {name}.mtl", f"o {name}"]
        + v_lines + vt_lines + vn_lines + [f"usemtl {name}"] + f_lines) + "\n"


def mtl(name: str) -> str:
    return (f"newmtl {name}\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nd 1\nillum 1\n"
            f"map_Kd {name}.png\n")


def write(name: str, obj: str, image: np.ndarray) -> None:
    (HERE / f"{name}.obj").write_text(obj)
    (HERE / f"{name}.mtl").write_text(mtl(name))
    cv2.imwrite(str(HERE / f"{name}.png"), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))


def main() -> None:
    HERE.mkdir(exist_ok=True)
    # Rod: 0.3 m long along +z, from 0.05 m behind the grasp point to its tip at 0.25 m.
    yellow, black = (250, 210, 20), (20, 20, 20)
    write("rod", box_obj("rod", (ROD_WIDTH, ROD_WIDTH, ROD_LENGTH), center=(0, 0, 0.1),
                         plain_axis=2, plain_uv=(0.02, 0.5)),
          rod_texture(yellow, black))
    # Box: 0.2 x 0.15 x 0.12 m, its top face at the grasp point, hanging along +z.
    white, blue = (235, 235, 235), (30, 60, 200)
    write("box", box_obj("box", (0.2, 0.15, 0.12), center=(0, 0, 0.06)),
          checker(256, 256, 4, 4, (white, blue)))
    # Backdrop: a 2 cm panel; only its front face (+x, toward the head) is seen.
    write("backdrop", box_obj("backdrop", (0.02, *BACKDROP_SIZE)), backdrop_texture())


if __name__ == "__main__":
    main()
