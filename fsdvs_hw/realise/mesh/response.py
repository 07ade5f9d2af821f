r"""Impulse response of one 2-D resistive mesh, at three fidelities.

A square resistive mesh ties every node to its four neighbours by a lateral conductance
:math:`g_l` (siemens) and to the reference (ground) by a vertical conductance :math:`g_v`. A pixel
injects its signal as a **current** into its own node; the mesh's output at a node is the node
voltage. Kirchhoff's current law on the lattice reads

.. math:: (g_v \mathbf{1} + g_l L) V = I,

with :math:`L` the graph Laplacian (4 on the diagonal in the interior, −1 per neighbour). We
normalise the impulse response by :math:`g_v`, :math:`H = g_v V / I_0` for a current
:math:`I_0` into one node, so that :math:`H = (\mathbf{1} + \lambda^2 L)^{-1} e_0` depends only on
the space constant :math:`\lambda = \sqrt{g_l / g_v}` (pixel pitches), and on an infinite lattice
it sums to exactly 1 (DC gain 1) with per-axis second moment :math:`2\lambda^2`.

Fidelities (fastest first):

``lattice_green_function``
    The infinite lattice (a pixel far from the array edge), exact. Fourier-transforming the
    lattice and integrating one axis in closed form leaves a one-dimensional integral

    .. math:: H(m, n) = \frac{1}{\pi}\int_0^\pi \frac{\cos(m k)\, \rho(k)^{|n|}}{\sqrt{D(k)}}\,dk,
       \quad a = 1 + \lambda^2 (2 - 2\cos k),\; D = a (a + 4\lambda^2),\;
       \rho = \frac{2\lambda^2}{a + 2\lambda^2 + \sqrt{D}},

    whose integrand is analytic and periodic, so the midpoint rule converges exponentially. The
    integrand peaks within :math:`|k| \lesssim 1/\lambda`; a circle map
    :math:`k = 2\arctan(s \tan(\theta/2))` with :math:`s = (1 + 2.8\lambda)^{-1/2}` balances the
    two branch points (at :math:`k \approx i/\lambda` and :math:`k = i\,\mathrm{acosh}\,3`) so that
    about :math:`64 + 40\sqrt{\lambda}` nodes give ~1e-15 relative accuracy for λ ≤ 10 and ~5e-13 up to λ = 1e3.
``finite_grid_response``
    A finite n×n grid with free (open) edges, the pixel at its centre: the chip (or a patch) of
    finite size. ``method="dct"``: exact diagonalisation by the DCT-II (uniform conductances);
    ``method="sparse"``: a sparse LU of the KCL matrix (any per-element conductances, used for
    mismatch). The half-width is the truncation knob: about ``3 + 3λ`` pixels keeps a 7×7
    window within ~1e-3 of the infinite lattice.
``continuum_response``
    The continuum limit :math:`K_0(r/\lambda) / (2\pi\lambda^2)` (modified Bessel function), the
    textbook law; it is 7–30 % off near the centre for λ ≲ 2 and is used only as a check.

The casadi circuit model (:func:`casadi_mesh_model`) writes the same KCL as a symbolic sparse
system solved with casadi's ``solve(A, b, "ldl")``, so gradients reach every conductance.

References
----------
C. Mead, *Analog VLSI and Neural Systems*, Addison-Wesley 1989, ch. 7 (resistive networks).
C. Mead and M. Mahowald, "A silicon model of early visual processing", *Neural Networks* 1, 1988.
S. Katsura and S. Inawashiro, "Lattice Green's functions for the rectangular and the square
lattices at arbitrary points", *J. Math. Phys.* 12, 1622 (1971).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...errors import InputError

__all__ = [
    "LAMBDA_RANGE_PX",
    "casadi_mesh_model",
    "continuum_response",
    "finite_grid_response",
    "grid_half_width_for",
    "lattice_green_function",
    "lattice_green_quarter",
    "mesh_kcl_matrix",
    "quadrature_nodes",
    "space_constant_px",
]

#: Space constants accepted by the models, in pixel pitches: conductance ratios g_l/g_v from
#: 1e-8 to 1e8. Outside this range a mesh is either a wire to ground or a short circuit.
LAMBDA_RANGE_PX: tuple[float, float] = (1e-4, 1e4)


def _check_lambda(lambda_px: Any, name: str = "lambda_px") -> float:
    try:
        lam = float(lambda_px)
    except (TypeError, ValueError):
        raise InputError(f"{name}: must be a number of pixel pitches, got {lambda_px!r}") from None
    lo, hi = LAMBDA_RANGE_PX
    if not (math.isfinite(lam) and lo <= lam <= hi):
        raise InputError(
            f"{name}={lambda_px!r} px is outside the allowed range [{lo:g}, {hi:g}] px "
            f"(conductance ratio g_l/g_v in [{lo * lo:g}, {hi * hi:g}])"
        )
    return lam


def check_radius(radius: Any, name: str = "radius") -> int:
    """``radius`` (pixels) as an int in 0…512, or an InputError naming ``name``."""
    if not isinstance(radius, (int, np.integer)) or isinstance(radius, bool) or not 0 <= radius <= 512:
        raise InputError(f"{name}: must be an integer number of pixels in 0..512, got {radius!r}")
    return int(radius)


def space_constant_px(g_lateral_s: float, g_vertical_s: float) -> float:
    r"""Space constant :math:`\lambda = \sqrt{g_l / g_v}` in pixel pitches.

    Parameters
    ----------
    g_lateral_s, g_vertical_s : float
        Lateral (node-to-neighbour) and vertical (node-to-reference) conductances in siemens,
        positive and finite.
    """
    for name, g in (("g_lateral_s", g_lateral_s), ("g_vertical_s", g_vertical_s)):
        if not (isinstance(g, (int, float, np.floating)) and math.isfinite(g) and g > 0):
            raise InputError(f"{name}: conductance must be a positive finite number in siemens, got {g!r}")
    return _check_lambda(math.sqrt(g_lateral_s / g_vertical_s), "sqrt(g_lateral_s / g_vertical_s)")


# ---------------------------------------------------------------------- infinite lattice
def quadrature_nodes(lambda_max_px: float, radius: int = 0) -> tuple[np.ndarray, np.ndarray]:
    r"""Midpoint-rule nodes ``k`` (rad) and weights for the lattice Green's function integral.

    Accurate to ~1e-15 (λ ≤ 10) … 5e-13 (λ = 1e3) relative for every λ ≤ ``lambda_max_px`` and taps up to ``radius`` from the
    centre. The weights include the :math:`1/\pi` prefactor and the Jacobian of the circle map.
    """
    lam = _check_lambda(lambda_max_px, "lambda_max_px")
    radius = check_radius(radius)
    n = 64 + 4 * radius + int(math.ceil(40.0 * math.sqrt(lam)))
    n = int(16 * math.ceil(n / 16))
    s = 1.0 / math.sqrt(1.0 + 2.8 * lam)
    theta = (np.arange(n) + 0.5) * (np.pi / n)
    t = np.tan(theta / 2)
    k = 2.0 * np.arctan(s * t)
    dk_dtheta = s * (1.0 + t * t) / (1.0 + s * s * t * t)
    return k, dk_dtheta / n


def green_terms(lam2, c, xp=np):
    """Per-node pieces (rho, 1/sqrt(D)) of the integrand, stable for λ² from 1e-8 to 1e8."""
    a = 1.0 + lam2 * c
    sq = xp.sqrt(a * (a + 4.0 * lam2))
    rho = 2.0 * lam2 / (a + 2.0 * lam2 + sq)
    return rho, 1.0 / sq


def lattice_green_quarter(
    lambda_px: float, radius: int, *, derivative: bool = False, nodes: tuple[np.ndarray, np.ndarray] | None = None
) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    r"""Infinite-lattice response ``H[m, n]`` for ``0 ≤ m, n ≤ radius`` (one quadrant).

    Parameters
    ----------
    lambda_px : float
        Space constant in pixel pitches.
    radius : int
        Largest offset in pixels.
    derivative : bool
        Also return :math:`\partial H / \partial (\lambda^2)` (analytic, per pixel²).
    nodes : (k, w), optional
        Quadrature from :func:`quadrature_nodes` (reuse it when evaluating many λ).
    """
    lam = _check_lambda(lambda_px)
    radius = check_radius(radius)
    k, w = nodes if nodes is not None else quadrature_nodes(max(lam, 1.0), radius)
    lam2 = lam * lam
    c = 2.0 - 2.0 * np.cos(k)
    rho, inv_sq = green_terms(lam2, c)
    m = np.arange(radius + 1)
    cos_mk = np.cos(np.outer(m, k)) * (w * inv_sq)  # (m, node)
    pow_rho = rho[:, None] ** m[None, :]  # (node, n)
    h = cos_mk @ pow_rho
    if not derivative:
        return h
    # d/d(lam2) of rho^n / sqrt(D), by the chain rule on a, D, rho
    a = 1.0 + lam2 * c
    d = a * (a + 4.0 * lam2)
    sq = np.sqrt(d)
    d_d = c * (a + 4.0 * lam2) + a * (c + 4.0)
    d_sq = d_d / (2.0 * sq)
    den = a + 2.0 * lam2 + sq
    d_rho = (2.0 * den - 2.0 * lam2 * (c + 2.0 + d_sq)) / (den * den)
    with np.errstate(divide="ignore", invalid="ignore"):
        n_rho = np.where(m[None, :] > 0, m[None, :] * rho[:, None] ** np.maximum(m[None, :] - 1, 0), 0.0)
    d_pow = n_rho * d_rho[:, None] - pow_rho * (d_sq / sq)[:, None]
    dh = (np.cos(np.outer(m, k)) * (w * inv_sq)) @ d_pow
    return h, dh


def unfold_quarter(q: np.ndarray) -> np.ndarray:
    """Mirror a quadrant ``q[|y|, |x|]`` into the full (2r+1)² array."""
    full = np.concatenate([q[:0:-1], q], axis=0)
    return np.concatenate([full[:, :0:-1], full], axis=1)


def lattice_green_function(lambda_px: float, radius: int) -> np.ndarray:
    r"""Normalised impulse response of an infinite resistive mesh on the (2r+1)² window.

    Parameters
    ----------
    lambda_px : float
        Space constant :math:`\sqrt{g_l/g_v}` in pixel pitches, in :data:`LAMBDA_RANGE_PX`.
    radius : int
        Window half-width r in pixels.

    Returns
    -------
    ndarray, shape (2r+1, 2r+1)
        :math:`g_v V / I_0` (dimensionless); sums to 1 over the whole lattice.
    """
    q = lattice_green_quarter(lambda_px, radius)
    return unfold_quarter(np.asarray(q))


# ---------------------------------------------------------------------- finite grid
def grid_half_width_for(lambda_px: float, radius: int) -> int:
    """Grid half-width (pixels) keeping a (2r+1)² window within ~1e-3 of the infinite lattice: r + 3 + 3λ."""
    return int(check_radius(radius) + 3 + math.ceil(3.0 * _check_lambda(lambda_px)))


def dct_basis(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvectors (columns) and eigenvalues of the open-boundary path-graph Laplacian."""
    i = np.arange(n)
    x = np.arange(n)
    phi = np.cos(np.pi * np.outer(x + 0.5, i) / n) * np.sqrt(2.0 / n)
    phi[:, 0] = np.sqrt(1.0 / n)
    return phi, 2.0 - 2.0 * np.cos(np.pi * i / n)


