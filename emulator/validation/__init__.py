"""Validation: the paper's experiments and the physical model's targets, side by side.

`report` writes docs/validation.md (`python -m emulator.validation`);
`physical_targets` measures the physical preset against its seven targets;
`reference_scenes` builds the small scenes (a room, a panel) they and the
tests share. It may import the flow (scene, optics, sensors) and `plots`;
nothing in the flow imports it.
"""
