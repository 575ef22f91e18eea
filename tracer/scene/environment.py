"""A scene's environment: radiance arriving from every direction at infinity.

What the scene readers produce for Mitsuba's ``envmap`` and ``constant`` emitters and TOML's
``[environment]`` table; ``tracer.lights.environment`` turns it into what the kernels look up
and sample. At most one per scene, as in Mitsuba 3 (``Scene``: one environment emitter).

The map is latitude-longitude in Mitsuba 3's convention (src/emitters/envmap.cpp): in the map's
own frame (``to_world`` takes it to the world) a unit direction v has

    u = atan2(v.x, -v.z) / 2 pi  (wrapped to [0, 1)),    t = acos(v.y) / pi,

column i of W is centred at u = (i + 1/2) / W (periodic), row j of H lies at t = j / (H - 1)
(row 0 the +y pole, row H - 1 the -y pole), and the radiance is the bilinear interpolation of
the texels. A constant environment is a map whose texels are all one colour.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Mitsuba pads a smaller map to 2 columns and 3 rows by repeating its last column and row
# (``Bitmap::pad_to``, called by the envmap plugin); the lookup needs two rows at least.
MIN_WIDTH, MIN_HEIGHT = 2, 3
# A to_world whose linear part is farther than this from a rotation (or mirror) is refused:
# Mitsuba applies it to unnormalized directions, which a lookup of unit ones cannot reproduce.
ORTHOGONAL_TOLERANCE = 1e-4


@dataclass
class Environment:
    """The environment light of a scene.

    texels : (H, W, 3) float32 linear radiance, ``scale`` applied, H >= 3, W >= 2 (row 0 the
        +y pole of the map's frame).
    to_world : (3, 3) float64 rotation (or mirror) from the map's frame to the world.
    kind : ``envmap`` (a map from ``source``) or ``constant``.
    source : the image file a map came from ("" for a constant), as the scene names it.
    scale : the factor applied to the file's texels (kept so that a converted scene says it).
    file : that image file's path as found (the scene's folder or Mitsuba's search path), which
        a converted scene refers to ("": unknown).
    """

    texels: np.ndarray
    to_world: np.ndarray
    kind: str = "envmap"
    source: str = ""
    scale: float = 1.0
    file: str = ""

    def __post_init__(self) -> None:
        texels = np.asarray(self.texels, dtype=np.float32)
        if texels.ndim != 3 or texels.shape[2] != 3 or texels.shape[0] < 1 or texels.shape[1] < 1:
            raise ValueError(f"environment texels must be (H, W, 3), got {texels.shape}")
        height, width = max(texels.shape[0], MIN_HEIGHT), max(texels.shape[1], MIN_WIDTH)
        if (height, width) != texels.shape[:2]:
            texels = np.pad(texels, ((0, height - texels.shape[0]), (0, width - texels.shape[1]), (0, 0)),
                            mode="edge")
        self.texels = np.ascontiguousarray(texels)
        self.to_world = np.asarray(self.to_world, dtype=np.float64).reshape(3, 3)

    @classmethod
    def constant(cls, radiance) -> "Environment":
        """A constant environment of ``radiance`` (3,) from every direction."""
        rgb = np.asarray(radiance, dtype=np.float32).reshape(1, 1, 3)
        return cls(np.broadcast_to(rgb, (MIN_HEIGHT, MIN_WIDTH, 3)), np.eye(3), kind="constant")

    @property
    def radiance(self) -> np.ndarray:
        """(3,) a constant environment's radiance (the mean texel of a map)."""
        return self.texels.reshape(-1, 3).mean(axis=0).astype(np.float64)

    @property
    def emits(self) -> bool:
        return bool(np.any(self.texels > 0.0))


def rotation_problem(linear: np.ndarray) -> str | None:
    """Why the 3x3 ``linear`` cannot orient an environment (not finite, or not a rotation or a
    mirror to ``ORTHOGONAL_TOLERANCE``), else None."""
    linear = np.asarray(linear, dtype=np.float64)
    if not np.all(np.isfinite(linear)):
        return "numbers must be finite"
    if np.max(np.abs(linear.T @ linear - np.eye(3))) > ORTHOGONAL_TOLERANCE:
        return ("it must be a rotation (or a mirror): an environment is a lookup by direction, not "
                "scaled or sheared")
    return None