def mesh_kcl_matrix(half_width: int, g_lateral_s: Any, g_vertical_s: Any):
    """Sparse KCL (nodal) matrix of an n×n mesh, n = 2·half_width + 1, open edges.

    Parameters
    ----------
    half_width : int
        Grid half-width in pixels.
    g_lateral_s : float or ndarray
        One conductance (S) for every edge, or one per edge: first the ``n·(n−1)`` horizontal edges
        (row-major, between (y, x) and (y, x+1)), then the ``n·(n−1)`` vertical ones (between (y, x)
        and (y+1, x)).
    g_vertical_s : float or ndarray
        Conductance to the reference, one value or one per node (row-major), in S.

    Returns
    -------
    scipy.sparse.csc_matrix, shape (n², n²)
    """
    import scipy.sparse as sp

    n = 2 * check_radius(half_width, "half_width") + 1
    idx = np.arange(n * n).reshape(n, n)
    a = np.concatenate([idx[:, :-1].ravel(), idx[:-1, :].ravel()])
    b = np.concatenate([idx[:, 1:].ravel(), idx[1:, :].ravel()])
    gl = np.broadcast_to(np.asarray(g_lateral_s, dtype=np.float64), a.shape)
    gv = np.broadcast_to(np.asarray(g_vertical_s, dtype=np.float64), (n * n,))
    rows = np.concatenate([a, b, a, b, np.arange(n * n)])
    cols = np.concatenate([b, a, a, b, np.arange(n * n)])
    vals = np.concatenate([-gl, -gl, gl, gl, gv])
    return sp.csc_matrix((vals, (rows, cols)), shape=(n * n, n * n))


