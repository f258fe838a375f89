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
    volume_gain: the receiver's response to distributed (smoke) echoes
        relative to surface echoes (assumption, calibrated: the URG-04LX
        ignored fog backscatter up to its extinction at BOCAS, the LMS200
        sees dense smoke as an obstacle).
    gain_ramp_m: sensitivity time control: the receiver's gain grows as u^2
        up to this range, flattening the 1/u^2 law of near echoes (0 = none;
        assumption for the LMS200, whose first-echo range then falls as
        1/density in homogeneous smoke, the paper's hypothesis 3).
    """

    overlap_m: float
    footprint_rad: float
    detection: str | tuple[float, float] = "reference"
    volume_gain: float = 1.0
    gain_ramp_m: float = 0.0


@dataclass(frozen=True)
class UrgReceiver(ReceiverOptics):
    """AMCW phase receiver. `modulation_hz` sets how strongly returns at
    different ranges decohere (assumption); below `min_coherence` (|sum of
    phasors| / sum of powers) the two modulation waves disagree → error 8
    (assumption)."""

    modulation_hz: float = 20e6
    min_coherence: float = 0.9


@dataclass(frozen=True)
class LmsReceiver(ReceiverOptics):
    """Pulsed first-echo receiver integrating the echo energy over the last
    `window_m` of range (its integration time × c/2).

    An echo is clean when at least `sharp_fraction` of the threshold energy
    arrived within the last `max_rise_m` before the trigger; a smeared
    return (smoke building up slowly at a plume edge, or a weak target on a
    smoke background) is rejected as 8187, signal-to-noise too small
    (assumptions)."""

    window_m: float = 3.0
    sharp_fraction: float = 0.5
    max_rise_m: float = 0.5


@dataclass(frozen=True)
class PulsedReceiver(ReceiverOptics):
    """A pulsed time-of-flight receiver that reports up to `max_echoes` returns per beam
    (the multi-echo Hokuyos and SICKs; docs/physical-model.md §6 gives each number's source).

    separation_m: two returns closer than this merge into one echo: the pulse's
        length in range, c·pulse_width/2 (pulse_width_s is kept for the docs).
    wavelength_nm: the laser's wavelength (datasheet; smoke extinction is taken as
        grey, the same at every wavelength here).
    intensity_reference: the intensity the unit reports for the reference target
        (white paper at 2.5 m, normal incidence): intensity is linear in received power.
    intensity_max: the largest intensity the unit reports (saturation).
    fog_filter_m, fog_filter_gain: with the fog filter on, echoes nearer than
        `fog_filter_m` must be `fog_filter_gain` times stronger than the threshold.
    range_sigma_m: clear-air range noise (one standard deviation) of every echo.
    """

    max_echoes: int = 1
    separation_m: float = 0.6
    pulse_width_s: float = 4e-9
    wavelength_nm: float = 905.0
    intensity_reference: float = 6000.0
    intensity_max: int = 65535
    fog_filter_m: float = 0.0
    fog_filter_gain: float = 1.0
    range_sigma_m: float = 0.0


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
    # target, raised by multiple scattering in dense smoke as
    # (1 + (sigma / multiple_scattering_extinction)^3) (assumptions,
    # calibrated: see docs/physical-model.md)
    backscatter_ratio: float = 1e-4
    multiple_scattering_extinction: float = 1.5  # 1/m
    # correlated density fluctuations (assumption)
    fluctuation_bulk: float = 0.12
    fluctuation_edge: float = 0.9
    fluctuation_length_m: float = 0.3
    fluctuation_modes: int = 12
    fluctuation_angle_deg: float = 2.0
    fluctuation_time_s: float = 1.5
    # range bins along each beam's smoke, each this much wider than the one before
    bins: int = 16
    bin_growth: float = 1.25
    sub_rays: int = 3
    edge_jump: float = 0.05  # neighbours' ranges differing by this fraction mark a depth edge
    urg: UrgReceiver = field(default_factory=lambda: UrgReceiver(overlap_m=0.3, footprint_rad=np.radians(0.36)))
    lms: LmsReceiver = field(
        default_factory=lambda: LmsReceiver(
            overlap_m=0.05, footprint_rad=np.radians(0.25), detection=(0.1, 10.0), volume_gain=400.0, gain_ramp_m=2.5
        )
    )

    def exact(self) -> PhysicalParams:
        """No noise, no fluctuation, no backscatter, no mixed pixels, no material effects."""
        return replace(self, noise=False, fluctuation=False, backscatter=False, mixed_pixels=False, material_effects=False)


DEFAULT_PARAMS = PhysicalParams()


def _hokuyo(max_echoes: int, detection: tuple[float, float], range_sigma_m: float) -> PulsedReceiver:
    return PulsedReceiver(
        overlap_m=PULSED_OVERLAP_M, footprint_rad=np.radians(0.25), detection=detection, volume_gain=HOKUYO_VOLUME_GAIN,
        max_echoes=max_echoes, separation_m=HOKUYO_SEPARATION_M, pulse_width_s=2.0 * HOKUYO_SEPARATION_M / SPEED_OF_LIGHT_M_S,
        wavelength_nm=905.0, intensity_reference=6000.0, intensity_max=65535, range_sigma_m=range_sigma_m,
    )


def _sick(max_echoes: int, detection: tuple[float, float], footprint_rad: float, wavelength_nm: float, range_sigma_m: float,
          fog_filter_m: float = 0.0, rssi: tuple[float, int] = (200.0, 255)) -> PulsedReceiver:
    return PulsedReceiver(
        overlap_m=PULSED_OVERLAP_M, footprint_rad=footprint_rad, detection=detection, volume_gain=SICK_VOLUME_GAIN,
        max_echoes=max_echoes, separation_m=SICK_SEPARATION_M, pulse_width_s=2.0 * SICK_SEPARATION_M / SPEED_OF_LIGHT_M_S,
        wavelength_nm=wavelength_nm, intensity_reference=rssi[0], intensity_max=rssi[1], range_sigma_m=range_sigma_m,
        fog_filter_m=fog_filter_m, fog_filter_gain=FOG_FILTER_GAIN if fog_filter_m else 1.0,
    )


# The multi-echo receivers (docs/physical-model.md §6 gives each number's source).
HOKUYO_SEPARATION_M = 0.6  # assumption: a 4 ns pulse (Hokuyo publishes no pulse width)
SICK_SEPARATION_M = 0.75  # c × 5 ns / 2: the TiM5xx's maximum pulse duration (datasheet), taken for every SICK
HOKUYO_VOLUME_GAIN = 400.0  # assumption, the LMS200's: β·V = 0.04, a smoke lidar ratio of π / (0.04 ρ_ref) ≈ 87 sr
SICK_VOLUME_GAIN = 400.0  # the same
PULSED_OVERLAP_M = 0.3  # assumption, the URG-04LX's: the first decimetres fade out (smoke at the window is not a 0 m echo)
FOG_FILTER_GAIN = 2.6  # assumption: SICK's Dx1000 fog filter raises its minimum level from 500 to 1300 digits
LMS1XX_DIVERGENCE_RAD = 0.015  # LMS1xx operating instructions: spot = distance × 0.015 rad + 8 mm
LMS5XX_DIVERGENCE_RAD = 0.0046  # LMS5xx operating instructions, high resolution: distance × 0.0046 rad + 13 mm
PULSED_RECEIVERS: dict[str, PulsedReceiver] = {
    "utm-30lx": _hokuyo(1, (0.9, 30.0), 0.015),
    "utm-30lx-ew": _hokuyo(3, (0.9, 30.0), 0.015),
    "ust-10lx": _hokuyo(3, (0.9, 10.0), 0.020),
    "ust-20lx": _hokuyo(3, (0.9, 20.0), 0.020),
    "tim561": _sick(1, (0.1, 8.0), LMS1XX_DIVERGENCE_RAD, 850.0, 0.020),
    "tim571": _sick(1, (0.1, 8.0), LMS1XX_DIVERGENCE_RAD, 850.0, 0.020),
    "tim781": _sick(1, (0.1, 8.0), LMS1XX_DIVERGENCE_RAD, 850.0, 0.020),
    "lms111": _sick(2, (0.1, 18.0), LMS1XX_DIVERGENCE_RAD, 905.0, 0.012),
    "lms511": _sick(5, (0.1, 40.0), LMS5XX_DIVERGENCE_RAD, 905.0, 0.012, fog_filter_m=16.0, rssi=(20000.0, 65535)),
}

# Clear-air range error (datasheets, docs/smoke-model.md §3).
URG_ACCURACY_NEAR_M = 0.010  # ±10 mm below 1 m
URG_ACCURACY_RELATIVE = 0.01  # ±1 % of the reading above 1 m
URG_ACCURACY_COVERAGE_SIGMAS = 2.0  # we read "±" as a 95 % bound: sigma = figure / 2 (assumption)
LMS_SYSTEMATIC_M = 0.015  # ±15 mm systematic, per beam, fixed (uniform in ±15 mm: assumption)
LMS_SIGMA_M = 0.005  # σ ≈ 5 mm in mm mode


def urg_noise_sigma_m(range_m: np.ndarray) -> np.ndarray:
    accuracy = np.where(range_m < 1.0, URG_ACCURACY_NEAR_M, URG_ACCURACY_RELATIVE * range_m)
    return accuracy / URG_ACCURACY_COVERAGE_SIGMAS
