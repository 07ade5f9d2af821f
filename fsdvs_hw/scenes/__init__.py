"""Scenes for the event simulator: synthetic clips with ground truth, and real video.

Submodules are imported on use; see ``synthetic`` (moving objects with boxes, labels and masks)
and ``video`` (real clips decoded with imageio, converted to linear intensity).
"""
