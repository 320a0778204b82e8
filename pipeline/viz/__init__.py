"""``pipeline viz``: a session in Foxglove's 3-D panel (``viz.mcap``, docs/viz.md)."""
