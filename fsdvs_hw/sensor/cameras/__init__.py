"""Real event cameras: named presets with sourced values, simulated events compared with a
recording, a sensor configuration calibrated to a recording, and the test video for calibrating.

The main public names are exported by :mod:`fsdvs_hw.sensor`; this package imports nothing itself.
"""

__all__: list[str] = []
