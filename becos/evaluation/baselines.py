"""Baseline matchers, so that evaluation tables and plots are real: a floor and an axiomatic method.

``becos baseline NAME STORE --out PRED_DIR [--split test]`` runs one baseline on every pair of a split
and writes predictions in the folder format of :mod:`becos.evaluation.evaluate` (``<pair_id>.npy``: each vertex of
Y to a vertex of X or -1; P2P also ``_overlap_x.npy``/``_overlap_y.npy``) plus ``baseline.json``.
``nn`` (:func:`nearest_neighbour`, nearest vertex in 3D after centring: a floor) and ``zoomout``
(:func:`wks_zoomout`, WKS functional map refined by ZoomOut). Both work in the records' final frame and
units, distances divided by each shape's full sqrt-area. Method details, scores and costs:
docs/design/evaluate.md.
"""

from __future__ import annotations

import contextlib
import json
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as sla
from scipy.spatial import cKDTree

from becos.atomic import write_text
from becos.build.record import PairRecord
from becos.errors import BecosError
from becos.evaluation.evaluate import Prediction, write_prediction


def _unit_scale(record: PairRecord, s: str) -> float:
    """The length that makes shape ``s``'s FULL shape unit-area (1 for area-normalised records)."""
    return 1.0 if record.meta.get("area_normalised") else float(record.arrays[f"{s}_full_sqrt_area"])


def _is_p2p(record: PairRecord) -> bool:
    setting = record.meta.get("setting")
    if setting is not None:
        return setting == "partial_partial"
    a = record.arrays
    return all((a[f"{s}_full_to_partial"] < 0).any() for s in ("x", "y"))


