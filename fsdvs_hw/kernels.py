"""Spatial kernels: taps on the sensor's pixel grid, reference families, loading and saving.

A :class:`Kernel` is what every other part of fsdvs_hw consumes and produces: a learned kernel
from training, a reference (delta, Gaussian, difference of Gaussians, Laplacian of Gaussian), or
the kernel a hardware realisation really implements. It holds an odd, square, finite float64
array of taps (row index = y, column index = x, centre tap at ``[r, r]`` with ``r = size // 2``)
and the sensor pixel pitch in metres, so that spatial frequencies can be turned into physical
units.

File formats (``Kernel.save`` / :func:`load_kernel`, chosen by extension):

``.npy``
    The taps only (``allow_pickle=False``).
``.csv``
    Comma-separated rows; an optional first comment line ``# fsdvs_hw {json}`` carries name,
    pitch and provenance.
``.json``
    ``{"format": "fsdvs_hw.kernel", "version": 1, "name", "pitch_m", "taps", "provenance"}``.
``.pt``
    ``torch.load(weights_only=True)`` only: a tensor (k×k, or 1×1×k×k as in a conv weight), or a
    dict with a ``"taps"`` (or ``"weight"``/``"kernel"``) tensor and optional ``"pitch_m"``,
    ``"name"``, ``"provenance_json"``. Arbitrary pickled objects are never loaded.
"""

from __future__ import annotations

import io
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import KernelError

__all__ = [
    "DEFAULT_PITCH_M",
    "MAX_KERNEL_FILE_BYTES",
    "MAX_KERNEL_SIZE",
    "PITCH_RANGE_M",
    "REFERENCE_KERNELS",
    "TAP_MAGNITUDE_RANGE",
    "Kernel",
    "as_kernel",
    "check_tap_magnitude",
    "delta_taps",
    "dog_taps",
    "gaussian_taps",
    "load_kernel",
    "load_kernel_or_reference",
    "log_taps",
    "reference_kernel",
    "validate_pitch",
]

#: Default sensor pixel pitch in metres: 4.86 µm, the pitch of the Sony IMX636 / Prophesee Gen4
#: event sensor (a common research DVS, 1280×720).
DEFAULT_PITCH_M: float = 4.86e-6

#: Largest kernel side accepted, in pixels. FS-DVS kernels are 3×3…9×9; realisations may be
#: evaluated on larger windows, but anything beyond this is almost certainly a mistake.
MAX_KERNEL_SIZE: int = 63

#: Largest |tap| a kernel may have where it meets float32 arithmetic or hardware (the simulator,
#: the fit functions, design files): squares of 1e15 are 1e30 < float32's 3.4e38 and nothing
#: vanishes. A :class:`Kernel` itself holds any finite float64 (its spectrum and CSF analysis are
#: scale-invariant); :func:`check_tap_magnitude` enforces this range where it matters.
TAP_MAGNITUDE_RANGE: tuple[float, float] = (1e-15, 1e15)

#: Largest kernel file read (bytes); kernels are at most 63×63 taps, a few hundred kB as text.
MAX_KERNEL_FILE_BYTES: int = 16 * 2**20

#: Allowed pixel pitch in metres, [low, high] (:func:`validate_pitch`; did you pass µm?).
PITCH_RANGE_M: tuple[float, float] = (1e-7, 1e-3)

_FORMAT_TAG = "fsdvs_hw.kernel"
_SUFFIXES = (".npy", ".csv", ".json", ".pt")


