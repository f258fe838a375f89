"""`scale_smoke`: the same scene with thinner or thicker smoke (`--smoke-scale F`).

Sweeping one scene's smoke from clear air up shows what smoke alone does to a
sensor or a SLAM run (docs/slam-in-smoke.md): nothing else changes.
"""

from __future__ import annotations

import dataclasses

from emulator.scene.model import Density, Scene


def scale_smoke(scene: Scene, factor: float) -> Scene:
    """The scene with every smoke density (regions and plumes) times `factor`; at 0 no region or
    plume is left (clear air, also for presets where a plume particle blocks a beam whatever its density)."""
    if factor == 0.0:
        return dataclasses.replace(scene, regions=(), plumes=())
    regions = tuple(
        dataclasses.replace(region, density=Density(tuple((t, value * factor) for t, value in region.density.keyframes)))
        for region in scene.regions
    )
    plumes = tuple(dataclasses.replace(plume, density=plume.density * factor) for plume in scene.plumes)
    return dataclasses.replace(scene, regions=regions, plumes=plumes)
