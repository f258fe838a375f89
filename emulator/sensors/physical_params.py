"""Every number of the `physical` model, with its source (docs/physical-model.md).

"assumption" marks a value we chose; "derived" one computed from the paper's
calibration; "datasheet" a manufacturer's figure.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

SPEED_OF_LIGHT_M_S = 299_792_458.0


@dataclass(frozen=True)
class ReceiverOptics:
    """One sensor's receiver.

    overlap_m: where transmitter and receiver fields of view overlap; the
        range law is (R_ref/u)^2 · (u^2/(u^2 + overlap^2))^2 so that echoes
        from the first few decimetres fade out (assumption).
    detection: "reference" = the echo that the reference target returns
        through exactly the penetration power (derived, paper eq. 1);
        otherwise a (reflectivity, range_m) target that is just detected in
        clear air (datasheet).
    footprint_rad: full beam width in the scan plane, spanned by the sub-rays
        that make mixed pixels (assumption).
    noise_*: clear-air range noise (datasheet, see `clear_air_sigma_m`).
    """

    overlap_m: float
    footprint_rad: float
    detection: str | tuple[float, float] = "reference"


@dataclass(frozen=True)
class UrgReceiver(ReceiverOptics):
    """AMCW phase receiver. modulation_hz sets how strongly returns at
    different ranges decohere (assumption); below `min_coherence` the two
    modulation waves disagree → error 8 (assumption); a blend whose smoke
    share exceeds `max_smoke_share` while the target still counts is
    ambiguous → error 8 as well (assumption)."""

    modulation_hz: float = 20e6
    min_coherence: float = 0.9


@dataclass(frozen=True)
class LmsReceiver(ReceiverOptics):
    """Pulsed first-echo receiver integrating the echo energy since emission.

    A clean echo rises from `onset_fraction` of the threshold to the
    threshold within `max_rise_m`; a slower (smeared) rise is rejected as
    8187, signal-to-noise too small (assumptions)."""

    onset_fraction: float = 0.25
    max_rise_m: float = 0.3


@dataclass(frozen=True)
class PhysicalParams:
    """Switches and constants. `exact()` gives the configuration that reduces to formsma2011."""

    noise: bool = True
    fluctuation: bool = True
    backscatter: bool = True
    mixed_pixels: bool = True
    material_effects: bool = True
    # the paper's calibration (eq. 1): white paper at 2.5 m fails at 0.007 d·m
    reference_reflectivity: float = 0.9  # white_paper in emulator/scene/materials.py
    reference_range_m: float = 2.5
    penetration_power: float = 0.0028 * 2.5
    # smoke backscatter per unit extinction relative to a white Lambertian
    # target (assumption, calibrated: see docs/physical-model.md §3)
    region_backscatter: float = 2e-4
    plume_backscatter: float = 0.3
    # correlated density fluctuations (assumption)
    fluctuation_bulk: float = 0.12
    fluctuation_edge: float = 0.9
    fluctuation_length_m: float = 0.3
    fluctuation_modes: int = 12
    fluctuation_time_s: float = 1.5
    # range bins along each beam's smoke
    bins: int = 48
    sub_rays: int = 4
    edge_jump: float = 0.05  # neighbours' ranges differing by this fraction mark a depth edge
    urg: UrgReceiver = field(default_factory=lambda: UrgReceiver(overlap_m=0.3, footprint_rad=np.radians(0.36)))
    lms: LmsReceiver = field(
        default_factory=lambda: LmsReceiver(overlap_m=0.1, footprint_rad=np.radians(0.25), detection=(0.1, 10.0))
    )

    def exact(self) -> PhysicalParams:
        """No noise, no fluctuation, no backscatter, no mixed pixels, no material effects."""
        return replace(self, noise=False, fluctuation=False, backscatter=False, mixed_pixels=False, material_effects=False)


DEFAULT_PARAMS = PhysicalParams()

# Clear-air range error (datasheets, SMOKE_MODEL.md §3).
URG_ACCURACY_NEAR_M = 0.010  # ±10 mm below 1 m
URG_ACCURACY_RELATIVE = 0.01  # ±1 % of the reading above 1 m
URG_ACCURACY_COVERAGE_SIGMAS = 2.0  # we read "±" as a 95 % bound: sigma = figure / 2 (assumption)
LMS_SYSTEMATIC_M = 0.015  # ±15 mm systematic, per beam, fixed (uniform in ±15 mm: assumption)
LMS_SIGMA_M = 0.005  # σ ≈ 5 mm in mm mode


def urg_noise_sigma_m(range_m: np.ndarray) -> np.ndarray:
    accuracy = np.where(range_m < 1.0, URG_ACCURACY_NEAR_M, URG_ACCURACY_RELATIVE * range_m)
    return accuracy / URG_ACCURACY_COVERAGE_SIGMAS
