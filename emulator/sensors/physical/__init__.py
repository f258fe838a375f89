"""The `physical` preset (docs/smoke-model.md §5): one echo-power mechanism behind every smoke behaviour.

`preset` is the preset module the scene's `model = "physical"` selects
(`urg_values[_at]`, `lms_values[_at]`); `beams` gathers each beam's smoke and
surface physics from the optics, `echo` turns it into the receivers' echoes,
`noise` draws the seeded noise and fluctuations, `params` holds the constants.
It may import `emulator.scene`, `emulator.optics` and the rest of
`emulator.sensors`; nothing here formats bytes.
"""