def _validate_taps(taps: Any, *, source: str = "taps") -> np.ndarray:
    """Return ``taps`` as a read-only float64 copy, or raise :class:`KernelError` naming the problem."""
    try:
        raw = taps if isinstance(taps, np.ndarray) else np.asarray(taps)
    except (TypeError, ValueError, RecursionError):
        raise KernelError(f"{source}: kernel taps must be a numeric 2-D array (rows of equal length)") from None
    if raw.dtype.kind == "c":
        raise KernelError(f"{source}: kernel taps must be real, got a complex array")
    if raw.dtype.kind not in "biuf":  # datetimes, strings, objects would convert silently or oddly
        raise KernelError(
            f"{source}: kernel taps must be numeric (booleans, integers, floats), got array dtype {raw.dtype}"
        )
    arr = np.array(raw, dtype=np.float64, copy=True)
    if arr.ndim != 2:
        raise KernelError(f"{source}: kernel taps must be 2-D, got {arr.ndim}-D with shape {arr.shape}")
    rows, cols = arr.shape
    if rows != cols:
        raise KernelError(f"{source}: kernel must be square, got shape {rows}x{cols}")
    if rows % 2 == 0:
        raise KernelError(f"{source}: kernel size must be odd (so it has a centre tap), got {rows}x{cols}")
    if rows > MAX_KERNEL_SIZE:
        raise KernelError(
            f"{source}: kernel size {rows}x{cols} is absurd for a per-pixel filter; allowed 1..{MAX_KERNEL_SIZE} (odd)"
        )
    bad = ~np.isfinite(arr)
    if bad.any():
        y, x = np.argwhere(bad)[0]
        raise KernelError(
            f"{source}: kernel taps must be finite; {int(bad.sum())} tap(s) are NaN/inf "
            f"(first at row {y}, column {x}: {arr[y, x]})"
        )
    if not np.any(arr != 0.0):
        raise KernelError(f"{source}: kernel is all zeros; it would pass no light and has no spectrum")
    arr.setflags(write=False)
    return arr


def check_tap_magnitude(taps: Any, *, source: str = "kernel") -> None:
    """Raise :class:`KernelError` unless the largest |tap| lies in :data:`TAP_MAGNITUDE_RANGE`.

    Called where a kernel meets float32 arithmetic or hardware: 1e300 taps pass a float64 check
    and become inf/NaN in float32 (or a NaN fit error), 1e-300 taps vanish.
    """
    arr = taps.taps if isinstance(taps, Kernel) else np.asarray(taps, dtype=np.float64)
    peak = float(np.abs(arr).max()) if arr.size else 0.0
    lo, hi = TAP_MAGNITUDE_RANGE
    if not lo <= peak <= hi:
        raise KernelError(
            f"{source}: largest |tap| is {peak:.3g}, outside the allowed [{lo:g}, {hi:g}] for "
            "the simulator and the hardware fits (float32 would overflow or lose it); "
            "rescale the kernel"
        )


def validate_pitch(pitch_m: Any, *, source: str = "pitch_m") -> float:
    """``pitch_m`` as a float in metres within the allowed pitch range (KernelError naming ``source``)."""
    try:
        p = float(pitch_m)
    except (TypeError, ValueError):
        raise KernelError(f"{source}: pixel pitch must be a number in metres, got {pitch_m!r}") from None
    lo, hi = PITCH_RANGE_M
    if not (math.isfinite(p) and lo <= p <= hi):
        raise KernelError(
            f"{source}: pixel pitch {p!r} m is outside the allowed range [{lo:g}, {hi:g}] m "
            "(did you pass micrometres instead of metres?)"
        )
    return p


