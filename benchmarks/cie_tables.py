#!/usr/bin/env python3
"""Writes tracer/scene/cie_tables.py, the CIE tables tracer's spectrum conversion uses, from
colour-science's copies of the CIE data.

- CIE 1931 2° colour-matching functions: colour's 'CIE 1931 2 Degree Standard Observer' (1 nm,
  360–830 nm), its entries at every 5 nm: the CIE's 5 nm table (CIE 15:2004, Table T.4).
- CIE D65: colour's 'D65' (CIE 15:2004 Table T.1, 5 nm, 300–780 nm) from 360 to 780 nm. Beyond
  780 nm, up to 830 nm, colour's table stops, and the values are the CIE daylight formula of
  CIE 15:2004 §3.1 (colour's ``sd_CIE_illuminant_D_series`` at the D65 chromaticity of
  6500 K × 1.4388 / 1.4380, M1 and M2 rounded to 3 decimals), cut (not rounded) to 4 decimals,
  which gives the values Mitsuba 3.9.1's D65 has there (rounding would make 825 nm 58.8766, not
  58.8765). Over 300–780 nm that formula lands within 0.0009 of Table T.1.

colour-science is not a tracer dependency; run this with an interpreter that has it, e.g.
``python -m venv /tmp/c && /tmp/c/bin/pip install colour-science && /tmp/c/bin/python
benchmarks/cie_tables.py``.
"""

from __future__ import annotations

import pathlib
import warnings

import numpy as np

warnings.filterwarnings("ignore")  # colour's notes on missing optional packages (scipy, matplotlib)
import colour  # noqa: E402
from colour.temperature import CCT_to_xy_CIE_D  # noqa: E402

OUT = pathlib.Path(__file__).resolve().parent.parent / "tracer" / "scene" / "cie_tables.py"
LAM = np.arange(360, 831, 5)

HEADER = '''"""CIE colorimetric tables (CIE 15:2004 / ISO 11664-1, -2), at 5 nm from 360 to 830 nm.

Written by ``benchmarks/cie_tables.py`` (do not edit by hand) from colour-science {version}'s
copies of the CIE data:

- ``CMF_1931``: the CIE 1931 2° standard observer's x̄, ȳ, z̄ (CIE 15:2004 Table T.4; colour's
  'CIE 1931 2 Degree Standard Observer', taken at every 5 nm);
- ``D65``: CIE standard illuminant D65's relative spectral power, 100 at 560 nm (CIE 15:2004
  Table T.1 up to 780 nm, colour's 'D65'; 785–830 nm from the CIE daylight formula of CIE 15:2004
  §3.1, colour's ``sd_CIE_illuminant_D_series``, cut to 4 decimals; these agree with Mitsuba
  3.9.1's D65 to float32 precision).
"""

# Wavelengths of the rows, nm: 360, 365, ..., 830.
LAMBDA_MIN, LAMBDA_STEP, LAMBDA_MAX = 360.0, 5.0, 830.0

'''


def main() -> None:
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    xyz = cmfs.values[np.searchsorted(cmfs.wavelengths, LAM)]
    assert np.array_equal(cmfs.wavelengths[np.searchsorted(cmfs.wavelengths, LAM)], LAM)
    table = colour.SDS_ILLUMINANTS["D65"]
    daylight = colour.sd_CIE_illuminant_D_series(CCT_to_xy_CIE_D(6500 * 1.4388 / 1.4380))
    d65 = []
    for lam in LAM:
        if lam <= table.wavelengths[-1]:
            d65.append(float(table.values[table.wavelengths == lam][0]))
        else:  # cut to 4 decimals, not rounded (see above)
            d65.append(np.floor(float(daylight.values[daylight.wavelengths == lam][0]) * 1e4 + 1e-6) / 1e4)
    rows = "\n".join(f"    ({x!r}, {y!r}, {z!r}),  # {lam}"
                     for lam, (x, y, z) in zip(LAM.tolist(), xyz.tolist(), strict=True))
    text = HEADER.format(version=colour.__version__)
    text += f"# (x̄, ȳ, z̄) at LAMBDA_MIN + i LAMBDA_STEP.\nCMF_1931 = (\n{rows}\n)\n\n"
    lines, line = [], "   "
    for value in d65:
        item = f" {round(float(value), 4)!r},"
        if len(line) + len(item) > 100:
            lines.append(line)
            line = "   "
        line += item
    lines.append(line)
    text += "# D65 at LAMBDA_MIN + i LAMBDA_STEP.\nD65 = (\n" + "\n".join(lines) + "\n)\n"
    OUT.write_text(text, encoding="utf-8")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
