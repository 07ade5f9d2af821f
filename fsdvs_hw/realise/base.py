"""The realisation protocol shared by every hardware form of a kernel.

A *realisation* is a physical way to build a kernel (dual resistive mesh, quantised ASIC taps,
metalens PSF), or a reference that is scored the same way (the learned kernel itself, the delta
"w/o" baseline). Every realisation answers four questions the exploration layer asks:

``kernel()``
    The :class:`~fsdvs_hw.kernels.Kernel` the hardware really applies, on the sensor's pixel grid
    (not the target it was fitted to).
``cost()``
    Named hardware quantities with units (:class:`CostItem`), e.g. conductances in siemens,
    adder count, die area in m², optical efficiency.
``describe()``
    A few human-readable lines.
``to_dict()``
    A JSON-serialisable dict with a ``"kind"`` key;
    :func:`fsdvs_hw.realise.registry.realisation_from_dict` inverts it.
``kernel_error(target, fit_scale=False)`` (optional)
    The realisation's own relative L2 error against a target: **the one definition** used by the
    fit reports and the scorer alike (:func:`realised_kernel_error`). It compares what the sensor
    really applies — the whole circuit response of a mesh (not the window crop), the applied PSF
    of a metalens *with its pedestal* (real light before the log) — with the target. A
    realisation without it is scored on :meth:`kernel`.

Every realisation registers itself, with its options, fit function and cost items, in
:mod:`fsdvs_hw.realise.registry`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from ..errors import InputError
from ..kernels import Kernel

__all__ = [
    "CostItem",
    "Realisation",
    "ReferenceRealisation",
    "kernel_error",
    "realised_kernel_error",
]


@dataclass(frozen=True)
class CostItem:
    """One named hardware cost.

    Parameters
    ----------
    value : float
        The quantity, in ``unit``.
    unit : str
        SI unit ("S", "F", "s", "m^2", "W") or "count" / "1" for dimensionless numbers.
    description : str
        What it counts, in a few words.
    """

    value: float
    unit: str
    description: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"value": float(self.value), "unit": self.unit, "description": self.description}


@runtime_checkable
class Realisation(Protocol):
    """Protocol every realisation (mesh, ASIC, metalens, reference) satisfies."""

    @property
    def kind(self) -> str:
        """The ``"kind"`` key its :meth:`to_dict` writes (read-only: frozen records satisfy it)."""
        ...

    def kernel(self) -> Kernel:
        """The kernel the realisation really applies, on the sensor pixel grid."""
        ...

    def cost(self) -> dict[str, CostItem]:
        """Named hardware costs with units."""
        ...

    def describe(self) -> str:
        """Human-readable summary (a few lines)."""
        ...

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable form including ``"kind"``."""
        ...


@dataclass(frozen=True, eq=False)
class ReferenceRealisation:
    """A kernel applied ideally (no hardware): the learned kernel, or the delta 'w/o' baseline.

    Parameters
    ----------
    target : Kernel
        The kernel applied exactly.
    label : str
        "learned", "delta", ... — shown in tables.
    """

    target: Kernel
    label: str = "reference"
    kind: str = field(default="reference", init=False)

    def kernel(self) -> Kernel:
        return self.target

    def cost(self) -> dict[str, CostItem]:
        return {}

    def describe(self) -> str:
        return f"{self.label}: ideal {self.target.size}x{self.target.size} kernel '{self.target.name}' (no hardware)"

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "label": self.label, "kernel": self.target.to_dict()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ReferenceRealisation:
        return cls(
            Kernel.from_dict(data["kernel"], source="realisation.kernel"), label=str(data.get("label", "reference"))
        )


def kernel_error(realised: Kernel | np.ndarray, target: Kernel | np.ndarray, *, fit_scale: bool = False) -> float:
    r"""Relative L2 error between a realised and a target kernel.

    :math:`e = \lVert s K_r - K_t \rVert_2 / \lVert K_t \rVert_2`, where both kernels are
    zero-padded (centred) to the larger size and :math:`s = 1`, or, with ``fit_scale=True``, the
    least-squares scale :math:`s = \langle K_r, K_t\rangle / \lVert K_r \rVert^2` (use it when the
    overall gain is free, e.g. folded into the event threshold).

    Examples
    --------
    >>> import numpy as np
    >>> from fsdvs_hw import kernel_error, reference_kernel
    >>> k = reference_kernel("dog", 5)
    >>> round(kernel_error(np.asarray(k) * 1.1, k), 6)                  # a 10 % gain error ...
    0.1
    >>> round(kernel_error(np.asarray(k) * 1.1, k, fit_scale=True), 6)  # ... which a threshold absorbs
    0.0
    """
    a = realised.taps if isinstance(realised, Kernel) else np.asarray(realised, dtype=np.float64)
    b = target.taps if isinstance(target, Kernel) else np.asarray(target, dtype=np.float64)
    n = max(a.shape[0], b.shape[0])
    a = np.pad(a, (n - a.shape[0]) // 2)
    b = np.pad(b, (n - b.shape[0]) // 2)
    nb = float(np.linalg.norm(b))
    if nb == 0:
        raise InputError("kernel_error: target kernel is all zeros")
    s = 1.0
    if fit_scale:
        na2 = float((a * a).sum())
        s = float((a * b).sum()) / na2 if na2 > 0 else 0.0
    return float(np.linalg.norm(s * a - b) / nb)


def realised_kernel_error(realisation: Any, target: Kernel | np.ndarray, *, fit_scale: bool = False) -> float:
    """The one kernel-error definition: the realisation's own ``kernel_error`` if it has one.

    Otherwise :func:`kernel_error` of ``realisation.kernel()`` (what the sensor applies) against
    ``target``. Fit reports and the scorer both call this, so a design reports about itself the
    number the scorer reports about it.
    """
    own = getattr(realisation, "kernel_error", None)
    if callable(own):
        return float(own(target, fit_scale=fit_scale))
    return kernel_error(realisation.kernel(), target, fit_scale=fit_scale)
