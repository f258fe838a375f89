"""Measurements of the `physical` model against docs/smoke-model.md §5's validation targets.

Each function measures one behaviour from device values only (what a driver
would see), so the tests and docs/validation.md share the numbers.
`physical_section(figures_dir)` returns the markdown section with figures.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from emulator.optics import World
from emulator.scene import load_scene
from emulator.scene.model import Material
from emulator.sensors import lms200
from emulator.sensors.physical import preset as physical
from emulator.sensors.physical.params import (
    DEFAULT_PARAMS,
    PhysicalParams,
    urg_noise_sigma_m,
)
from emulator.sensors.physical.preset import LMS_SIGNAL_TO_NOISE
from emulator.sensors.response import apply_model_override
from emulator.sensors.urg04lx import MIN_VALUE_MM
from emulator.validation.reference_scenes import (
    cast_beams,
    panel,
    reference_scene,
    room,
)

PENETRATION_POWER = DEFAULT_PARAMS.penetration_power
URG_STEP_RAD = 2.0 * np.pi / 1024
NEAR_FRONT_RAD = URG_STEP_RAD * np.arange(-4, 5)  # nine beams within ±1.4° of straight ahead
SAMPLE_TIMES_S = np.arange(0.0, 400.0, 2.0)  # 2 s apart: longer than the fluctuation's correlation time


def urg_error_rate(
    optical_path: float,
    reflectivity: float = 0.9,
    range_m: float = 2.5,
    times_s: np.ndarray = SAMPLE_TIMES_S,
    params: PhysicalParams = DEFAULT_PARAMS,
) -> float:
    """Share of error codes on beams near the front of a URG facing a panel through homogeneous smoke."""
    material = Material("panel_material", reflectivity)
    scene = reference_scene(
        objects=(panel("target", range_m, material.name),),
        regions=(room(optical_path / range_m),),
        materials={material.name: material},
    )
    world = World(scene)
    errors = 0
    for time_s in times_s:
        hits, beams = cast_beams(scene, "urg", NEAR_FRONT_RAD, float(time_s), world)
        errors += int(np.count_nonzero(physical.urg_values(hits, beams, params) < MIN_VALUE_MM))
    return errors / (len(times_s) * len(NEAR_FRONT_RAD))


def fifty_percent_point(optical_paths: np.ndarray, rates: np.ndarray) -> float:
    """Where a rising error-rate curve crosses 0.5, interpolated linearly."""
    above = int(np.argmax(rates >= 0.5))
    if above == 0:
        return float(optical_paths[0])
    x0, x1, y0, y1 = optical_paths[above - 1], optical_paths[above], rates[above - 1], rates[above]
    return float(x0 + (0.5 - y0) * (x1 - x0) / (y1 - y0))


def lms_homogeneous_ranges(densities: np.ndarray, target_m: float = 2.0, times_s: np.ndarray = np.arange(0.0, 40.0, 2.0)) -> np.ndarray:
    """Mean reported range (m; NaN if every reading was an error) of an LMS200's front beam facing
    white paper at `target_m` through a room of homogeneous smoke (Pascoal et al.'s set-up)."""
    means = []
    for density in densities:
        scene = reference_scene(objects=(panel("target", target_m, "white_paper"),), regions=(room(float(density)),))
        world = World(scene)
        readings = []
        for time_s in times_s:
            hits, beams = cast_beams(scene, "lms", np.array([0.0]), float(time_s), world)
            value = int(physical.lms_values(hits, beams, "mm")[0])
            if value < lms200.ABOVE_MAXIMUM:
                readings.append(value / 1000.0)
        means.append(float(np.mean(readings)) if readings else float("nan"))
    return np.array(means)


@dataclass(frozen=True)
class MarulanBehaviour:
    """Phillips et al.'s four behaviours counted over an LMS200 waterfall of the `marulan` scene."""

    waterfall: np.ndarray  # (times, beams) device values
    times_s: np.ndarray
    hit_target: int
    hit_particulate: int
    no_return: int
    mixed: int
    error_rate_at_edges: float
    error_rate_inside: float
    errors_at_edges_share: float


def marulan_behaviour(times_s: np.ndarray = np.arange(0.0, 95.0, 1.0)) -> MarulanBehaviour:
    """Classify every beam against the same scene without smoke.

    hit target: within 0.1 m of the smoke-free reading; hit particulate: a
    range shorter than it (or where nothing solid is); no return: 8191 where
    a solid answers without smoke; mixed: 8187. A beam is at a plume edge
    when within ±3 beams (1.5°) there are both smoke returns and clean ones.
    """
    scene = apply_model_override(load_scene("marulan"), "physical")
    clear = dataclasses.replace(scene, plumes=(), regions=())
    angles = np.radians(np.arange(0.0, 180.5, 0.5) - 90.0)
    clear_hits, clear_beams = cast_beams(clear, "lms", angles, 0.0)
    baseline = physical.lms_values(clear_hits, clear_beams, "mm", dataclasses.replace(DEFAULT_PARAMS, noise=False))
    solid = baseline < lms200.ABOVE_MAXIMUM
    world = World(scene)
    rows = []
    counts = dict(target=0, particulate=0, no_return=0, mixed=0)
    at_edge = edge_beams = inside = inside_beams = 0
    for time_s in times_s:
        hits, beams = cast_beams(scene, "lms", angles, float(time_s), world)
        values = physical.lms_values(hits, beams, "mm")
        rows.append(values)
        ranged = values < lms200.ABOVE_MAXIMUM
        particulate = ranged & (~solid | (values < baseline - 100))
        target = ranged & solid & (np.abs(values - baseline) <= 100)
        error = values == LMS_SIGNAL_TO_NOISE
        counts["target"] += int(target.sum())
        counts["particulate"] += int(particulate.sum())
        counts["no_return"] += int(((values == lms200.NO_ECHO) & solid).sum())
        counts["mixed"] += int(error.sum())
        clean = target | ((values == lms200.NO_ECHO) & ~solid)
        near_smoke, near_clean = _within(particulate, 3), _within(clean, 3)
        edge = near_smoke & near_clean
        interior = near_smoke & ~near_clean
        at_edge += int((error & edge).sum())
        edge_beams += int(edge.sum())
        inside += int((error & interior).sum())
        inside_beams += int(interior.sum())
    return MarulanBehaviour(
        waterfall=np.array(rows),
        times_s=np.asarray(times_s),
        hit_target=counts["target"],
        hit_particulate=counts["particulate"],
        no_return=counts["no_return"],
        mixed=counts["mixed"],
        error_rate_at_edges=at_edge / max(edge_beams, 1),
        error_rate_inside=inside / max(inside_beams, 1),
        errors_at_edges_share=at_edge / max(counts["mixed"], 1),
    )


def _within(mask: np.ndarray, beams: int) -> np.ndarray:
    """True where `mask` holds for any beam within ±`beams`."""
    padded = np.concatenate([np.zeros(beams, bool), mask, np.zeros(beams, bool)])
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * beams + 1)
    return windows.any(axis=1)


