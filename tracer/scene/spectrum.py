"""Spectra to linear sRGB, as Mitsuba 3's RGB variants convert a scene's ``<spectrum>`` values.

A Mitsuba scene may give a colour as a spectrum: one number (a constant) or
``"wavelength:value, ..."`` pairs in nm, linear between the pairs and 0 outside them. tracer
renders in linear sRGB, so such a spectrum becomes an RGB triple when the scene is read. This
module does what Mitsuba 3.9.1's ``scalar_rgb`` variant does (its ``spectrum_list_to_srgb``),
a recipe worked out by matching that function's outputs, not taken from its code:

- **Tabulated spectra** are sampled at 1000 points x_i = 360 + 470 i / 999 nm (i = 0..999),
  skipping the points outside the spectrum's own first and last wavelengths (where it is 0).
  At each point the spectrum (linear between its pairs) times the CIE 1931 2° colour-matching
  functions (x̄, ȳ, z̄) is added up, each sample weighted 470 / 1000 nm (a little less than
  the spacing 470 / 999: Mitsuba's choice, kept), and the XYZ sum goes to linear sRGB.
- **Emitters** (``radiance``, ``intensity``): the spectrum is the light's power, so
  XYZ = Σ S (x̄, ȳ, z̄) 0.47 / Y_E, where Y_E = Σ ȳ 0.47 over all 1000 points (106.750202;
  Mitsuba's constant is 106.750259, the same sum to float32's precision), so that the
  equal-energy spectrum 1 over 360–830 nm has Y = 1. A constant c is the equal-energy spectrum
  (CIE illuminant E), taken as XYZ = (c, c, c): sRGB c (1.204794, 0.948291, 0.908916), not
  (c, c, c) as ``<rgb>`` or ``<float>`` give (Mitsuba: c (1.20479, 0.948292, 0.908916)).
- **Reflectances and other non-emitter values** (``reflectance``, ``eta``, ``k``, ...): a
  constant stays that number in every channel. A tabulated spectrum is seen under CIE
  illuminant D65 (relative power, 100 at 560 nm): XYZ = Σ S D65 (x̄, ȳ, z̄) 0.47 / 10568,
  10568 being Mitsuba's value of ∫ D65 ȳ dλ (the CIE tables give 10567.08 summed at 1 nm, D65
  interpolated, and 10567.30 at 5 nm; the 1000-point sum is 10556.29). Mitsuba's D65 normalization constant is
  exactly 1 / (10568 / 106.750259), and the 106.750259 cancels against the one an emitter is
  divided by. So a reflectance of 1 everywhere comes to (0.998985, 0.998874, 0.998802), not
  white, in Mitsuba and here alike.
- Negative channels are clamped to 0, and for reflectances (``reflectance``,
  ``diffuse_reflectance``, ``specular_reflectance``) channels above 1 to 1 (Mitsuba warns
  "clamping out-of-gamut color"); the reader does that (``mitsuba_xml.py``), not this module.

The data: the CIE 1931 2° standard observer and D65, tabulated at 5 nm over 360–830 nm and
linear in between, are the CIE's (CIE 15:2004, Tables T.4 and T.1), in
:mod:`tracer.scene.cie_tables` (written by ``benchmarks/cie_tables.py`` from colour-science,
which says how). Mitsuba 3.9.1 uses the same tables: its ``mi.cie1931_xyz`` at the 95 table
wavelengths agrees with them to 6e-8 relative (float32), and its ``mi.cie_d65`` (divided by
its normalization) to 7e-6 in 100, including the 785–830 nm entries. XYZ -> linear sRGB is
the widely quoted six-decimal matrix for the Rec. 709 / sRGB primaries (0.64, 0.33), (0.30,
0.60), (0.15, 0.06) and white D65 (as in C. Poynton's "Color FAQ"), which is what
``mi.xyz_to_srgb`` applies (read off it with the unit vectors). The matrix computed exactly
from those primaries and the white (0.3127, 0.3290) of IEC 61966-2-1 differs from it by up
to 4.9e-4 in an entry and 3.2e-4 relative on equal-energy white, more than the agreement
sought here.

How far this lands from Mitsuba 3.9.1 (float32), as a fraction of the largest channel:
through ``mi.spectrum_list_to_srgb`` on 194 spectra, 14 picked ones (the tests' and edge
cases) and 180 random ones of 2 to 200 pairs with wavelengths in 340–850 nm, each as
reflectance and as emitter, within 6.2e-6 (reflectances) and 9.0e-6 (emitters); through
scenes loaded by Mitsuba and read with ``mi.traverse`` (the numbers, to 6 decimals, in
``tests/test_mitsuba_xml.py``), within 1.2e-6, every channel within 5.9e-6. For example
reflectance "400:0.1, 500:0.5, 600:0.8, 700:0.3": (0.752187, 0.645269, 0.271706), Mitsuba's
scene the same, its ``spectrum_list_to_srgb`` (0.752186, 0.645270, 0.271707); emitter
"400:2, 500:6, 600:9, 700:4": (10.038172, 7.132712, 3.266686), Mitsuba (10.038166, 7.132708,
3.266685) and (10.038175, 7.132703, 3.266683); "450:0.2, 550:0.8, 650:0.3" as reflectance
(0.417042, 0.726045, 0.113149) and emitter (0.506507, 0.696452, 0.087186), the same to 6
decimals in Mitsuba. What is left is Mitsuba's float32 arithmetic; tracer sums in float64.
"""

