"""The dimension map: which random number each decision of a camera sample uses.

Every random number of a render is ``u(seed, pixel, sample index, dimension)``
(``tracer.samplers``). This module is the one place that says which dimension feeds which
decision, so that a sampler that distributes points well per pair of dimensions (stratified,
Sobol: pbrt-v4's padded samplers) sees every 2-D decision on a pair of its own.

Dimensions come in pairs ``(2 i, 2 i + 1)``:

======================  ===========================================  =======================
pair                    decision                                      dimensions
======================  ===========================================  =======================
0                       camera jitter inside the pixel (x, y)         0, 1
1                       technique choice of one-sample MIS; unused    2, (3)
2 + 2 j                 light sample j: the point on the emitter      4 + 4 j, 5 + 4 j
3 + 2 j                 light sample j: which light; unused           6 + 4 j, (7 + 4 j)
2 + 2 N + 2 j           direction sample j (N light samples)          4 + 4 N + 4 j, + 1
3 + 2 N + 2 j           direction sample j: which lobe; unused        6 + 4 N + 4 j, (+ 1)
2 + 2 N + 2 M           a thin lens's point (M direction samples)     4 + 4 N + 4 M, + 1
======================  ===========================================  =======================

The lens takes the pair after every other decision, so that a render without one keeps the
dimensions (and so the bits) it had before thin lenses existed.

1-D decisions take the first dimension of a pair of their own and leave the second unused,
which costs nothing for counter-based samplers and keeps each pair a clean 2-D point set.
"""

from __future__ import annotations

from ..jit import jit

CAMERA_JITTER = 0
TECHNIQUE_CHOICE = 2
_FIRST_LIGHT = 4
_PER_LIGHT = 4
_PER_DIRECTION = 4


@jit
def light_point(j: int) -> int:
    """First of the two dimensions of the point sampled on the emitter by light sample ``j``."""
    return _FIRST_LIGHT + _PER_LIGHT * j


@jit
def light_choice(j: int) -> int:
    """The dimension that chooses the light of light sample ``j``."""
    return _FIRST_LIGHT + _PER_LIGHT * j + 2


@jit
def direction(n_light: int, j: int) -> int:
    """First of the two dimensions of direction sample ``j`` after ``n_light`` light samples."""
    return _FIRST_LIGHT + _PER_LIGHT * n_light + _PER_DIRECTION * j


@jit
def lobe_choice(n_light: int, j: int) -> int:
    """The dimension that chooses the material lobe of direction sample ``j``."""
    return _FIRST_LIGHT + _PER_LIGHT * n_light + _PER_DIRECTION * j + 2


def lens(n_light: int, n_direction: int) -> int:
    """First of the two dimensions of a thin lens's point after ``n_light`` light and
    ``n_direction`` direction samples (from Python: the camera's kernel takes it as an argument)."""
    return _FIRST_LIGHT + _PER_LIGHT * n_light + _PER_DIRECTION * n_direction
