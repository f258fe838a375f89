"""Pictures of scans over time (the waterfall of the paper's Fig. 3/5/10), with matplotlib.

It may import the flow (scene, optics, sensors); `commands.plot` and
`validation` use it.
"""