def finite_grid_response(lambda_px: float, radius: int, half_width: int, *, method: str = "dct") -> np.ndarray:
    """Normalised impulse response of a finite (2h+1)² open-edge mesh, pixel at the centre.

    Parameters
    ----------
    lambda_px : float
        Space constant in pixel pitches.
    radius : int
        Window half-width r (≤ ``half_width``) of the returned taps.
    half_width : int
        Grid half-width h in pixels (the truncation knob).
    method : {"dct", "sparse"}
        Exact DCT diagonalisation, or a sparse LU of the KCL matrix (same answer to rounding).

    Returns
    -------
    ndarray, shape (2r+1, 2r+1)
        :math:`g_v V / I_0` on the window around the injecting node.
    """
    lam = _check_lambda(lambda_px)
    radius = check_radius(radius)
    half_width = check_radius(half_width, "half_width")
    if radius > half_width:
        raise InputError(f"radius={radius} exceeds the grid half_width={half_width}")
    n = 2 * half_width + 1
    lo, hi = half_width - radius, half_width + radius + 1
    if method == "dct":
        phi, s = dct_basis(n)
        c0 = phi[half_width]
        m = (c0[:, None] * c0[None, :]) / (1.0 + lam * lam * (s[:, None] + s[None, :]))
        p = phi[lo:hi]
        return p @ m @ p.T
    if method == "sparse":
        import scipy.sparse.linalg as spla

        a = mesh_kcl_matrix(half_width, lam * lam, 1.0)
        e = np.zeros(n * n)
        e[half_width * n + half_width] = 1.0
        v = spla.spsolve(a, e).reshape(n, n)
        return v[lo:hi, lo:hi]
    raise InputError(f"method={method!r} unknown; allowed 'dct', 'sparse'")