@dataclass(frozen=True)
class ClearAirNoise:
    urg_range_m: tuple[float, ...]
    urg_half_width_95_m: tuple[float, ...]  # 1.96 × measured σ: compare with the datasheet's ±
    urg_datasheet_m: tuple[float, ...]
    lms_sigma_m: float  # per-beam scatter over time, pooled
    lms_systematic_max_m: float  # largest per-beam mean offset
    lms_systematic_sd_m: float  # spread of per-beam mean offsets (uniform in ±15 mm → 8.66 mm)


def clear_air_noise(times_s: np.ndarray = np.arange(0.0, 40.0, 0.1)) -> ClearAirNoise:
    """Clear-air range errors of both sensors against the exact ranges."""
    widths, datasheet = [], []
    distances = (0.5, 3.0)
    for distance in distances:
        scene = reference_scene(objects=(panel("target", distance, "white_paper"),))
        world = World(scene)
        errors = []
        for time_s in times_s:
            hits, beams = cast_beams(scene, "urg", np.array([0.0]), float(time_s), world)
            errors.append(physical.urg_values(hits, beams)[0] / 1000.0 - hits.solid_range_m[0])
        widths.append(1.96 * float(np.std(errors)))
        datasheet.append(float(urg_noise_sigma_m(np.array([distance]))[0] * 2.0))
    scene = reference_scene(objects=(panel("target", 3.0, "white_paper", width_m=4.0),))
    world = World(scene)
    angles = np.radians(np.arange(-30.0, 30.5, 0.5))
    samples = []
    for time_s in times_s[::2]:
        hits, beams = cast_beams(scene, "lms", angles, float(time_s), world)
        samples.append(physical.lms_values(hits, beams, "mm") / 1000.0 - hits.solid_range_m)
    samples = np.array(samples)
    offsets = samples.mean(axis=0)
    return ClearAirNoise(
        urg_range_m=distances,
        urg_half_width_95_m=tuple(widths),
        urg_datasheet_m=tuple(datasheet),
        lms_sigma_m=float(np.sqrt(np.mean(samples.var(axis=0)))),
        lms_systematic_max_m=float(np.abs(offsets).max()),
        lms_systematic_sd_m=float(offsets.std()),
    )