@dataclass(frozen=True, eq=False)
class Kernel:
    """A spatial kernel on the sensor's pixel grid.

    Parameters
    ----------
    taps : array_like, shape (k, k)
        Kernel weights; ``k`` odd, 1 ≤ k ≤ :data:`MAX_KERNEL_SIZE`, finite, not all zero. Stored as
        a read-only float64 copy. Row index is y, column index is x; the centre tap is
        ``taps[k // 2, k // 2]``. Units: dimensionless (gain per input pixel).
    pitch_m : float, optional
        Sensor pixel pitch in metres (default :data:`DEFAULT_PITCH_M` = 4.86 µm).
    name : str, optional
        Short human-readable name.
    provenance : dict, optional
        JSON-serialisable record of where the kernel came from (training run, reference family and
        parameters, realisation).

    Raises
    ------
    KernelError
        If the taps are not 2-D, not square, of even or absurd size, contain NaN/inf or are all
        zeros, or if the pitch is not a plausible length in metres.

    Examples
    --------
    >>> import numpy as np
    >>> from fsdvs_hw import Kernel
    >>> k = Kernel(np.array([[0.0, -0.25, 0.0], [-0.25, 2.0, -0.25], [0.0, -0.25, 0.0]]), name="cross")
    >>> k.size, k.pitch_m
    (3, 4.86e-06)
    >>> round(float(k.taps.sum()), 6)          # DC gain
    1.0
    """

    taps: np.ndarray
    pitch_m: float = DEFAULT_PITCH_M
    name: str = "kernel"
    provenance: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "taps", _validate_taps(self.taps))
        object.__setattr__(self, "pitch_m", validate_pitch(self.pitch_m))
        if not isinstance(self.name, str):
            raise KernelError(f"name: kernel name must be a string, got {type(self.name).__name__}")
        try:
            prov = dict(self.provenance)
            json.dumps(prov)
        except (TypeError, ValueError, RecursionError) as exc:
            raise KernelError(f"provenance: must be JSON-serialisable ({exc})") from None
        object.__setattr__(self, "provenance", prov)

    # ------------------------------------------------------------------ properties
    @property
    def size(self) -> int:
        """Side length k in pixels."""
        return int(self.taps.shape[0])

    @property
    def radius(self) -> int:
        """Half-width ``k // 2`` in pixels."""
        return self.size // 2

    @property
    def dc_gain(self) -> float:
        """Sum of the taps: the response to a uniform input (dimensionless)."""
        return float(self.taps.sum())

    @property
    def centre(self) -> float:
        """The centre tap's value."""
        return float(self.taps[self.radius, self.radius])

    # ------------------------------------------------------------------ derived kernels
    def with_taps(self, taps: Any, *, name: str | None = None, **provenance: Any) -> Kernel:
        """A new kernel with other taps but this kernel's pitch (provenance extended)."""
        prov = {**self.provenance, **provenance}
        return Kernel(taps, pitch_m=self.pitch_m, name=name or self.name, provenance=prov)

    def scaled(self, factor: float) -> Kernel:
        """This kernel multiplied by ``factor`` (a non-zero finite number)."""
        if not (math.isfinite(factor) and factor != 0):
            raise KernelError(f"scale factor must be finite and non-zero, got {factor!r}")
        return self.with_taps(self.taps * factor)

    def normalised(self, mode: str = "peak") -> Kernel:
        """This kernel scaled by a positive constant.

        Parameters
        ----------
        mode : {"peak", "sum", "l2", "centre"}
            ``peak``: max |tap| = 1; ``sum``: taps sum to 1 (needs non-zero DC); ``l2``: Euclidean
            norm 1; ``centre``: centre tap = 1 (needs a non-zero centre).
        """
        t = self.taps
        if mode == "peak":
            d = float(np.abs(t).max())
        elif mode == "sum":
            d = float(t.sum())
            if abs(d) < 1e-12 * float(np.abs(t).sum()):
                raise KernelError("normalised('sum'): kernel has zero DC gain; use 'peak' or 'l2'")
        elif mode == "l2":
            d = float(np.sqrt((t * t).sum()))
        elif mode == "centre":
            d = self.centre
            if d == 0:
                raise KernelError("normalised('centre'): centre tap is zero")
        else:
            raise KernelError(f"normalised: mode {mode!r} unknown; allowed 'peak', 'sum', 'l2', 'centre'")
        return self.with_taps(t / d)

    def padded(self, size: int) -> Kernel:
        """This kernel zero-padded (centred) to ``size`` × ``size`` (odd, ≥ current size)."""
        if size < self.size or size % 2 == 0:
            raise KernelError(f"padded: size must be odd and ≥ {self.size}, got {size}")
        p = (size - self.size) // 2
        return self.with_taps(np.pad(self.taps, p))

    def cropped(self, size: int) -> Kernel:
        """The central ``size`` × ``size`` window (odd, ≤ current size)."""
        if size > self.size or size % 2 == 0 or size < 1:
            raise KernelError(f"cropped: size must be odd and in 1..{self.size}, got {size}")
        c = (self.size - size) // 2
        return self.with_taps(self.taps[c : c + size, c : c + size])

    def asymmetry(self) -> float:
        """Relative departure from 8-fold (dihedral D4) symmetry: ‖K − sym(K)‖₂ / ‖K‖₂ ∈ [0, 1]."""
        t = self.taps
        group = [t, t.T, t[::-1], t[:, ::-1], t[::-1, ::-1], t.T[::-1], t.T[:, ::-1], t.T[::-1, ::-1]]
        sym = np.mean(group, axis=0)
        return float(np.linalg.norm(t - sym) / np.linalg.norm(t))

    def allclose(self, other: Kernel, *, rtol: float = 1e-9, atol: float = 0.0) -> bool:
        """True when the taps have equal shape and agree elementwise (pitch ignored)."""
        return self.taps.shape == other.taps.shape and bool(np.allclose(self.taps, other.taps, rtol=rtol, atol=atol))

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the ``.json`` file format)."""
        return {
            "format": _FORMAT_TAG,
            "version": 1,
            "name": self.name,
            "pitch_m": self.pitch_m,
            "taps": self.taps.tolist(),
            "provenance": dict(self.provenance),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, source: str = "dict") -> Kernel:
        """Inverse of :meth:`to_dict`; errors name ``source`` and the field."""
        if not isinstance(data, Mapping):
            raise KernelError(f"{source}: expected a JSON object, got {type(data).__name__}")
        if "taps" not in data:
            raise KernelError(f"{source}: missing field 'taps' (a list of rows)")
        fmt = data.get("format", _FORMAT_TAG)
        if fmt != _FORMAT_TAG:
            raise KernelError(f"{source}: field 'format' is not {_FORMAT_TAG!r}: not an fsdvs_hw kernel file")
        taps = _validate_taps(data["taps"], source=f"{source}: field 'taps'")
        pitch = validate_pitch(data.get("pitch_m", DEFAULT_PITCH_M), source=f"{source}: field 'pitch_m'")
        prov = data.get("provenance", {})
        if not isinstance(prov, Mapping):
            raise KernelError(f"{source}: field 'provenance' must be an object")
        return cls(taps, pitch_m=pitch, name=str(data.get("name", Path(source).stem)), provenance=prov)

    def save(self, path: str | Path) -> Path:
        """Write the kernel to ``path``; the format follows the extension (.npy .csv .json .pt).

        The file is written whole or not at all, never through a symbolic link
        (:func:`fsdvs_hw.paths.write_output`).
        """
        from .paths import write_output

        path = Path(path)
        suffix = path.suffix.lower()
        if suffix not in (".npy", ".csv", ".json", ".pt"):
            raise KernelError(f"{path}: unknown kernel file extension {suffix!r}; allowed {', '.join(_SUFFIXES)}")
        path.parent.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()
        if suffix == ".npy":
            np.save(buf, np.asarray(self.taps), allow_pickle=False)
        elif suffix == ".csv":
            meta = {"name": self.name, "pitch_m": self.pitch_m, "provenance": dict(self.provenance)}
            header = "fsdvs_hw " + json.dumps(meta)
            np.savetxt(buf, self.taps, delimiter=",", fmt="%.17g", header=header, comments="# ")
        elif suffix == ".json":
            buf.write((json.dumps(self.to_dict(), indent=1) + "\n").encode("utf-8"))
        else:
            import torch

            torch.save(
                {
                    "taps": torch.from_numpy(np.array(self.taps)),
                    "pitch_m": self.pitch_m,
                    "name": self.name,
                    "provenance_json": json.dumps(dict(self.provenance)),
                },
                buf,
            )
        write_output(path, buf.getvalue(), flag=str(path))
        return path

    @classmethod
    def load(cls, path: str | Path, *, pitch_m: float | None = None) -> Kernel:
        """Same as :func:`load_kernel`."""
        return load_kernel(path, pitch_m=pitch_m)

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> np.ndarray:
        """``np.asarray(kernel)`` is the ``(k, k)`` tap array (a copy: the kernel stays immutable)."""
        return np.array(self.taps, dtype=dtype if dtype is not None else np.float64, copy=True)

    def __repr__(self) -> str:
        return (
            f"Kernel(name={self.name!r}, size={self.size}x{self.size}, pitch_m={self.pitch_m:.3g}, "
            f"dc_gain={self.dc_gain:.4g}, centre={self.centre:.4g})"
        )


# ---------------------------------------------------------------------- loading
def as_kernel(kernel: Any, *, name: str = "kernel", pitch_m: float | None = None, repitch: bool = False) -> Kernel:
    """A :class:`Kernel` from what a user holds: a Kernel, a file path, a torch tensor or a k×k array.

    Every public function of fsdvs_hw that takes a kernel passes it through here, so each accepts
    the same things.

    Parameters
    ----------
    kernel : Kernel, str, Path, torch.Tensor or array_like
        A Kernel is returned unchanged (``pitch_m`` then must be None or equal to its pitch, unless
        ``repitch``); a path is read with :func:`load_kernel`; anything else must be an odd square
        array of finite taps.
    name : str
        Name given to an array (and used in error messages).
    pitch_m : float, optional
        Pixel pitch in metres for an array or a file (default :data:`DEFAULT_PITCH_M`, or the
        file's own).
    repitch : bool
        A Kernel given with a different ``pitch_m`` gets that pitch (same taps, name and
        provenance) instead of being refused: for functions whose ``pitch_m`` argument means
        "the pitch to design for".

    Raises
    ------
    KernelError
        Not convertible: names what was given and what is allowed.

    Examples
    --------
    >>> as_kernel([[0, 0, 0], [0, 1, 0], [0, 0, 0]]).size
    3
    """
    if isinstance(kernel, Kernel):
        if pitch_m is not None and not math.isclose(float(pitch_m), kernel.pitch_m, rel_tol=1e-12):
            if repitch:
                return Kernel(kernel.taps, pitch_m=pitch_m, name=kernel.name, provenance=kernel.provenance)
            raise KernelError(
                f"{name}: a Kernel with pitch {kernel.pitch_m:.4g} m was given with pitch_m={pitch_m!r}; "
                "use kernel.with_taps or pass the taps as an array"
            )
        return kernel
    if isinstance(kernel, (str, Path)):
        return load_kernel(kernel, pitch_m=pitch_m)
    if hasattr(kernel, "detach"):  # a torch tensor, without importing torch here
        kernel = kernel.detach().cpu().numpy()
    try:
        taps = np.asarray(kernel, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise KernelError(
            f"{name}: expected a Kernel, a kernel file path or a k×k array of numbers, got "
            f"{type(kernel).__name__} ({exc})"
        ) from None
    kw: dict[str, Any] = {} if pitch_m is None else {"pitch_m": pitch_m}
    return Kernel(taps, name=name, **kw)


def _kernel_file_suffix(path: Path) -> str:
    """The kernel file's extension (lower case), once the file is found, of a known format and small enough."""
    src = str(path)
    if not path.is_file():
        raise KernelError(f"{src}: kernel file not found")
    suffix = path.suffix.lower()
    if suffix not in _SUFFIXES:
        raise KernelError(f"{src}: unknown kernel file extension {suffix!r}; allowed {', '.join(_SUFFIXES)}")
    try:
        n_bytes = path.stat().st_size
    except OSError as exc:
        raise KernelError(f"{src}: cannot read ({exc.strerror})") from None
    if n_bytes > MAX_KERNEL_FILE_BYTES:
        raise KernelError(
            f"{src}: {n_bytes} bytes is too large for a kernel file (limit {MAX_KERNEL_FILE_BYTES} bytes)"
        )
    return suffix


def load_kernel(path: str | Path, *, pitch_m: float | None = None) -> Kernel:
    """Load a kernel from a .npy, .csv, .json or .pt file.

    Parameters
    ----------
    path : str or Path
        The file. The format follows the extension; see the module docstring.
    pitch_m : float, optional
        Pixel pitch in metres. Overrides a pitch stored in the file; formats without one
        (.npy, plain .csv) get :data:`DEFAULT_PITCH_M` when it is not given.

    Raises
    ------
    KernelError
        Missing file, unknown extension, unreadable content, or invalid taps — the message names
        the file.

    Examples
    --------
    >>> from fsdvs_hw import load_kernel
    >>> k = load_kernel("designs/kernels/dog_7x7.json")
    >>> k.size, round(float(k.taps.sum()), 4)
    (7, 0.2)
    """
    path = Path(path)
    src = str(path)
    suffix = _kernel_file_suffix(path)
    meta: dict[str, Any] = {}
    if suffix == ".npy":
        try:
            taps = np.load(path, allow_pickle=False)
        except (ValueError, EOFError, OSError) as exc:
            why = (
                "not an .npy file, or an object array, which is never loaded"
                if "pickle" in str(exc)
                else type(exc).__name__
            )
            raise KernelError(f"{src}: not a plain numeric .npy array ({why})") from None
        if not isinstance(taps, np.ndarray):
            raise KernelError(f"{src}: not a plain .npy array (got a {type(taps).__name__})")
    elif suffix == ".csv":
        taps, meta = _parse_csv(_read_text(path), src)
    elif suffix == ".json":
        try:
            data = json.loads(_read_text(path))
        except json.JSONDecodeError as exc:
            raise KernelError(f"{src}: invalid JSON ({exc.msg} at line {exc.lineno}, column {exc.colno})") from None
        except RecursionError:
            raise KernelError(f"{src}: invalid JSON (nested too deeply)") from None
        if isinstance(data, list):
            data = {"taps": data}
        k = Kernel.from_dict(data, source=src)
        return k if pitch_m is None else Kernel(k.taps, pitch_m=pitch_m, name=k.name, provenance=k.provenance)
    elif suffix == ".pt":
        taps, meta = _load_pt(path)
    taps = np.asarray(taps)
    while taps.ndim > 2 and taps.shape[0] == 1:  # conv weights (1, 1, k, k)
        taps = taps[0]
    taps = _validate_taps(taps, source=src)
    pitch = pitch_m if pitch_m is not None else meta.get("pitch_m", DEFAULT_PITCH_M)
    pitch = validate_pitch(pitch, source=f"{src}: pitch_m")
    prov = meta.get("provenance", {}) or {"loaded_from": path.name}
    if not isinstance(prov, Mapping):
        raise KernelError(f"{src}: provenance must be a JSON object, got {type(prov).__name__}")
    return Kernel(taps, pitch_m=pitch, name=str(meta.get("name", path.stem)), provenance=prov)


def _read_text(path: Path) -> str:
    """The file as UTF-8 text; a :class:`KernelError` naming the file and the first bad byte otherwise."""
    data = path.read_bytes()
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise KernelError(f"{path}: not UTF-8 text (invalid byte at offset {exc.start})") from None


def _parse_csv(text: str, src: str) -> tuple[np.ndarray, dict[str, Any]]:
    """Rows of comma-separated numbers; ``#`` lines are comments, the first may carry metadata.

    Errors name the row and column but never echo the file's content.
    """
    lines = text.splitlines()
    meta: dict[str, Any] = {}
    if lines and lines[0].startswith("# fsdvs_hw "):
        try:
            meta = json.loads(lines[0][len("# fsdvs_hw ") :])
        except (json.JSONDecodeError, RecursionError):
            raise KernelError(f"{src}: malformed '# fsdvs_hw' header line (not a JSON object)") from None
        if not isinstance(meta, dict):
            raise KernelError(f"{src}: malformed '# fsdvs_hw' header line (not a JSON object)")
    rows: list[list[float]] = []
    for n, line in enumerate(lines, start=1):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        row = []
        for c, cell in enumerate(body.split(","), start=1):
            try:
                row.append(float(cell.strip()))
            except ValueError:
                raise KernelError(f"{src}: line {n}, column {c} is not a number") from None
        if rows and len(row) != len(rows[0]):
            raise KernelError(f"{src}: line {n} has {len(row)} values, the first row {len(rows[0])}")
        rows.append(row)
    if not rows:
        raise KernelError(f"{src}: no numeric rows (an empty kernel file)")
    return np.array(rows, dtype=np.float64), meta


def _load_pt(path: Path) -> tuple[np.ndarray, dict[str, Any]]:
    import pickle

    import torch

    _TORCH_INTS = (torch.int8, torch.uint8, torch.int16, torch.int32, torch.int64)

    try:
        obj = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - any failure of an untrusted file is an input error
        why = "refused by the safe unpickler" if isinstance(exc, pickle.UnpicklingError) else type(exc).__name__
        raise KernelError(
            f"{path}: could not load safely with torch.load(weights_only=True); only tensors and "
            f"plain dicts are accepted, never arbitrary pickled objects ({why})"
        ) from None
    meta: dict[str, Any] = {}
    if isinstance(obj, Mapping):
        key = next((k for k in ("taps", "weight", "kernel") if k in obj), None)
        if key is None:
            tensors = [k for k, v in obj.items() if isinstance(v, torch.Tensor)]
            if len(tensors) != 1:
                raise KernelError(
                    f"{path}: dict has no 'taps'/'weight'/'kernel' entry and {len(tensors)} tensors; "
                    "cannot tell which one is the kernel"
                )
            key = tensors[0]
        tensor = obj[key]
        if "pitch_m" in obj:
            meta["pitch_m"] = obj["pitch_m"]  # validated by the caller
        if "name" in obj:
            meta["name"] = str(obj["name"])
        if "provenance_json" in obj:
            try:
                meta["provenance"] = json.loads(str(obj["provenance_json"]))
            except (json.JSONDecodeError, RecursionError):
                raise KernelError(f"{path}: entry 'provenance_json' is not valid JSON") from None
    else:
        tensor = obj
    if not isinstance(tensor, torch.Tensor):
        raise KernelError(f"{path}: kernel entry is a {type(tensor).__name__}, expected a tensor")
    if tensor.is_complex():
        raise KernelError(f"{path}: kernel taps must be real, got a complex tensor ({tensor.dtype})")
    if tensor.dtype == torch.bool or not (tensor.is_floating_point() or tensor.dtype in _TORCH_INTS):
        raise KernelError(f"{path}: kernel taps must be numeric, got tensor dtype {tensor.dtype}")
    return tensor.detach().to(torch.float64).cpu().numpy(), meta


# ---------------------------------------------------------------------- reference families
def _grid(size: int) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(size, (int, np.integer)) or size < 1 or size % 2 == 0 or size > MAX_KERNEL_SIZE:
        raise KernelError(f"size: must be an odd integer in 1..{MAX_KERNEL_SIZE}, got {size!r}")
    r = size // 2
    y, x = np.mgrid[-r : r + 1, -r : r + 1].astype(np.float64)
    return x, y


def _positive(name: str, value: float) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0):
        raise KernelError(f"{name}: must be a positive finite number, got {value!r}")
    return v