from __future__ import annotations

import numpy as np

from . import cie_tables

# Mitsuba's visible range, nm: spectra are integrated over it.
LAMBDA_MIN, LAMBDA_MAX = cie_tables.LAMBDA_MIN, cie_tables.LAMBDA_MAX
_TABLE_LAMBDA = np.arange(LAMBDA_MIN, LAMBDA_MAX + 0.5 * cie_tables.LAMBDA_STEP, cie_tables.LAMBDA_STEP)
_CMF_TABLE = np.array(cie_tables.CMF_1931, dtype=np.float64)
_D65_TABLE = np.array(cie_tables.D65, dtype=np.float64)
assert _CMF_TABLE.shape == (len(_TABLE_LAMBDA), 3) and _D65_TABLE.shape == (len(_TABLE_LAMBDA),)

# The sample points and each one's weight, nm (470 / 1000, not the spacing 470 / 999).
_STEPS = 1000
SAMPLES = LAMBDA_MIN + (LAMBDA_MAX - LAMBDA_MIN) * np.arange(_STEPS) / (_STEPS - 1)
_WEIGHT = (LAMBDA_MAX - LAMBDA_MIN) / _STEPS

# ∫ D65 ȳ dλ as Mitsuba 3.9.1 normalizes D65 with it (rounded; 10567.08 from the tables at 1 nm).
D65_Y = 10568.0


def cie_1931(lam: np.ndarray) -> np.ndarray:
    """(n, 3): x̄, ȳ, z̄ at wavelengths ``lam`` (nm), linear between the CIE's 5 nm entries, 0
    outside 360–830 nm."""
    lam = np.asarray(lam, dtype=np.float64)
    return np.stack([np.interp(lam, _TABLE_LAMBDA, _CMF_TABLE[:, k], left=0.0, right=0.0)
                     for k in range(3)], axis=-1)


def d65(lam: np.ndarray) -> np.ndarray:
    """CIE D65's relative power at ``lam`` (nm; 100 at 560 nm), linear between the 5 nm
    entries, 0 outside 360–830 nm."""
    return np.interp(np.asarray(lam, dtype=np.float64), _TABLE_LAMBDA, _D65_TABLE, left=0.0, right=0.0)


_CMF_SAMPLES = cie_1931(SAMPLES)
_D65_SAMPLES = d65(SAMPLES)
# Y of the equal-energy spectrum 1 as summed here: what an emitter's XYZ is divided by.
Y_EQUAL_ENERGY = float(np.sum(_CMF_SAMPLES[:, 1]) * _WEIGHT)

# CIE XYZ -> linear sRGB (Rec. 709 primaries, D65 white), six decimals, as Mitsuba applies it.
XYZ_TO_SRGB = np.array([[3.240479, -1.537150, -0.498535],
                        [-0.969256, 1.875991, 0.041556],
                        [0.055648, -0.204043, 1.057311]])


def constant_emitter_rgb(value: float) -> np.ndarray:
    """Linear sRGB of an emitter's constant spectrum ``value``: equal energy, XYZ = value (1, 1, 1)."""
    return XYZ_TO_SRGB @ np.full(3, float(value))


def tabulated_rgb(wavelengths: np.ndarray, values: np.ndarray, emitter: bool) -> np.ndarray:
    """Linear sRGB, unclamped, of the spectrum that is linear between ``(wavelengths[i],
    values[i])`` (nm, increasing) and 0 outside them: under D65, 1 about white, for a
    reflectance (``emitter`` False); as power, equal-energy 1 at Y = 1, for an emitter."""
    wavelengths = np.asarray(wavelengths, dtype=np.float64)
    values = np.asarray(values, dtype=np.float64)
    inside = (SAMPLES >= wavelengths[0]) & (SAMPLES <= wavelengths[-1])
    s = np.interp(SAMPLES[inside], wavelengths, values) * _WEIGHT
    if emitter:
        xyz = s @ _CMF_SAMPLES[inside] / Y_EQUAL_ENERGY
    else:
        xyz = (s * _D65_SAMPLES[inside]) @ _CMF_SAMPLES[inside] / D65_Y
    return XYZ_TO_SRGB @ xyz
