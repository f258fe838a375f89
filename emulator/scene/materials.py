"""Built-in surface materials, available to every scene without a [[materials]] entry.

The paper names these surfaces (section 3.3 and 6: white paper / MDF as the
reference target, reflecting gold paper, rusty steel heat shields; Pascoal et
al.'s black velvet) and describes how the lasers behave on them, but it gives
no reflectance numbers. Every reflectivity below is therefore OUR ASSUMPTION,
chosen as a plausible diffuse reflectance near the lasers' 785 nm (URG-04LX)
and 905 nm (LMS200) wavelengths:

- default       0.5   a mid-grey surface (concrete, painted metal)
- white_paper   0.9   white paper / MDF, the paper's reference target
- gold_paper    0.6   the paper's "reflecting gold paper": partly specular, so
                      less diffuse light returns than from white paper
- rusty_steel   0.25  the rusty steel plates beside the target in section 3.1
- black_velvet  0.02  Pascoal et al.'s black velvet, a near-perfect absorber
- retro_reflector 1.0 retro-reflective tape or a cat's-eye target (`retroreflective`):
                      it sends the light back towards the scanner, so the LMS200
                      sets its reflector bits (measuring modes 01, 03, 05) on it

A scene's [[materials]] table adds materials or overrides these by name.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Mapping

from emulator.scene.model import Material

DEFAULT_MATERIAL = "default"

BUILTIN_MATERIALS: Mapping[str, Material] = MappingProxyType(
    {
        material.name: material
        for material in (
            Material("default", reflectivity=0.5),
            Material("white_paper", reflectivity=0.9),
            Material("gold_paper", reflectivity=0.6),
            Material("rusty_steel", reflectivity=0.25),
            Material("black_velvet", reflectivity=0.02),
            Material("retro_reflector", reflectivity=1.0, retroreflective=True),
        )
    }
)