def overlap_by_distance(points_y: np.ndarray, points_x: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """(V_y,) and (V_x,) bool: a vertex is in the overlap when the other shape has a vertex within
    ``threshold`` (same units as the points)."""
    d_y, _ = cKDTree(points_x).query(points_y, distance_upper_bound=threshold)
    d_x, _ = cKDTree(points_y).query(points_x, distance_upper_bound=threshold)
    return np.isfinite(d_y), np.isfinite(d_x)


# --------------------------------------------------------------------------------------------
# Nearest neighbour in 3D


@dataclass(frozen=True)
class NearestNeighbourOptions:
    """``overlap_threshold``: P2P overlap distance, in units of sqrt(full area)."""

    overlap_threshold: float = 0.03


def nearest_neighbour(record: PairRecord, options: NearestNeighbourOptions = NearestNeighbourOptions()) -> Prediction:
    """Each Y vertex -> the nearest X vertex after subtracting each shape's centroid (see
    docs/design/evaluate.md). Shapes are compared at unit full-shape area."""
    x = record["x_vertices"] / _unit_scale(record, "x")
    y = record["y_vertices"] / _unit_scale(record, "y")
    x = x - x.mean(axis=0)
    y = y - y.mean(axis=0)
    _, mapping = cKDTree(x).query(y)
    mapping = mapping.astype(np.int64)
    if not _is_p2p(record):
        return Prediction(mapping)
    overlap_y, overlap_x = overlap_by_distance(y, x, options.overlap_threshold)
    return Prediction(np.where(overlap_y, mapping, -1), overlap_x, overlap_y)


# --------------------------------------------------------------------------------------------
# Spectral: WKS + functional map + ZoomOut


@dataclass(frozen=True)
class ZoomOutOptions:
    """Parameters of :func:`wks_zoomout`.

    Attributes:
        n_eigen: eigenpairs per shape (WKS uses all of them; ZoomOut grows up to ``k_final``).
        n_energies: WKS energies (log-spaced over the shared eigenvalue range).
        wks_variance: WKS bandwidth as a multiple of the energy spacing (Aubry et al.: 7).
        descriptor_step: every how many WKS energies one descriptor is kept for the first map.
        k_init: size of the first functional map (from descriptors).
        k_final, k_step: ZoomOut's last basis size and step.
        w_lap, w_comm, w_orient: weights of the Laplacian-commutativity, descriptor-commutativity and
            orientation terms of :func:`functional_map` (the descriptor term has weight 1).
        orient_descriptors: how many of the kept descriptors (lowest energies first) define orientation
            operators (smooth ones: their gradient fields are reliable).
        n_samples: Y vertices sampled for the ZoomOut iterations (all when fewer).
        overlap_threshold: P2P overlap distance after alignment, in units of sqrt(full area).
        seed: seed of the vertex sample.
    """

    n_eigen: int = 60
    n_energies: int = 100
    wks_variance: float = 7.0
    descriptor_step: int = 5
    k_init: int = 20
    k_final: int = 60
    k_step: int = 4
    w_lap: float = 1.0
    w_comm: float = 1.0
    w_orient: float = 3e-2
    orient_descriptors: int = 5
    n_samples: int = 2000
    overlap_threshold: float = 0.03
    seed: int = 0


def eigenpairs(vertices: np.ndarray, faces: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The first ``k`` eigenpairs of the robust Laplacian: ``L φ = λ M φ``.

    Returns:
        evals (k,) ascending (first ~0), evecs (V, k) M-orthonormal, mass (V,) lumped vertex areas;
        in the units of ``vertices`` (λ scales as 1/length²).
    """
    import robust_laplacian

    stiffness, mass = robust_laplacian.mesh_laplacian(
        np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    )
    k = min(k, len(vertices) - 2)
    area = float(mass.diagonal().sum())
    start = np.random.default_rng(0).standard_normal(len(vertices))  # ARPACK's start: fixed, for repeatable runs
    evals, evecs = sla.eigsh(stiffness, k, mass, sigma=-1e-6 / max(area, 1e-300), which="LM", v0=start)
    order = np.argsort(evals)
    return np.maximum(evals[order], 0.0), evecs[:, order], mass.diagonal().copy()


def wave_kernel_signature(
    evals: np.ndarray, evecs: np.ndarray, mass: np.ndarray, energies: np.ndarray, sigma: float
) -> np.ndarray:
    """(V, E) WKS at log-energies ``energies`` with bandwidth ``sigma`` (the zero eigenpair skipped),
    each column scaled to unit M-norm."""
    log_l = np.log(np.maximum(evals[1:], 1e-12))
    coefs = np.exp(-((energies[None, :] - log_l[:, None]) ** 2) / (2.0 * sigma**2))  # (k-1, E)
    desc = (evecs[:, 1:] ** 2) @ coefs / np.maximum(coefs.sum(axis=0), 1e-300)
    norms = np.sqrt(mass @ desc**2)
    return desc / np.maximum(norms, 1e-300)


def _nearest_rows(targets: np.ndarray, queries: np.ndarray, block: int = 2048) -> np.ndarray:
    """(Q,) index of the nearest row of ``targets`` (T, k) for each row of ``queries`` (Q, k), by
    blocked brute force in float32 (faster than a k-d tree in 20-60 dimensions)."""
    t = np.ascontiguousarray(targets, dtype=np.float32)
    q = np.ascontiguousarray(queries, dtype=np.float32)
    half_sq = 0.5 * np.einsum("ij,ij->i", t, t)
    out = np.empty(len(q), dtype=np.int64)
    for start in range(0, len(q), block):
        scores = q[start : start + block] @ t.T - half_sq[None, :]
        out[start : start + block] = scores.argmax(axis=1)
    return out


def face_gradients(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-face gradients of the hat functions: (F, 3, 3) ``grad[f, c]`` = gradient (a 3-vector) of the
    hat function of corner c on face f, and (F,) face areas. Independent of the faces' winding."""
    tri = vertices[faces]  # (F, 3 corners, 3)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    double_area = np.linalg.norm(normal, axis=1)
    safe = np.maximum(double_area, 1e-300)
    unit = normal / safe[:, None]
    opposite = np.stack([tri[:, 2] - tri[:, 1], tri[:, 0] - tri[:, 2], tri[:, 1] - tri[:, 0]], axis=1)
    grad = np.cross(unit[:, None, :], opposite) / safe[:, None, None]
    return grad, 0.5 * double_area


def orientation_operators(
    vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, evecs: np.ndarray, descriptors: np.ndarray
) -> np.ndarray:
    """(D, k, k) reduced orientation operators (Ren et al. 2018): for each descriptor f, the operator
    ``g -> <n x grad f / |grad f|, grad g>`` in the basis ``evecs`` (V, k), integrated with face areas;
    ``normals`` (F, 3) are consistently oriented unit face normals. A reflection flips its sign, so
    ``C O_X = O_Y C`` makes a functional map prefer orientation-preserving solutions."""
    grad, area = face_gradients(vertices, faces)
    basis_grad = np.einsum("fcd,fck->fdk", grad, evecs[faces])  # (F, 3, k)
    basis_face = evecs[faces].mean(axis=1) * area[:, None]  # (F, k)
    out = np.empty((descriptors.shape[1], evecs.shape[1], evecs.shape[1]))
    for d in range(descriptors.shape[1]):
        g = np.einsum("fcd,fc->fd", grad, descriptors[faces, d])
        field = np.cross(normals, g)
        field /= np.maximum(np.linalg.norm(field, axis=1, keepdims=True), 1e-300)
        out[d] = basis_face.T @ np.einsum("fd,fdk->fk", field, basis_grad)
    return out


def multiplication_operators(evecs: np.ndarray, mass: np.ndarray, descriptors: np.ndarray) -> np.ndarray:
    """(D, k, k) reduced operators of pointwise multiplication by each descriptor: Φᵀ M diag(f) Φ."""
    weighted = evecs * mass[:, None]
    return np.einsum("vi,vd,vj->dij", weighted, descriptors, evecs)


def _sylvester_normal(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Normal matrix of |C P - Q C|² in row-major vec(C) (k² x k²)."""
    k = p.shape[0]
    eye = np.eye(k)
    m = np.kron(eye, p.T) - np.kron(q, eye)
    return m.T @ m


def _balanced(ops_x: np.ndarray, ops_y: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Operator pairs divided by the geometric mean of their Frobenius norms and by sqrt(count), times
    the descriptor coefficients' norm |A|: a family of D operator pairs then weighs about as much as
    the descriptor term, whatever D and the operators' units."""
    if len(ops_x) == 0:
        return ops_x, ops_y
    norms = np.sqrt(np.linalg.norm(ops_x, axis=(1, 2)) * np.linalg.norm(ops_y, axis=(1, 2)))
    scale = np.linalg.norm(a) / (np.maximum(norms, 1e-300) * np.sqrt(len(ops_x)))
    return ops_x * scale[:, None, None], ops_y * scale[:, None, None]


def functional_map(
    a: np.ndarray,
    b: np.ndarray,
    evals_x: np.ndarray,
    evals_y: np.ndarray,
    commute_x: np.ndarray,
    commute_y: np.ndarray,
    orient_x: np.ndarray,
    orient_y: np.ndarray,
    weights: tuple[float, float, float],
) -> np.ndarray:
    """(k, k) map C from X's to Y's spectral coefficients: the minimiser of
    ``|C A - B|² + w_lap |A|²/k Σ C_ij² (λY_i - λX_j)² / s + w_comm Σ_d |C P_d - Q_d C|²
    + w_orient Σ_d |C O_d - O'_d C|²`` (pyFM's energy: descriptor preservation, Laplacian
    commutativity with s the mean squared eigenvalue difference, descriptor commutativity,
    orientation preservation), solved exactly as one k² x k² linear system. Each operator family is first balanced against the
    descriptor term (:func:`_balanced`).

    Args:
        a, b: (k, E) descriptor coefficients on X and Y.
        evals_x, evals_y: (k,) eigenvalues.
        commute_x, commute_y: (D, k, k) multiplication operators; orient_x, orient_y: (D', k, k).
        weights: (w_lap, w_comm, w_orient).
    """
    k = a.shape[0]
    w_lap, w_comm, w_orient = weights
    eye = np.eye(k)
    # operator terms are scaled so that each family weighs like the descriptor term at weight 1
    commute_x, commute_y = _balanced(commute_x, commute_y, a)
    orient_x, orient_y = _balanced(orient_x, orient_y, a)
    h = np.kron(eye, a @ a.T)
    rhs = (b @ a.T).ravel()
    diff = (evals_y[:k, None] - evals_x[None, :k]) ** 2
    h[np.diag_indices_from(h)] += w_lap * (np.sum(a**2) / k) * (diff / max(float(diff.mean()), 1e-300)).ravel()
    for p, q in zip(commute_x, commute_y):
        h += w_comm * _sylvester_normal(p, q)
    for p, q in zip(orient_x, orient_y):
        h += w_orient * _sylvester_normal(p, q)
    return np.linalg.solve(h, rhs).reshape(k, k)


def zoomout_refine(
    c: np.ndarray, evecs_x: np.ndarray, evecs_y: np.ndarray, k_final: int, k_step: int, sample: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """ZoomOut from ``c`` (k0, k0) up to ``k_final``.

    ``c`` maps X's spectral coefficients to Y's (the pull-back of a map T: Y -> X, ``Φ_Y C ≈ Φ_X[T]``).
    At each size: map the sampled Y vertices to their nearest X vertex in the embedding (rows of
    ``Φ_Y C`` against rows of ``Φ_X``), then refit C one step larger by least squares on those pairs.
    Returns the final C and the full (V_y,) map."""
    k = c.shape[0]
    while True:
        mapped = _nearest_rows(evecs_x[:, :k], evecs_y[sample, :k] @ c)
        if k >= k_final:
            break
        k = min(k + k_step, k_final)
        c = np.linalg.lstsq(evecs_y[sample, :k], evecs_x[mapped, :k], rcond=None)[0]
    return c, _nearest_rows(evecs_x[:, :k], evecs_y[:, :k] @ c)


def trimmed_procrustes(source: np.ndarray, target: np.ndarray, keep: float = 0.5, rounds: int = 4):
    """Rigid fit of ``source`` onto ``target`` (paired rows), refitted on the ``keep`` share of pairs
    with the smallest residuals ``rounds`` times. Returns (R, t) with target ≈ source @ R.T + t."""
    from becos.core.align import procrustes

    use = np.ones(len(source), dtype=bool)
    fit = procrustes(source, target, use)
    for _ in range(rounds):
        residual = np.linalg.norm(fit.apply(source) - target, axis=1)
        use = residual <= np.quantile(residual, keep)
        fit = procrustes(source, target, use)
    return fit


def _oriented_normals(record: PairRecord, s: str, vertices: np.ndarray) -> np.ndarray:
    """(F_s, 3) consistently oriented (outward) unit face normals of shape ``s`` at ``vertices``,
    oriented on the full shape when the record carries it (a partial shape's own orientation can come
    out inside-out)."""
    from becos.core.geometry import oriented_face_normals
    from becos.core.mesh import TriMesh

    a = record.arrays
    if len(a.get(f"{s}_full_faces", ())):
        full = TriMesh(a[f"{s}_full_vertices"], a[f"{s}_full_faces"])
        reference = oriented_face_normals(full)[a[f"{s}_full_face_ids"]]
    else:
        reference = oriented_face_normals(TriMesh(vertices, a[f"{s}_faces"]))
    tri = vertices[a[f"{s}_faces"]]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    sign = np.where(np.einsum("fd,fd->f", normal, reference) < 0, -1.0, 1.0)
    return normal * sign[:, None]


def spectral_map(record: PairRecord, options: ZoomOutOptions = ZoomOutOptions()) -> np.ndarray:
    """(V_y,) Y -> X vertex map of the WKS functional map refined by ZoomOut (no overlap decision)."""
    x = record["x_vertices"] / _unit_scale(record, "x")
    y = record["y_vertices"] / _unit_scale(record, "y")
    ex, vx, mx = eigenpairs(x, record["x_faces"], options.n_eigen)
    ey, vy, my = eigenpairs(y, record["y_faces"], options.n_eigen)
    k_eig = min(len(ex), len(ey))
    # shared log-energies over the union of both spectra (zero eigenvalues left out)
    lo = np.log(max(min(ex[1], ey[1]), 1e-12))
    hi = np.log(max(ex[k_eig - 1], ey[k_eig - 1], 1e-12))
    sigma = options.wks_variance * (hi - lo) / options.n_energies
    energies = np.linspace(lo + 2 * sigma, hi - 2 * sigma, options.n_energies)
    dx = wave_kernel_signature(ex[:k_eig], vx[:, :k_eig], mx, energies, sigma)[:, :: options.descriptor_step]
    dy = wave_kernel_signature(ey[:k_eig], vy[:, :k_eig], my, energies, sigma)[:, :: options.descriptor_step]
    k0 = min(options.k_init, k_eig)
    bx, by = vx[:, :k0], vy[:, :k0]
    a = bx.T @ (mx[:, None] * dx)
    b = by.T @ (my[:, None] * dy)
    n_orient = options.orient_descriptors
    orient_x = orientation_operators(x, record["x_faces"], _oriented_normals(record, "x", x), bx, dx[:, :n_orient])
    orient_y = orientation_operators(y, record["y_faces"], _oriented_normals(record, "y", y), by, dy[:, :n_orient])
    c = functional_map(
        a,
        b,
        ex,
        ey,
        multiplication_operators(bx, mx, dx),
        multiplication_operators(by, my, dy),
        orient_x,
        orient_y,
        (options.w_lap, options.w_comm, options.w_orient),
    )
    rng = np.random.default_rng(options.seed)
    n_y = len(y)
    sample = np.sort(rng.choice(n_y, options.n_samples, replace=False)) if n_y > options.n_samples else np.arange(n_y)
    _, mapping = zoomout_refine(c, vx, vy, min(options.k_final, k_eig), options.k_step, sample)
    return mapping


def single_threaded_blas():
    """A context limiting BLAS to one thread (threadpoolctl, when installed; else no-op). Per-pair jobs
    run side by side; a multi-threaded BLAS then oversubscribes the cores (measured on 2 busy cores:
    ARPACK and small least-squares solves 5-10x slower)."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - optional dependency
        return contextlib.nullcontext()
    return threadpool_limits(1, user_api="blas")


def wks_zoomout(record: PairRecord, options: ZoomOutOptions = ZoomOutOptions()) -> Prediction:
    """WKS functional map refined by ZoomOut (docs/design/evaluate.md). Y -> X map, -1 only outside the
    predicted overlap of a P2P pair."""
    with single_threaded_blas():
        mapping = spectral_map(record, options)
    if not _is_p2p(record):
        return Prediction(mapping)
    x = record["x_vertices"] / _unit_scale(record, "x")
    y = record["y_vertices"] / _unit_scale(record, "y")
    fit = trimmed_procrustes(y, x[mapping])
    overlap_y, overlap_x = overlap_by_distance(fit.apply(y), x, options.overlap_threshold)
    return Prediction(np.where(overlap_y, mapping, -1), overlap_x, overlap_y)


BASELINES = {"nn": (nearest_neighbour, NearestNeighbourOptions), "zoomout": (wks_zoomout, ZoomOutOptions)}
"""name -> (function(record, options) -> Prediction, options class)."""


def run_baseline(name: str, records, out: str | Path, options=None, progress: bool = False) -> dict:
    """Run baseline ``name`` on every record of ``records`` (an iterable of :class:`PairRecord`) and
    write the predictions into folder ``out``; returns the run facts also written to
    ``out/baseline.json``."""
    if name not in BASELINES:
        raise BecosError(f"unknown baseline {name!r}; choose one of {sorted(BASELINES)}")
    function, options_class = BASELINES[name]
    options = options or options_class()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    seconds, count = [], 0
    for record in records:
        t0 = time.perf_counter()
        write_prediction(out, record.pair_id, function(record, options))
        seconds.append(time.perf_counter() - t0)
        count += 1
        if progress:
            print(f"becos baseline {name}: {count} pairs, last {seconds[-1]:.2f} s", file=sys.stderr)
    facts = {
        "baseline": name,
        "options": asdict(options),
        "n_pairs": count,
        "seconds_total": round(time.perf_counter() - started, 2),
        "seconds_per_pair_median": round(float(np.median(seconds)), 3) if seconds else None,
    }
    write_text(out / "baseline.json", json.dumps(facts, indent=2, sort_keys=True) + "\n")
    return facts
