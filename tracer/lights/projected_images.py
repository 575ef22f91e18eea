"""Images that point lights project: Mitsuba's textured ``spot`` and its ``projector``.

Both are point lights (``tracer.lights.techniques.point``) whose radiant intensity in the unit
direction d from the light toward a point is multiplied by an image's RGB value there. With
(x, y, z) = R d, R the rotation from world to the light's frame (z its axis), the image is
looked up at

    u = 1/2 + fu x / z,   v = 1/2 + fv y / z

(a pinhole projection through the plane z = 1), as Mitsuba 3.9.1 does:

- ``spot`` (src/emitters/spot.cpp, ``direction_to_uv``): fu = fv = 1 / (2 tan(cutoff)), so the
  image's inscribed disk fills the cone; the spot's falloff applies as well;
- ``projector`` (src/emitters/projector.cpp, ``sample_direction``): Mitsuba's perspective
  projection of the image's aspect ratio a = W / H and horizontal field of view fov_x,
  fu = -1 / (2 tan(fov_x / 2)), fv = -a / (2 tan(fov_x / 2)) (local +x is the image's left, as
  for a camera); nothing outside u, v in [0, 1] or behind the light (z <= 0), and the
  intensity is pi scale irradiance / cos^3(theta), cos theta = z: the irradiance on the plane
  at distance 1 along the axis is the image's (Mitsuba's normalization).

In the light table (``tracer.lights.LightTables.rows``) a light with an image links to a block
of rows after the candidates' (``appendix``): a header row (``HEADER_*`` columns), then the
texels, RGB row by row, packed 16 floats a row (float32, as the table holds everything).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..jit import jit
from ..textures import BILINEAR, FILTERS, WRAPS, Texture
from ..textures.lookup import bitmap_value

SPOT, PROJECTOR = 0, 1
KINDS = ("spot", "projector")
# Header columns.
TO_LOCAL, KIND, FACTOR_U, FACTOR_V, WIDTH, HEIGHT, WRAP, FILTER = 0, 9, 10, 11, 12, 13, 14, 15
HEADER_WIDTH = 16
# The table's float32 holds every integer up to 2^24 exactly: the offsets of blocks must stay below.
MAX_TABLE_FLOATS = 2**24


@dataclass
class ProjectedImage:
    """The image a point light projects.

    kind : ``spot`` or ``projector``.   to_local : (3, 3) rotation, world to the light's frame
    (its rows are the light's x, y and z axes in world).   factor_u, factor_v : fu, fv of the
    module docstring.   texture : a bitmap (``tracer.textures.Texture``: linear float32 pixels
    (H, W, 3), filter, wrap).   area : a projector's image area on the plane z = 1."""

    kind: str
    to_local: np.ndarray
    factor_u: float
    factor_v: float
    texture: Texture
    area: float = 0.0  # a projector's image on the plane z = 1 (``projector_frustum``)

    def block(self) -> np.ndarray:
        """The header and texel rows, ``(1 + ceil(3 H W / 16), 16)`` float32."""
        pixels = np.ascontiguousarray(self.texture.pixels, dtype=np.float32)
        height, width = pixels.shape[:2]
        header = np.zeros(HEADER_WIDTH)
        header[TO_LOCAL:TO_LOCAL + 9] = np.asarray(self.to_local, dtype=np.float64).reshape(9)
        header[[KIND, FACTOR_U, FACTOR_V, WIDTH, HEIGHT]] = (KINDS.index(self.kind), self.factor_u,
                                                             self.factor_v, width, height)
        header[WRAP] = WRAPS.index(self.texture.wrap)
        header[FILTER] = FILTERS.index(self.texture.filter)
        flat = pixels.reshape(-1)
        texels = np.zeros(-(-len(flat) // HEADER_WIDTH) * HEADER_WIDTH, dtype=np.float32)
        texels[:len(flat)] = flat
        return np.concatenate([header[None].astype(np.float32), texels.reshape(-1, HEADER_WIDTH)])

    def mean(self) -> float:
        """The mean of the image's channels: its share of the light's power (``emitters.points``)."""
        return float(np.mean(self.texture.pixels, dtype=np.float64))

    def digest(self) -> bytes:
        """Bytes that change with anything the light's image does, for the scene's digest."""
        header = self.block()[0].astype("<f4").tobytes()
        pixels = np.ascontiguousarray(self.texture.pixels, dtype="<f4")
        return b"projected image\0" + header + str(pixels.shape).encode() + pixels.tobytes()


@jit
def image_factor(rows, header: int, dx: float, dy: float, dz: float):
    """The RGB factor of the image whose header is row ``header`` of ``rows`` in the unit
    direction (dx, dy, dz) from the light (module docstring): the texel value (a projector's
    times 1 / cos^3), 0 outside the image."""
    x = rows[header, TO_LOCAL] * dx + rows[header, TO_LOCAL + 1] * dy + rows[header, TO_LOCAL + 2] * dz
    y = rows[header, TO_LOCAL + 3] * dx + rows[header, TO_LOCAL + 4] * dy + rows[header, TO_LOCAL + 5] * dz
    z = rows[header, TO_LOCAL + 6] * dx + rows[header, TO_LOCAL + 7] * dy + rows[header, TO_LOCAL + 8] * dz
    if not z > 0.0:
        return 0.0, 0.0, 0.0
    u = 0.5 + rows[header, FACTOR_U] * x / z
    v = 0.5 + rows[header, FACTOR_V] * y / z
    projector = int(rows[header, KIND]) == PROJECTOR
    if projector and not (0.0 <= u <= 1.0 and 0.0 <= v <= 1.0):
        return 0.0, 0.0, 0.0
    # The texels follow the header row; the table is C-contiguous, so its flat view is theirs.
    r, g, b = bitmap_value(rows.reshape(-1), (header + 1) * HEADER_WIDTH, int(rows[header, WIDTH]),
                           int(rows[header, HEIGHT]), int(rows[header, WRAP]),
                           int(rows[header, FILTER]) == BILINEAR, u, v)
    if projector:
        inv = 1.0 / (z * z * z)
        return r * inv, g * inv, b * inv
    return r, g, b


def spot_factor(cutoff_radians: float) -> float:
    """fu = fv of a spot of that cutoff angle (module docstring)."""
    return 0.5 / math.tan(cutoff_radians)


def projector_frustum(tan_half_x: float, aspect: float) -> tuple[float, float, float, float]:
    """(fu, fv, the half-angle of the cone around the image's corners (radians), the image's
    area on the plane z = 1) of a projector of horizontal tan(fov_x / 2) and aspect W / H."""
    tan_half_y = tan_half_x / aspect
    return (-0.5 / tan_half_x, -0.5 * aspect / tan_half_x, math.atan(math.hypot(tan_half_x, tan_half_y)),
            4.0 * tan_half_x * tan_half_y)
