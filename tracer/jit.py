"""The one way tracer compiles its per-lane code: numba's ``njit`` with fixed options.

The estimator runs a loop over lanes in compiled code instead of ~100 whole-array numpy passes
(see the README's Performance section): one pass per batch, no temporaries. Options:

- ``cache=True``: compiled machine code is kept beside the sources (``__pycache__``), so only
  the first run after an install or an edit pays for compilation;
- ``nogil=True``: render threads run the kernels on both cores at once;
- ``error_model="numpy"``: x / 0 gives inf or nan as in numpy instead of raising, so a
  degenerate sample is caught by the render loop's non-finite guard like before.

Floating-point semantics stay IEEE (no ``fastmath``): results match numpy to rounding.
"""

from __future__ import annotations

from numba import njit

jit = njit(cache=True, nogil=True, error_model="numpy", inline="always")
