"""Deformable superquadric shells (docs/method-physics.md, sections 1 and 3).

The shell (w = 1) over material coordinates u in [-pi/2, pi/2] (latitude) and v in [-pi, pi)
(longitude) with the global parameters

    q_s = (a0, a1, a2, a3, eps1, eps2, t1, t2, b1, b2, b3)

is the superquadric (eq 20), tapered and bent (eq 21):

    e = a0 (a1 Cu Cv, a2 Cu Sv, a3 Su),   Cu = sgn(cos u)|cos u|^eps1, Su likewise, Cv, Sv with eps2
    A = a0 a3,   r = pi b3 (e3 + b2) / A
    s = ((1 + t1 e3/A) e1 + b1 cos r,  (1 + t2 e3/A) e2,  e3)

so e3/A = Su, tau1 = 1 + t1 Su, tau2 = 1 + t2 Su.  The map (a0, a1, a2, a3) -> (k a0, a1/k,
a2/k, a3/k) leaves s unchanged (section 1, degeneracy 4): the estimator must freeze a0 or add
a prior.

Local deformation (section 3): nodal displacements d (n, 3) on the triangulated ``Mesh``,
linear over each triangle.  The deformed reference point at (u, v) is s(u, v) + N d with
N = ``interpolation_matrix(mesh, u, v)``; in the paper's notation S = N (x) I3 acting on
q_d = d.ravel().  Likewise the stiffness is K_dd = K_node (x) I3 with K_node =
``membrane_stiffness(...)``, so K_dd q_d = (K_node @ d).ravel().  The full model point
x = c + R (s + d) is the dynamics' business.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

N_PARAMETERS = 11
"""Length of q_s = (a0, a1, a2, a3, eps1, eps2, t1, t2, b1, b2, b3)."""

LOWER = np.array([1e-3, 1e-3, 1e-3, 1e-3, 0.1, 0.1, -1.0, -1.0, -np.inf, -np.inf, 1e-2])
UPPER = np.array([np.inf, np.inf, np.inf, np.inf, 1.9, 1.9, 1.0, 1.0, np.inf, np.inf, 1.0])
"""Bounds of q_s used by ``clamp`` (section 1, degeneracy 3; see ``clamp``)."""

_TRIG_ZERO = 1e-15
"""|cos|, |sin| below this are rounding residues of a multiple of pi/2 and are set to 0."""


def clamp(q_s: np.ndarray) -> np.ndarray:
    """q_s clipped into [LOWER, UPPER] (section 1, degeneracy 3).

    eps1, eps2 in [0.1, 1.9]: at eps = 0 the signed power jumps, eps < 0 gives inf, and
    eps1 < 2 keeps the poles smooth.  a0 .. a3 >= 1e-3: s and J divide by A = a0 a3, and a1, a2
    > 0 keep the mesh triangles non-degenerate.  t1, t2 in [-1, 1] (the paper's range) keep
    tau1, tau2 >= 0, so the shell does not turn inside out.  b3 in [0.01, 1]: s is even in b3
    and the b2, b3 columns of J vanish at b3 = 0, where an estimator would stick.  b1 and b2
    are free (b2 is a length, so the paper's [-1, 1] depends on the units).
    """
    return np.clip(np.asarray(q_s, dtype=np.float64), LOWER, UPPER)


def _trig(angle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin with rounding residues at multiples of pi/2 set to exact zeros.

    numpy gives cos(pi/2) = 6e-17, and |6e-17|^0.1 = 0.024: without this the poles of a
    box-like shell (eps1 = 0.1) would sit off the axis by 2.4 % of its size.
    """
    c, s = np.cos(angle), np.sin(angle)
    return np.where(np.abs(c) < _TRIG_ZERO, 0.0, c), np.where(np.abs(s) < _TRIG_ZERO, 0.0, s)


def _signed_power(x: np.ndarray, eps: float) -> np.ndarray:
    """sgn(x) |x|^eps."""
    return np.sign(x) * np.abs(x) ** eps


def _log_abs(x: np.ndarray) -> np.ndarray:
    """ln|x| with ln|0| := 0 (section 1, singularity 1, 'xlogabs').

    It only ever multiplies |x|^eps, and |x|^eps ln|x| -> 0 as x -> 0, but numpy would give
    0 * (-inf) = NaN.
    """
    out = np.zeros_like(x)
    np.log(np.abs(x), out=out, where=x != 0.0)
    return out


@dataclass(frozen=True)
class _Terms:
    """The factors of eq 20-21 at arrays of (u, v)."""

    cu: np.ndarray
    su: np.ndarray
    cv: np.ndarray
    sv: np.ndarray
    Cu: np.ndarray
    Su: np.ndarray
    Cv: np.ndarray
    Sv: np.ndarray


def _terms(q_s: np.ndarray, u: np.ndarray, v: np.ndarray) -> _Terms:
    eps1, eps2 = q_s[4], q_s[5]
    u, v = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
    cu, su = _trig(u)
    cv, sv = _trig(v)
    return _Terms(
        cu,
        su,
        cv,
        sv,
        _signed_power(cu, eps1),
        _signed_power(su, eps1),
        _signed_power(cv, eps2),
        _signed_power(sv, eps2),
    )


REMEMBERED = 256
"""Distinct (q_s, u, v) whose shape and Jacobian are kept (``_remembered``)."""


def _remembered(function: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]):
    """``function(q_s, u, v)`` that keeps its results for the last REMEMBERED distinct arguments, compared
    by value, and returns them read-only.  Fitting and tracking evaluate the same shape at the same
    nodes many times per step (a rigid part never changes q_s), so this saves much of
    ``tracker points``' time with identical results (measured: docs/physics.md)."""
    results: dict = {}

    @functools.wraps(function)
    def remembered(q_s, u, v):
        q_s, u, v = (np.asarray(x, dtype=np.float64) for x in (q_s, u, v))
        key = (q_s.tobytes(), u.shape, u.tobytes(), v.shape, v.tobytes())
        out = results.get(key)
        if out is None:
            if len(results) >= REMEMBERED:
                results.clear()
            out = function(q_s, u, v)
            out.setflags(write=False)
            results[key] = out
        return out

    return remembered


@_remembered
def shape(q_s: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Reference shape s(u, v) (eq 20 with w = 1, tapered and bent by eq 21), shape (..., 3).

    u, v are broadcast against each other; q_s = (a0, a1, a2, a3, eps1, eps2, t1, t2, b1, b2, b3).
    """
    a0, a1, a2, a3, _, _, t1, t2, b1, b2, b3 = np.asarray(q_s, dtype=np.float64)
    f = _terms(q_s, u, v)
    r = np.pi * b3 * (f.Su + b2 / (a0 * a3))
    return np.stack(
        [
            (1.0 + t1 * f.Su) * a0 * a1 * f.Cu * f.Cv + b1 * np.cos(r),
            (1.0 + t2 * f.Su) * a0 * a2 * f.Cu * f.Sv,
            a0 * a3 * f.Su,
        ],
        axis=-1,
    )


@_remembered
def jacobian(q_s: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """J = ds/dq_s (eq 41, w = 1, with the corrected J1,11), shape (..., 3, 11).

    The 17 nonzero entries (section 1; Lsu = ln|sin u| etc. with ln 0 := 0):

        J11 = tau1 a1 Cu Cv + pi b1 b2 b3 sin(r) / (a0 A)     J12 = tau1 a0 Cu Cv
        J14 = pi b1 b2 b3 sin(r) / (a3 A)
        J15 = a0 a1 Cu Cv (t1 Su Lsu + tau1 Lcu) - pi b1 b3 Su Lsu sin(r)
        J16 = tau1 a0 a1 Cu Cv Lcv     J17 = a0 a1 Su Cu Cv     J19 = cos(r)
        J1,10 = -pi b1 b3 sin(r) / A   J1,11 = -pi b1 sin(r) (e3 + b2) / A   (corrected)
        J21 = tau2 a2 Cu Sv   J23 = tau2 a0 Cu Sv   J25 = a0 a2 Cu Sv (t2 Su Lsu + tau2 Lcu)
        J26 = tau2 a0 a2 Cu Sv Lsv     J28 = a0 a2 Su Cu Sv
        J31 = a3 Su   J34 = a0 Su   J35 = a0 a3 Su Lsu

    J1,11 is written with (e3 + b2)/A rather than r/b3 so that it stays finite at b3 = 0.
    """
    a0, a1, a2, a3, _, _, t1, t2, b1, b2, b3 = np.asarray(q_s, dtype=np.float64)
    f = _terms(q_s, u, v)
    area = a0 * a3
    tau1, tau2 = 1.0 + t1 * f.Su, 1.0 + t2 * f.Su
    height = f.Su + b2 / area  # (e3 + b2) / A
    sin_r = np.sin(np.pi * b3 * height)
    cos_r = np.cos(np.pi * b3 * height)
    su_lsu = f.Su * _log_abs(f.su)
    lcu, lcv, lsv = _log_abs(f.cu), _log_abs(f.cv), _log_abs(f.sv)
    cucv, cusv = f.Cu * f.Cv, f.Cu * f.Sv

    j = np.zeros(f.Cu.shape + (3, N_PARAMETERS))
    j[..., 0, 0] = tau1 * a1 * cucv + np.pi * b1 * b2 * b3 * sin_r / (a0 * area)
    j[..., 0, 1] = tau1 * a0 * cucv
    j[..., 0, 3] = np.pi * b1 * b2 * b3 * sin_r / (a3 * area)
    j[..., 0, 4] = a0 * a1 * cucv * (t1 * su_lsu + tau1 * lcu) - np.pi * b1 * b3 * su_lsu * sin_r
    j[..., 0, 5] = tau1 * a0 * a1 * cucv * lcv
    j[..., 0, 6] = a0 * a1 * f.Su * cucv
    j[..., 0, 8] = cos_r
    j[..., 0, 9] = -np.pi * b1 * b3 * sin_r / area
    j[..., 0, 10] = -np.pi * b1 * sin_r * height
    j[..., 1, 0] = tau2 * a2 * cusv
    j[..., 1, 2] = tau2 * a0 * cusv
    j[..., 1, 4] = a0 * a2 * cusv * (t2 * su_lsu + tau2 * lcu)
    j[..., 1, 5] = tau2 * a0 * a2 * cusv * lsv
    j[..., 1, 7] = a0 * a2 * f.Su * cusv
    j[..., 2, 0] = a3 * f.Su
    j[..., 2, 3] = a0 * f.Su
    j[..., 2, 4] = a0 * a3 * su_lsu
    return j


def normals(q_s: np.ndarray, u: np.ndarray, v: np.ndarray, *, step: float = 1e-6) -> np.ndarray:
    """Outward unit normals of the reference shape at (u, v), shape (..., 3).

    n ~ s_v x s_u from central differences with the given step in u and v (section 1,
    singularity 2: analytic tangents hold |cos u|^(eps1 - 1), unbounded for eps < 1, and vanish
    at the equator for eps1 > 1; the differences stay finite and point the right way).  At the
    poles (cos u = 0) the parametrisation collapses (s_v = 0); there n = (0, 0, sgn(sin u)):
    for eps1 < 2 the superquadric's tangent plane at a pole is horizontal (e3 - a0 a3 is of
    order |(e1, e2)|^(2/eps1)), and taper and bend only scale and shift x and y as functions
    of e3, so it stays horizontal.
    """
    u, v = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
    s_u = shape(q_s, u + step, v) - shape(q_s, u - step, v)
    s_v = shape(q_s, u, v + step) - shape(q_s, u, v - step)
    cu, su = _trig(u)
    pole = (cu == 0.0)[..., None]
    n = np.where(pole, np.array([0.0, 0.0, 1.0]) * np.sign(su)[..., None], np.cross(s_v, s_u))
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


@dataclass(frozen=True)
class Mesh:
    """Nodes over (u, v) and their triangles (section 3).

    Node 0 is the south pole (u = -pi/2), node n - 1 the north pole (u = pi/2); between them
    ring i (i = 0 .. n_rings - 1, u_i = -pi/2 + (i + 1) pi / (n_rings + 1)) holds the nodes
    1 + i n_longitudes + j at v_j = -pi + 2 pi j / n_longitudes, so v = pi (= -pi) is one node.
    Triangles are counter-clockwise seen from outside (their normal (p1 - p0) x (p2 - p0)
    points out of the shell).  The poles carry v = 0, which does not matter: cos u = 0 there.
    """

    u: np.ndarray
    v: np.ndarray
    triangles: np.ndarray
    n_rings: int
    n_longitudes: int


def mesh(n_rings: int = 11, n_longitudes: int = 11) -> Mesh:
    """The closed triangulated sphere of n_rings x n_longitudes + 2 nodes (section 3).

    11 x 11 + 2 = 123 nodes is the paper's main experiment, 5 x 5 + 2 = 27 its 'insect'.
    Each quad between rings i and i + 1 (nodes a = (i, j), b = (i, j + 1), c = (i + 1, j + 1),
    d = (i + 1, j)) is split along a-c into (a, b, c) and (a, c, d); the poles are fans.
    That makes 2 n_rings n_longitudes triangles, 3 n_rings n_longitudes edges, and Euler
    characteristic V - E + F = 2.
    """
    if n_rings < 1 or n_longitudes < 3:
        raise ValueError(f"a mesh needs n_rings >= 1 and n_longitudes >= 3, got {n_rings}, {n_longitudes}")
    rings = -np.pi / 2 + np.pi * np.arange(1, n_rings + 1) / (n_rings + 1)
    longitudes = -np.pi + 2.0 * np.pi * np.arange(n_longitudes) / n_longitudes
    u = np.concatenate([[-np.pi / 2], np.repeat(rings, n_longitudes), [np.pi / 2]])
    v = np.concatenate([[0.0], np.tile(longitudes, n_rings), [0.0]])
    south, north = 0, len(u) - 1

    j = np.arange(n_longitudes)
    j1 = (j + 1) % n_longitudes
    triangles = [np.column_stack([np.full(n_longitudes, south), 1 + j1, 1 + j])]
    for i in range(n_rings - 1):
        a, b = 1 + i * n_longitudes + j, 1 + i * n_longitudes + j1
        c, d = b + n_longitudes, a + n_longitudes
        triangles += [np.column_stack([a, b, c]), np.column_stack([a, c, d])]
    top = 1 + (n_rings - 1) * n_longitudes
    triangles.append(np.column_stack([top + j, top + j1, np.full(n_longitudes, north)]))
    return Mesh(u, v, np.concatenate(triangles).astype(np.int64), n_rings, n_longitudes)


def interpolation_matrix(m: Mesh, u: np.ndarray, v: np.ndarray) -> sp.csr_matrix:
    """N (points x nodes): the linear-element weights of the nodes at material points (u, v).

    The displacement at the points is N @ d for nodal displacements d (n, 3); S = N (x) I3.
    With alpha = (v - v_j)/dv and beta = (u - u_i)/du the offsets inside the (u, v) cell:
    in the quad's triangle (a, b, c) (beta <= alpha) the weights are (1 - alpha, alpha - beta,
    beta), in (a, c, d) they are (1 - beta, alpha, beta - alpha); in a pole fan
    (pole, ring node j, ring node j + 1) they are (1 - beta', beta' (1 - alpha), beta' alpha)
    with beta' the share of the way from the pole to the ring.  The field is continuous, and
    a row at a node is that node's selector.  v is taken modulo 2 pi; u must lie in
    [-pi/2, pi/2].
    """
    u, v = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
    u, v = u.ravel(), v.ravel()
    rings, lons = m.n_rings, m.n_longitudes
    n_nodes = len(m.u)

    x = (u + np.pi / 2) * (rings + 1) / np.pi
    band = np.clip(np.floor(x), 0, rings).astype(np.int64)  # 0: south fan, rings: north fan
    beta = x - band
    y = np.mod(v + np.pi, 2.0 * np.pi) * lons / (2.0 * np.pi)
    j = np.clip(np.floor(y), 0, lons - 1).astype(np.int64)
    alpha = y - j
    j1 = (j + 1) % lons

    lower = 1 + (band - 1) * lons  # first node of the ring below (meaningless in the south fan)
    a, b = lower + j, lower + j1
    c, d = b + lons, a + lons
    first = beta <= alpha
    cols = np.column_stack([a, b, c, d])
    weights = np.column_stack(
        [
            np.where(first, 1.0 - alpha, 1.0 - beta),
            np.where(first, alpha - beta, 0.0),
            np.where(first, beta, alpha),
            np.where(first, 0.0, beta - alpha),
        ]
    )
    south = band == 0
    cols[south] = np.column_stack([np.zeros_like(j), 1 + j, 1 + j1, np.zeros_like(j)])[south]
    weights[south] = np.column_stack([1.0 - beta, beta * (1.0 - alpha), beta * alpha, np.zeros_like(beta)])[south]
    north = band == rings
    top = 1 + (rings - 1) * lons
    cols[north] = np.column_stack([top + j, top + j1, np.full_like(j, n_nodes - 1), top + j])[north]
    weights[north] = np.column_stack([(1.0 - beta) * (1.0 - alpha), (1.0 - beta) * alpha, beta, np.zeros_like(beta)])[
        north
    ]

    rows = np.repeat(np.arange(len(u)), 4)
    out = sp.csr_matrix((weights.ravel(), (rows, cols.ravel())), shape=(len(u), n_nodes))
    out.eliminate_zeros()
    return out


def membrane_stiffness(points: np.ndarray, triangles: np.ndarray, *, w0: float, w1: float) -> sp.csr_matrix:
    """K_node = w0 M_h + w1 K_h (n x n), the loaded membrane on linear triangles (section 3).

    It discretises E(d) = 1/2 int [w0 |d|^2 + w1 (|d_u|^2 + |d_v|^2)] dA = 1/2 tr(d^T K_node d)
    for nodal displacements d (n, 3) over the 3-D surface through ``points`` (n, 3), e.g.
    ``shape(q_s, mesh.u, mesh.v)`` (not over the (u, v) rectangle, which degenerates at the
    poles).  K_h is the cotangent Dirichlet matrix, per element K_e[a, b] = e_a . e_b / (4 area)
    with e_a the edge opposite vertex a; M_h is the lumped mass, area/3 per vertex.  The
    stiffness of q_d = d.ravel() is K_dd = K_node (x) I3.  Triangles need a positive area.
    """
    p = np.asarray(points, dtype=np.float64)[triangles]
    edges = p[:, [2, 0, 1]] - p[:, [1, 2, 0]]  # e_a = p_{a+2} - p_{a+1}
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    k_e = np.einsum("mai,mbi->mab", edges, edges) / (4.0 * area)[:, None, None]
    rows = np.broadcast_to(triangles[:, :, None], k_e.shape)
    cols = np.broadcast_to(triangles[:, None, :], k_e.shape)
    n = len(points)
    k_h = sp.csr_matrix((k_e.ravel(), (rows.ravel(), cols.ravel())), shape=(n, n))
    m_h = sp.diags(np.bincount(triangles.ravel(), weights=np.repeat(area / 3.0, 3), minlength=n))
    return (w0 * m_h + w1 * k_h).tocsr()
