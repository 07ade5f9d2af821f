"""The pixel model and the simulator: configuration, pixel response, spatial filtering, threshold
crossings, event frames, lists and voxel grids, streaming, the scene's model plan, photon noise,
frame upsampling and the simulation's threads.

The main public names are exported by :mod:`fsdvs_hw.sensor`; this package imports nothing itself, so
reading one module (the configuration's field names) does not import torch.
"""

__all__: list[str] = []
