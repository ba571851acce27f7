"""Writes the textured OBJ/MTL/PNG meshes of the tools (run once; the outputs are committed).

The rod and the box carry high-contrast checker textures so that a corner detector finds trackable
corners on them (the paper tracked corners on the held rod); the workshop tools (``wood_handle``,
``metal_bar``, ``speckle_bar``, ``plain_bar``) look like tools a workshop has, and their SDF
files are written here too. Every texture is drawn from a fixed seed (nothing is downloaded). Usage:
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
            plain_uv=(0.0, 0.0), slots: int = 1) -> str:
    """An OBJ box whose every face maps the whole texture (u along the first in-face axis).

    The two faces normal to ``plain_axis`` (if given) take the single texel at ``plain_uv``
    instead: a plain colour (the ends of a rod; squeezing the whole texture onto them would put
    corners there). With ``slots`` > 1 the texture is that many equal columns side by side (an
    atlas, see ``bar_atlas``) and the k-th textured face maps the k-th column only."""
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
        elif slots > 1:
            k = sum(1 for f in _FACES[:i] if f[0] != plain_axis)
            uvs = [(f"{(k + u) / slots:.6f}", v) for u, v in uvs]
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


# The workshop tools (scenario key ``tool.model``): bars of the rod's 50 mm square grip
# cross-section (the same gripper closing, ``tool.gripper_position``), the tool frame T as the
# rod's (origin at the grasp point, 0.05 m from the back end, z along the bar) and the tracked
# point at the tip. Their textures are an atlas (``bar_atlas``): one column per side face and a
# last column whose colour the two plain ends take. The prints are on the -x face (the one the
# head camera sees at the default posture) and the +y face.
BAR_WIDTH = ROD_WIDTH  # m: the grip cross-section, as the rod's
BAR_BACK = 0.05  # m from the back end to the grasp point (the rod's)
BAR_TEXEL = ROD_TEXEL  # m per texture pixel
# name: (length m, mass kg, wall m or 0 for solid, what it is). Masses from the materials:
# beech 700 kg/m^3 (solid), aluminium 2700 kg/m^3 and PVC 1400 kg/m^3 (square tubes).
WORKSHOP_TOOLS = {
    "wood_handle": (0.28, 0.49, 0.0, "A wooden handle (beech, solid): wood grain, a printed "
                    "sticker and a barcode sticker, scratches"),
    "metal_bar": (0.32, 0.33, 0.002, "A painted metal bar (aluminium square tube, 2 mm wall): "
                  "red paint with slight wear, one printed logo"),
    "speckle_bar": (0.30, 0.24, 0.003, "A speckled bar (PVC square tube, 3 mm wall): a fine "
                    "random black-and-white speckle, a few pixels per speck at 0.6-1 m"),
    "plain_bar": (0.30, 0.46, 0.003, "A plain bar (anodised aluminium square tube, 3 mm wall): "
                  "one colour, only its edges and ends show"),
}


def smooth_noise(rng: np.random.Generator, shape, cell: float) -> np.ndarray:
    """Zero-mean, unit-variance noise of ``shape`` that varies over about ``cell`` pixels."""
    coarse = rng.standard_normal((int(shape[0] / cell) + 3, int(shape[1] / cell) + 3))
    fine = cv2.resize(coarse, (shape[1] + 2 * round(cell), shape[0] + 2 * round(cell)),
                      interpolation=cv2.INTER_CUBIC)[round(cell):, round(cell):][:shape[0], :shape[1]]
    return (fine - fine.mean()) / fine.std()


def bar_atlas(faces, end_color) -> np.ndarray:
    """The atlas of a bar: its four side faces (RGB, as seen from outside, rows from the tip down
    to the back end) in box_obj's order (+x, -x, +y, -y), then a column of ``end_color`` for the
    ends. The -x and +y faces' u axis runs right to left seen from outside: their columns are
    stored mirrored, so that print reads the right way round."""
    end = np.empty_like(faces[0])
    end[:] = end_color
    columns = [np.ascontiguousarray(f[:, ::-1]) if i in (1, 2) else f for i, f in enumerate(faces)]
    return np.concatenate([*columns, end], axis=1)


def bar_obj(name: str, length: float) -> str:
    """The OBJ of a workshop bar: BAR_WIDTH square, ``length`` along +z from BAR_BACK behind the
    grasp point; side faces from the atlas, the ends plain (the atlas's last column)."""
    return box_obj(name, (BAR_WIDTH, BAR_WIDTH, length), center=(0, 0, length / 2 - BAR_BACK),
                   plain_axis=2, plain_uv=(0.9, 0.5), slots=5)


def text_block(lines, size, ink, paper, scale: float, thickness: int) -> np.ndarray:
    """``lines`` of text printed on a ``size`` (rows, cols) sheet, centred, each line at ``scale``."""
    img = np.empty((*size, 3), np.uint8)
    img[:] = paper
    font = cv2.FONT_HERSHEY_DUPLEX
    sizes = [cv2.getTextSize(t, font, scale, thickness)[0] for t in lines]
    gap = size[0] / (len(lines) + 1)
    for k, (text, (w, h)) in enumerate(zip(lines, sizes, strict=True)):
        org = (int((size[1] - w) / 2), int(gap * (k + 1) + h / 2))
        cv2.putText(img, text, org, font, scale, ink, thickness, cv2.LINE_AA)
    return img


def along(sheet: np.ndarray) -> np.ndarray:
    """A sheet drawn landscape turned to read along the bar (bottom to top of the face)."""
    return np.ascontiguousarray(np.rot90(sheet))


def paste(face: np.ndarray, sheet: np.ndarray, row: int) -> None:
    """Sticks ``sheet`` on ``face`` centred across it, its top at ``row``."""
    col = (face.shape[1] - sheet.shape[1]) // 2
    face[row:row + sheet.shape[0], col:col + sheet.shape[1]] = sheet


def barcode(rng: np.random.Generator, length_px: int, width_px: int) -> np.ndarray:
    """A barcode-like label, landscape: black bars 2-6 px (1-3 mm) wide on white, digits below."""
    img = np.full((width_px, length_px, 3), 245, np.uint8)
    col, quiet = 8, 8
    while col < length_px - quiet - 6:
        bar = int(rng.integers(2, 7))
        img[4:width_px - 18, col:col + bar] = 15
        col += bar + int(rng.integers(2, 7))
    digits = "".join(str(int(d)) for d in rng.integers(0, 10, 12))
    cv2.putText(img, digits, (10, width_px - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (15, 15, 15), 1,
                cv2.LINE_AA)
    return img


def wood_faces(rng: np.random.Generator, rows: int, cols: int) -> list[np.ndarray]:
    """Beech: grain lines along the bar, wavy, light and dark bands, fine fibres."""
    light, dark = np.array([196, 150, 98.0]), np.array([128, 82, 44.0])
    faces = []
    for _ in range(4):
        u = np.arange(cols)[None, :] + 10.0 * smooth_noise(rng, (rows, cols), 60)
        u = u + 2.0 * smooth_noise(rng, (rows, cols), 12)
        grain = (0.5 + 0.5 * np.sin(2 * np.pi * u / rng.uniform(9, 14))) ** 3
        band = 0.5 + 0.25 * smooth_noise(rng, (rows, cols), 150)
        t = np.clip(0.6 * grain + 0.4 * band, 0, 1)[..., None]
        fibre = 6.0 * cv2.resize(rng.standard_normal((rows // 8, cols)), (cols, rows))[..., None]
        faces.append(np.clip(light * (1 - t) + dark * t + fibre, 0, 255).astype(np.uint8))
    return faces


def scratch(rng: np.random.Generator, faces, count: int, shade: int) -> None:
    """``count`` thin straight scratches, lighter by ``shade``, mostly along the bar."""
    for _ in range(count):
        face = faces[int(rng.integers(0, len(faces)))]
        rows, cols = face.shape[:2]
        p0 = np.array([rng.uniform(0, cols), rng.uniform(0, rows)])
        angle = np.pi / 2 + rng.uniform(-0.6, 0.6)
        p1 = p0 + rng.uniform(10, 80) * np.array([np.cos(angle), np.sin(angle)])
        mask = np.zeros(face.shape[:2], np.uint8)
        cv2.line(mask, tuple(int(x) for x in p0), tuple(int(x) for x in p1), 255, 1, cv2.LINE_AA)
        face[:] = np.clip(face + shade * (mask[..., None] / 255.0), 0, 255).astype(np.uint8)


def wood_handle_texture(rng: np.random.Generator, rows: int, cols: int) -> np.ndarray:
    faces = wood_faces(rng, rows, cols)
    # A printed sticker on the -x face, a barcode sticker on the +y face; both between the grasp
    # (BAR_BACK from the back end, the bottom rows) and the tip (row 0).
    sticker = text_block(["WORKSHOP 7", "KEEP CLEAN", "INV 0427"], (80, 150), (25, 25, 25),
                         (238, 236, 226), 0.5, 1)
    paste(faces[1], along(sticker), 40)
    paste(faces[2], along(barcode(rng, 160, 70)), 90)
    scratch(rng, faces, 30, 45)
    return bar_atlas(faces, (150, 104, 60))


def metal_bar_texture(rng: np.random.Generator, rows: int, cols: int) -> np.ndarray:
    """Red paint, a slightly uneven sheen, worn to the bare metal in small spots near the edges."""
    paint = np.array([182, 40, 32.0])
    faces = []
    for _ in range(4):
        shade = 1 + 0.04 * smooth_noise(rng, (rows, cols), 80) + 0.015 * smooth_noise(rng, (rows, cols), 6)
        face = np.clip(paint * shade[..., None], 0, 255).astype(np.uint8)
        for _ in range(12):  # chips of the paint near the edges
            centre = (int(rng.choice([rng.integers(0, 6), rng.integers(cols - 6, cols)])),
                      int(rng.integers(0, rows)))
            axes = (int(rng.integers(1, 4)), int(rng.integers(2, 7)))
            cv2.ellipse(face, centre, axes, 0, 0, 360, (165, 165, 170), -1, cv2.LINE_AA)
        faces.append(face)
    # The logo, printed on the -x face between the tip and the grasp.
    red, white = tuple(int(x) for x in paint), (240, 240, 235)
    cv2.circle(faces[1], (cols // 2, 105), 38, white, -1, cv2.LINE_AA)
    cv2.circle(faces[1], (cols // 2, 105), 31, red, 3, cv2.LINE_AA)
    cv2.putText(faces[1], "SD", (cols // 2 - 24, 118), cv2.FONT_HERSHEY_DUPLEX, 1.2, red, 2,
                cv2.LINE_AA)
    return bar_atlas(faces, (150, 150, 155))


def speckle_bar_texture(rng: np.random.Generator, rows: int, cols: int) -> np.ndarray:
    """Band-limited noise (a 2 mm Gaussian blur of white noise) pushed to black and white: specks
    about 6 mm across (the median run of one shade), 3.5-6 px at 0.6-1 m from the 640x480 head
    camera (1.0-1.7 mm per px)."""
    faces = []
    for _ in range(4):
        z = cv2.GaussianBlur(rng.standard_normal((rows, cols)), (0, 0), 0.002 / BAR_TEXEL)
        grey = 128 + 110 * np.tanh(3 * z / z.std())
        faces.append(np.repeat(grey[..., None], 3, axis=2).astype(np.uint8))
    return bar_atlas(faces, (120, 120, 120))


def plain_bar_texture(rng: np.random.Generator, rows: int, cols: int) -> np.ndarray:
    del rng
    faces = [np.full((rows, cols, 3), (60, 118, 168), np.uint8) for _ in range(4)]
    return bar_atlas(faces, (60, 118, 168))


def bar_inertia(mass: float, length: float, wall: float) -> tuple[float, float]:
    """``(I_xx = I_yy, I_zz)`` about the centre of mass of a BAR_WIDTH square bar of ``length``:
    solid (``wall`` 0) or a square tube of that wall, of uniform density."""
    a, b = BAR_WIDTH, (BAR_WIDTH - 2 * wall if wall > 0 else 0.0)
    density = mass / ((a * a - b * b) * length)
    m_out, m_in = density * a * a * length, density * b * b * length
    ixx = (m_out * (a * a + length * length) - m_in * (b * b + length * length)) / 12
    izz = (m_out * 2 * a * a - m_in * 2 * b * b) / 12
    return ixx, izz


def tool_sdf(name: str, length: float, mass: float, wall: float, what: str) -> str:
    """The SDF of a workshop bar, laid out as ``rod_tool.sdf`` (tool frame T, tracked_point)."""
    ixx, izz = bar_inertia(mass, length, wall)
    com, tip = length / 2 - BAR_BACK, length - BAR_BACK
    return f"""<?xml version="1.0"?>
<!--
  Generated by models/generate_assets.py. {what}.
  {length:g} m long, {1e3 * BAR_WIDTH:g} mm square (the rod's grip cross-section), {mass:g} kg.
  Tool frame T: origin at the grasp point, z along the bar; the bar spans z in [{-BAR_BACK:g}, {tip:g}].
  tracked_point is the bar's tip (the point the hand-eye calibration tracks).
-->
<sdf version="1.9">
  <model name="{name}_tool">
    <link name="tool">
      <inertial><pose>0 0 {com:g} 0 0 0</pose><mass>{mass:g}</mass>
        <inertia><ixx>{ixx:.4g}</ixx><iyy>{ixx:.4g}</iyy><izz>{izz:.4g}</izz>
          <ixy>0</ixy><ixz>0</ixz><iyz>0</iyz></inertia>
      </inertial>
      <visual name="{name}">
        <geometry><mesh><uri>package://sustain_drake/meshes/{name}.obj</uri></mesh></geometry>
      </visual>
    </link>
    <frame name="tracked_point" attached_to="tool"><pose>0 0 {tip:g} 0 0 0</pose></frame>
  </model>
</sdf>
"""


TOOL_TEXTURES = {"wood_handle": wood_handle_texture, "metal_bar": metal_bar_texture,
                 "speckle_bar": speckle_bar_texture, "plain_bar": plain_bar_texture}


def write_workshop_tools(seed: int = 0) -> None:
    """The four workshop tools' SDF, OBJ/MTL and atlas PNG, each drawn from its own fixed stream."""
    cols = round(BAR_WIDTH / BAR_TEXEL)
    for k, (name, (length, mass, wall, what)) in enumerate(WORKSHOP_TOOLS.items()):
        rng = np.random.default_rng([seed, k])
        image = TOOL_TEXTURES[name](rng, round(length / BAR_TEXEL), cols)
        write(name, bar_obj(name, length), image)
        (HERE.parent / f"{name}_tool.sdf").write_text(tool_sdf(name, length, mass, wall, what))


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
    write_workshop_tools()


if __name__ == "__main__":
    main()