def delta_taps(size: int = 7) -> np.ndarray:
    r"""Discrete delta: :math:`K[y, x] = 1` at the centre, 0 elsewhere (the 'w/o' FS-DVS baseline)."""
    x, _ = _grid(size)
    k = np.zeros_like(x)
    k[size // 2, size // 2] = 1.0
    return k


def gaussian_taps(size: int = 7, sigma_px: float = 1.0) -> np.ndarray:
    r"""Sampled Gaussian normalised to unit sum.

    :math:`K[y, x] = \exp(-(x^2 + y^2) / (2\sigma^2)) / \sum \exp(\cdot)`, σ in pixels.
    Its continuous Fourier transform is :math:`\exp(-2\pi^2\sigma^2 f^2)` (f in cycles/pixel).
    """
    x, y = _grid(size)
    s = _positive("sigma_px", sigma_px)
    g = np.exp(-(x * x + y * y) / (2 * s * s))
    return g / g.sum()


def dog_taps(
    size: int = 7,
    sigma_centre_px: float = 0.7,
    sigma_surround_px: float = 2.0,
    w_centre: float = 1.0,
    w_surround: float = 0.8,
) -> np.ndarray:
    r"""Difference of Gaussians (centre-surround).

    :math:`K = w_c G_{\sigma_c} - w_s G_{\sigma_s}` with each :math:`G` a sampled Gaussian of unit
    sum on the k×k window (:func:`gaussian_taps`), so the DC gain is exactly :math:`w_c - w_s`:
    ``w_surround == w_centre`` gives a balanced, zero-DC band-pass. The default (0.7 px, 2.0 px,
    1.0, 0.8) keeps 20 % DC so that pre-log filtering of a uniform scene stays positive.
    """
    sc = _positive("sigma_centre_px", sigma_centre_px)
    ss = _positive("sigma_surround_px", sigma_surround_px)
    if ss <= sc:
        raise KernelError(f"sigma_surround_px ({ss}) must exceed sigma_centre_px ({sc}) for a centre-surround DoG")
    wc, ws = float(w_centre), float(w_surround)
    if not (math.isfinite(wc) and math.isfinite(ws)) or wc <= 0 or ws < 0:
        raise KernelError(f"DoG weights must be finite with w_centre > 0, w_surround ≥ 0; got {wc}, {ws}")
    return wc * gaussian_taps(size, sc) - ws * gaussian_taps(size, ss)


def log_taps(size: int = 7, sigma_px: float = 1.0) -> np.ndarray:
    r"""Negated Laplacian of Gaussian ("Mexican hat"), zero-mean, centre tap = 1.

    :math:`K \propto (1 - r^2/(2\sigma^2))\, e^{-r^2/(2\sigma^2)}` (that is :math:`-\nabla^2 G` up to a
    positive constant), then the window mean is subtracted so the DC gain is exactly 0 (as in
    MATLAB's ``fspecial('log')``), then scaled so the centre tap is 1.
    """
    x, y = _grid(size)
    s = _positive("sigma_px", sigma_px)
    q = (x * x + y * y) / (2 * s * s)
    k = (1 - q) * np.exp(-q)
    k = k - k.mean()
    c = k[size // 2, size // 2]
    if c <= 0:
        raise KernelError(f"log: sigma_px={s} is too small for a {size}x{size} window")
    return k / c


#: Registry of reference kernel families: name → taps generator ``f(size, **params)``.
REFERENCE_KERNELS: dict[str, Callable[..., np.ndarray]] = {
    "delta": delta_taps,
    "gaussian": gaussian_taps,
    "dog": dog_taps,
    "log": log_taps,
}


def reference_kernel(name: str, size: int = 7, *, pitch_m: float = DEFAULT_PITCH_M, **params: float) -> Kernel:
    """A reference kernel from :data:`REFERENCE_KERNELS`.

    Parameters
    ----------
    name : {"delta", "gaussian", "dog", "log"}
        Family; see each ``*_taps`` function for its formula and parameters (σ in pixels).
    size : int
        Odd side length in pixels.
    pitch_m : float
        Pixel pitch in metres.
    **params
        Family parameters, e.g. ``sigma_px=1.2`` or ``sigma_centre_px=0.7, w_surround=1.0``.

    Examples
    --------
    >>> abs(reference_kernel("dog", 7, w_surround=1.0).dc_gain) < 1e-12  # balanced DoG
    True
    """
    key = name.lower().replace("-", "_")
    if key not in REFERENCE_KERNELS:
        raise KernelError(f"reference kernel {name!r} unknown; allowed: {', '.join(REFERENCE_KERNELS)}")
    fn = REFERENCE_KERNELS[key]
    try:
        taps = fn(size, **params)
    except TypeError as exc:
        raise KernelError(f"reference kernel {name!r}: bad parameters {params} ({exc})") from None
    label = key if not params else key + "(" + ", ".join(f"{k}={v:g}" for k, v in params.items()) + ")"
    prov = {"reference": key, "size": size, **{k: float(v) for k, v in params.items()}}
    return Kernel(taps, pitch_m=pitch_m, name=f"{label} {size}x{size}", provenance=prov)


def _parse_reference(spec: str, pitch_m: float | None) -> Kernel:
    """A reference kernel from a spec ``family[:key=value,...]`` (``size`` odd, others floats)."""
    name, _, rest = spec.partition(":")
    params: dict[str, float] = {}
    size = 7
    for item in filter(None, rest.split(",")):
        key, eq, value = item.partition("=")
        if not eq:
            raise KernelError(f"reference spec {spec!r}: expected key=value, got {item!r}")
        try:
            num = float(value)
        except ValueError:
            raise KernelError(f"reference spec {spec!r}: {key} must be a number, got {value!r}") from None
        if not math.isfinite(num):
            raise KernelError(f"reference spec {spec!r}: {key} must be finite, got {value!r}")
        if key.strip() == "size":
            if num != int(num):
                raise KernelError(f"reference spec {spec!r}: size must be an odd integer, got {value}")
            size = int(num)
        else:
            params[key.strip()] = num
    return reference_kernel(name, size, pitch_m=DEFAULT_PITCH_M if pitch_m is None else pitch_m, **params)


def load_kernel_or_reference(spec: str, pitch_m: float | None = None) -> Kernel:
    """A kernel from a file path, or from a reference spec like ``dog:size=7,w_surround=1``.

    Parameters
    ----------
    spec : str
        A kernel file (``.npy``, ``.csv``, ``.json``, ``.pt``) or a reference family of
        :data:`REFERENCE_KERNELS` with optional ``key=value`` parameters after a colon (``size``
        odd, in pixels; sigmas in pixels).
    pitch_m : float, optional
        Pixel pitch in metres (default: the file's, else :data:`DEFAULT_PITCH_M`).

    Raises
    ------
    KernelError
        ``spec`` is neither a kernel file nor a reference spec, or a parameter is malformed.
    """
    path = Path(spec)
    if path.suffix.lower() in (".npy", ".csv", ".json", ".pt") or path.exists():
        return load_kernel(path, pitch_m=pitch_m)
    if spec.partition(":")[0].lower() in REFERENCE_KERNELS:
        return _parse_reference(spec, pitch_m)
    raise KernelError(
        f"{spec!r} is neither a kernel file (.npy .csv .json .pt) nor a reference family "
        f"({', '.join(REFERENCE_KERNELS)})"
    )