# ---------------------------------------------------------------------- continuum
def continuum_response(lambda_px: float, r_px: Any) -> np.ndarray:
    r"""Continuum mesh law :math:`K_0(r/\lambda) / (2\pi\lambda^2)` at distances ``r_px`` > 0 (pixels)."""
    from scipy.special import k0

    lam = _check_lambda(lambda_px)
    r = np.asarray(r_px, dtype=np.float64)
    if np.any(~np.isfinite(r)) or np.any(r <= 0):
        raise InputError("r_px: distances must be positive and finite (K0 diverges at r = 0)")
    return k0(r / lam) / (2.0 * np.pi * lam * lam)


# ---------------------------------------------------------------------- casadi circuit model
def casadi_mesh_model(half_width: int, *, per_element: bool = False):
    r"""Symbolic nodal analysis of one mesh as a casadi ``Function`` (MX, sparse LDLᵀ solve).

    Parameters
    ----------
    half_width : int
        Grid half-width h; the grid has n = 2h+1 nodes per side, open edges.
    per_element : bool
        False: inputs are one lateral and one vertical conductance (S). True: one conductance per
        edge (ordering of :func:`mesh_kcl_matrix`) and one vertical conductance per node.

    Returns
    -------
    casadi.Function
        ``f(g_lateral_s, g_vertical_s, i_in_a) -> v_node_v``: injected node currents (A, n² vector,
        row-major) to node voltages (V). Differentiable in all inputs (``casadi.jacobian``).
    """
    import casadi as ca

    n = 2 * check_radius(half_width, "half_width") + 1
    nn = n * n
    idx = np.arange(nn).reshape(n, n)
    a = np.concatenate([idx[:, :-1].ravel(), idx[:-1, :].ravel()])
    b = np.concatenate([idx[:, 1:].ravel(), idx[1:, :].ravel()])
    ne = a.size
    # incidence matrix B (edges x nodes): KCL matrix = B^T diag(g_e) B + diag(g_v)
    rows = np.concatenate([np.arange(ne), np.arange(ne)])
    cols = np.concatenate([a, b])
    vals = np.concatenate([np.ones(ne), -np.ones(ne)])
    inc = ca.DM.triplet(rows.tolist(), cols.tolist(), ca.DM(vals), ne, nn)
    g_l = ca.MX.sym("g_lateral_s", ne if per_element else 1)
    g_v = ca.MX.sym("g_vertical_s", nn if per_element else 1)
    i_in = ca.MX.sym("i_in_a", nn)
    if per_element:
        lap = ca.mtimes([inc.T, ca.diag(g_l), inc])
        kcl = lap + ca.diag(g_v)
    else:
        lap_const = ca.mtimes(inc.T, inc)
        kcl = g_l * lap_const + g_v * ca.DM.eye(nn)
    v = ca.solve(kcl, i_in, "ldl")
    return ca.Function("mesh_kcl", [g_l, g_v, i_in], [v], ["g_lateral_s", "g_vertical_s", "i_in_a"], ["v_node_v"])