def urg_readings(densities: np.ndarray, material: str, target_m: float = 2.5, times_s: np.ndarray = np.arange(0.0, 20.0, 2.0)) -> np.ndarray:
    """URG front-beam values (times, densities) facing `material` through homogeneous smoke."""
    columns = []
    for density in densities:
        scene = reference_scene(objects=(panel("target", target_m, material),), regions=(room(float(density)),))
        world = World(scene)
        column = []
        for time_s in times_s:
            hits, beams = cast_beams(scene, "urg", np.array([0.0]), float(time_s), world)
            column.append(int(physical.urg_values(hits, beams)[0]))
        columns.append(column)
    return np.array(columns).T


def physical_section(figures_dir: Path) -> str:
    """The `physical` model's section of docs/validation.md; writes its figures into `figures_dir`."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # nan-means of all-error columns are expected
        return _render_section(Path(figures_dir))


def _render_section(figures_dir: Path) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figures_dir.mkdir(parents=True, exist_ok=True)

    # Target 2 and 3: S-curves
    optical_paths = np.linspace(0.5, 1.6, 12) * PENETRATION_POWER
    times = np.arange(0.0, 200.0, 2.0)
    curves = {
        "white paper (0.9), 2.5 m": [urg_error_rate(op, times_s=times) for op in optical_paths],
        "gold-like (0.6), 2.5 m": [urg_error_rate(op, reflectivity=0.6, times_s=times) for op in optical_paths],
        "dark (0.3), 2.5 m": [urg_error_rate(op, reflectivity=0.3, times_s=times) for op in optical_paths],
        "white paper (0.9), 3.5 m": [urg_error_rate(op, range_m=3.5, times_s=times) for op in optical_paths],
    }
    reference_fifty = fifty_percent_point(optical_paths, np.array(curves["white paper (0.9), 2.5 m"]))
    figure, axis = plt.subplots(figsize=(6.4, 3.6), dpi=100)
    for label, rates in curves.items():
        axis.plot(optical_paths * 1000, rates, marker="o", markersize=3, label=label)
    axis.axvline(PENETRATION_POWER * 1000, color="grey", linestyle="--", linewidth=1)
    axis.set_xlabel("optical path to the target (10⁻³ d·m)")
    axis.set_ylabel("URG-04LX error rate")
    axis.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(figures_dir / "physical_s_curve.png")
    plt.close(figure)

    # Target 4, the URG's regimes and the materials of section 3.3
    densities = np.array([0.0, 0.0005, 0.001, 0.0015, 0.002, 0.003, 0.004, 0.006, 0.008, 0.012, 0.02, 0.04, 0.08, 0.2])
    lms_densities = densities[densities <= 0.012]  # denser: readings of a few cm (docs/physical-model.md §4)
    lms_ranges = lms_homogeneous_ranges(lms_densities)
    urg = urg_readings(densities, "white_paper")
    urg_short = np.where(urg >= MIN_VALUE_MM, urg / 1000.0, np.nan)
    material_densities = np.linspace(0.0, 0.0034, 18)
    materials = {name: urg_readings(material_densities, name, times_s=np.arange(0.0, 40.0, 2.0)) for name in ("white_paper", "gold_paper", "rusty_steel")}
    figure, (left, right) = plt.subplots(1, 2, figsize=(10, 3.6), dpi=100)
    left.plot(lms_densities * 1000, lms_ranges, marker="o", label="LMS200 mean range")
    left.plot(densities * 1000, np.nanmean(urg_short, axis=0), marker="s", label="URG-04LX mean range")
    left.plot(densities * 1000, np.mean(urg < MIN_VALUE_MM, axis=0) * 2.0, linestyle=":", color="red", label="URG error share × 2 m")
    left.set_xscale("symlog", linthresh=0.5)
    left.set_xlabel("homogeneous smoke density (10⁻³ d)")
    left.set_ylabel("range (m)")
    left.set_title("white paper 2 m (LMS) / 2.5 m (URG)", fontsize=9)
    left.legend(fontsize=8)
    for name, values in materials.items():
        ranged = np.where(values >= MIN_VALUE_MM, values / 1000.0, np.nan)
        with np.errstate(invalid="ignore"):
            share = np.mean(np.isfinite(ranged), axis=0)
        mean = np.where(share > 0.5, np.nanmean(np.where(np.isfinite(ranged), ranged, np.nan), axis=0), np.nan)
        right.plot(material_densities * 1000, mean, marker="o", markersize=3, label=name)
    right.set_xlabel("homogeneous smoke density (10⁻³ d)")
    right.set_ylabel("URG-04LX mean range (m), while > 50 % valid")
    right.set_title("paper §3.3: target 2.5 m", fontsize=9)
    right.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(figures_dir / "physical_homogeneous.png")
    plt.close(figure)

    # Targets 5 and 6: the marulan waterfall
    marulan = marulan_behaviour()
    waterfall = marulan.waterfall.astype(float)
    shade = np.where(waterfall < lms200.ABOVE_MAXIMUM, waterfall / 1000.0, np.nan)
    figure, axis = plt.subplots(figsize=(6.4, 4.8), dpi=100)
    axis.imshow(shade, aspect="auto", cmap="gray", vmin=0.0, vmax=8.0, extent=(0.0, 180.0, marulan.times_s[-1], marulan.times_s[0]))
    errors = np.ma.masked_where(marulan.waterfall != LMS_SIGNAL_TO_NOISE, np.ones_like(waterfall))
    axis.imshow(errors, aspect="auto", cmap="autumn", extent=(0.0, 180.0, marulan.times_s[-1], marulan.times_s[0]))
    axis.set_xlabel("device angle (°)")
    axis.set_ylabel("time (s)")
    axis.set_title("marulan, model physical: dark = short, red = 8187, white = no echo", fontsize=9)
    figure.tight_layout()
    figure.savefig(figures_dir / "physical_marulan.png")
    plt.close(figure)

    noise = clear_air_noise()
    gold = np.where(materials["gold_paper"] >= MIN_VALUE_MM, materials["gold_paper"] / 1000.0, np.nan)
    gold_growth = np.nanmax(np.nanmean(gold, axis=0)) / np.nanmean(gold[:, 0]) - 1.0
    smoke_band = lms_ranges[np.isfinite(lms_ranges) & (lms_ranges < 1.9)]
    return "\n".join(
        [
            "## The `physical` model (beyond the paper)",
            "",
            "How the `physical` preset (docs/physical-model.md) meets the validation targets of",
            "docs/smoke-model.md §5. All numbers are measured from device values with noise and",
            "density fluctuations on; `tests/emulator/test_physical_*.py` assert them.",
            "",
            "![URG error rate vs optical path](figures/physical_s_curve.png)",
            "",
            "- **Target 1** (exact reduction): with noise, fluctuation, backscatter, mixed pixels and material",
            "  effects off, the reference beam equals `formsma2011` for any region arrangement (hypothesis test).",
            "- **Target 2**: the reference target's error rate is an S-curve with its 50 % point at",
            f"  {reference_fifty * 1000:.3f}·10⁻³ d·m (paper: 7.000·10⁻³).",
            "- **Target 3**: at a fixed optical path darker and farther targets fail more often (curves above).",
            "",
            "![Homogeneous smoke: LMS200 and URG-04LX; materials](figures/physical_homogeneous.png)",
            "",
            "- **Target 4**: the LMS200's reading of white paper 2 m away falls steadily from",
            f"  {smoke_band.max():.2f} m to {smoke_band.min():.2f} m as the smoke thickens (roughly as 1/density,",
            "  the paper's hypothesis 3); the URG-04LX fails near 2.8·10⁻³ d and returns short readings",
            "  again in very thick smoke (Pascoal's third regime).",
            f"- Gold paper's URG reading grows by up to {gold_growth * 100:.0f} % before it drops out (paper §3.3: 10 %);",
            "  rusty steel drops out early and unevenly from beam to beam.",
            "",
            "![marulan waterfall under the physical model](figures/physical_marulan.png)",
            "",
            f"- **Target 5**: 8187 at plume edges in {marulan.error_rate_at_edges * 100:.1f} % of edge beams versus",
            f"  {marulan.error_rate_inside * 100:.1f} % inside plumes ({marulan.errors_at_edges_share * 100:.0f} % of all 8187 lie on a plume edge).",
            f"- **Target 6**: hit target {marulan.hit_target}, hit particulate {marulan.hit_particulate},",
            f"  no return {marulan.no_return}, mixed (8187) {marulan.mixed} beams over {len(marulan.times_s)} scans.",
            f"- **Target 7**: URG 95 % error bound {noise.urg_half_width_95_m[0] * 1000:.1f} mm at 0.5 m (datasheet ±10 mm),",
            f"  {noise.urg_half_width_95_m[1] * 1000:.1f} mm at 3 m (±1 %: 30 mm); LMS200 σ {noise.lms_sigma_m * 1000:.2f} mm (5 mm),",
            f"  systematic offsets up to {noise.lms_systematic_max_m * 1000:.1f} mm (±15 mm).",
            "",
        ]
    )
