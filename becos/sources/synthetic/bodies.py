"""Articulated synthetic bodies: parts, skeletons, the implicit surface, charts and posing.

A body is a tree of parts, each a tapered capsule around a bone ``a -> b``, in becos's common frame
(metres, +y up, facing +z, anatomical left = +x, feet at y ~ 0). Derived, vectorised over points and
parts: the part field ``f_p(x)`` (metres, < 0 inside) and the implicit surface, the part label
(``argmin_p f_p``) and the chart of a point on part p's canonical capsule (shared by part *name* across
classes, which gives the correspondences). Part names: ``b_*`` biped, ``q_*`` quadruped (a centaur has
both), ``_l``/``_r`` left/right copies. In detail: docs/design/data.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from becos.seeding import rng_for

CANONICAL_LENGTH = 3.0
"""Length of every canonical capsule (its radius is 1); the chart's axial coordinate is t * this."""

PART_GROUPS = {"horns": ("b_horn_l", "b_horn_r", "q_horn_l", "q_horn_r"), "tail": ("b_tail", "q_tail")}
"""Optional parts that some classes lack (a semantic missing part for their correspondences)."""


@dataclass(frozen=True)
class Part:
    """One body part: a tapered capsule with elliptic cross-section around the bone ``a -> b``.

    Attributes:
        name: part name (see docs/design/data.md).
        parent: name of the parent part (None for the root), the part it is blended with and moves with.
        a, b: (3,) bone end points, metres, common frame; ``a`` is the joint the part rotates about.
        ra, rb: radius at ``a`` and at ``b`` (metres), linear in between, spherical-ish caps.
        sx, sy: cross-section semi-axis factors along the bone frame's e1 and e2 (1 = circular).
        k: blending width (metres) of the smooth union with the parent.
    """

    name: str
    parent: str | None
    a: tuple[float, float, float]
    b: tuple[float, float, float]
    ra: float
    rb: float
    sx: float = 1.0
    sy: float = 1.0
    k: float = 0.02


def mirror(part: Part) -> Part:
    """The right-side copy (x -> -x) of a left part (name ``*_l`` -> ``*_r``, parent likewise)."""

    def flip(p):
        return (-p[0], p[1], p[2])

    def rename(n):
        return n[:-2] + "_r" if n is not None and n.endswith("_l") else n

    return Part(
        rename(part.name), rename(part.parent), flip(part.a), flip(part.b), part.ra, part.rb, part.sx, part.sy, part.k
    )


def _with_mirrors(parts: list[Part]) -> list[Part]:
    out = []
    for p in parts:
        out.append(p)
        if p.name.endswith("_l"):
            out.append(mirror(p))
    return out


# --- body plans --------------------------------------------------------------------------------


def _upper_body(waist: np.ndarray, s: float, g: float, head: float, horns: bool, parent: str | None) -> list[Part]:
    """Biped upper body (chest, neck, head, arms, optional horns) above the waist point (metres).

    Coordinates are those of a 1.75 m reference human whose waist is at y = 1.04, scaled by ``s``
    (height), radii and lateral offsets by ``g`` (girth), the head by ``head``.
    """
    w = np.asarray(waist, float)

    def P(x, y, z, lateral=True):  # reference-human coordinate -> this body's
        return tuple(w + np.array([x * (g if lateral else 1.0), y - 1.04, z]) * s)

    r = s * g
    hs = s * head
    head_base = np.array(P(0, 1.62, 0.015))
    parts = [
        Part("b_chest", parent, P(0, 1.04, 0), P(0, 1.28, 0), 0.135 * r, 0.16 * r, 1.0, 0.62, 0.07 * s),
        Part("b_neck", "b_chest", P(0, 1.38, 0), P(0, 1.56, 0.01), 0.052 * r, 0.048 * r, k=0.03 * s),
        Part(
            "b_head",
            "b_neck",
            tuple(head_base),
            tuple(head_base + np.array([0, 0.07, 0.005]) * hs),
            0.09 * hs,
            0.085 * hs,
            0.9,
            1.05,
            0.025 * s,
        ),
        Part("b_upperarm_l", "b_chest", P(0.20, 1.34, 0), P(0.26, 1.08, -0.01), 0.052 * r, 0.042 * r, k=0.04 * s),
        Part(
            "b_forearm_l", "b_upperarm_l", P(0.26, 1.08, -0.01), P(0.29, 0.86, 0.02), 0.041 * r, 0.032 * r, k=0.02 * s
        ),
        Part(
            "b_hand_l",
            "b_forearm_l",
            P(0.29, 0.86, 0.02),
            P(0.30, 0.74, 0.03),
            0.032 * r,
            0.028 * r,
            0.75,
            1.0,
            0.015 * s,
        ),
    ]
    if horns:
        base = head_base + np.array([0.05, 0.10, 0.025]) * hs
        parts.append(
            Part(
                "b_horn_l",
                "b_head",
                tuple(base),
                tuple(base + np.array([0.06, 0.13, 0.03]) * hs),
                0.032 * hs,
                0.02 * hs,
                k=0.015 * s,
            )
        )
    return parts


def humanoid(
    height: float = 1.75, girth: float = 1.0, head: float = 1.0, horns: bool = False, tail: bool = False
) -> list[Part]:
    """A humanoid standing upright (feet at y ~ 0, facing +z, arms hanging slightly apart), metres."""
    s, g = height / 1.75, girth
    r = s * g

    def P(x, y, z):
        return (x * g * s, y * s, z * s)

    parts = [Part("b_pelvis", None, P(0, 0.86, 0), P(0, 1.04, 0), 0.15 * r, 0.135 * r, 1.0, 0.68, 0.07 * s)]
    parts += _upper_body(np.array([0.0, 1.04 * s, 0.0]), s, g, head, horns, "b_pelvis")
    parts += [
        Part("b_thigh_l", "b_pelvis", P(0.10, 0.88, 0), P(0.11, 0.50, 0), 0.085 * r, 0.055 * r, k=0.05 * s),
        Part("b_shin_l", "b_thigh_l", P(0.11, 0.50, 0), P(0.11, 0.10, -0.02), 0.055 * r, 0.04 * r, k=0.02 * s),
        Part(
            "b_foot_l",
            "b_shin_l",
            P(0.11, 0.07, -0.03),
            P(0.115, 0.045, 0.15),
            0.045 * r,
            0.035 * r,
            1.0,
            0.7,
            0.02 * s,
        ),
    ]
    if tail:
        parts.append(Part("b_tail", "b_pelvis", P(0, 0.92, -0.10), P(0, 0.62, -0.42), 0.045 * r, 0.025 * r, k=0.03 * s))
    return _with_mirrors(parts)


def _quadruped_head(P, s: float, r: float, neck: float, horns: bool) -> list[Part]:
    """Quadruped neck, head and (``horns``) left horn on the barrel's front, metres: ``P`` maps the reference
    coordinates of :func:`_quadruped_parts` to the body's, ``s`` its size, ``r`` size x girth; ``neck``
    stretches the neck, and the head moves with the neck's end."""
    n0 = np.array(P(0, 0.62, 0.30))
    n1 = n0 + (np.array(P(0, 0.82, 0.46)) - n0) * neck
    shift = n1 - np.array(P(0, 0.82, 0.46))
    h0 = np.array(P(0, 0.86, 0.48)) + shift
    h1 = np.array(P(0, 0.80, 0.66)) + shift
    parts = [
        Part("q_neck", "q_barrel", tuple(n0), tuple(n1), 0.075 * r, 0.055 * r, k=0.05 * s),
        Part("q_head", "q_neck", tuple(h0), tuple(h1), 0.075 * r, 0.042 * r, 0.85, 1.0, 0.03 * s),
    ]
    if horns:
        base = np.array(P(0.035, 0.93, 0.50)) + shift
        tip = base + np.array([0.055, 0.13, -0.08]) * s
        parts.append(Part("q_horn_l", "q_head", tuple(base), tuple(tip), 0.03 * s, 0.02 * s, k=0.015 * s))
    return parts


def _quadruped_legs(P, s: float, r: float) -> list[Part]:
    """Quadruped left fore and hind legs (upper, lower, foot), metres; arguments as :func:`_quadruped_head`."""
    return [
        Part(
            "q_fupper_l",
            "q_barrel",
            P(0.09, 0.50, 0.28, True),
            P(0.10, 0.30, 0.30, True),
            0.055 * r,
            0.042 * r,
            k=0.05 * s,
        ),
        Part(
            "q_flower_l",
            "q_fupper_l",
            P(0.10, 0.30, 0.30, True),
            P(0.10, 0.08, 0.29, True),
            0.038 * r,
            0.03 * r,
            k=0.02 * s,
        ),
        Part(
            "q_ffoot_l",
            "q_flower_l",
            P(0.10, 0.06, 0.29, True),
            P(0.10, 0.04, 0.34, True),
            0.033 * r,
            0.03 * r,
            k=0.015 * s,
        ),
        Part(
            "q_hupper_l",
            "q_barrel",
            P(0.09, 0.50, -0.35, True),
            P(0.10, 0.30, -0.40, True),
            0.07 * r,
            0.045 * r,
            k=0.05 * s,
        ),
        Part(
            "q_hlower_l",
            "q_hupper_l",
            P(0.10, 0.30, -0.40, True),
            P(0.10, 0.08, -0.36, True),
            0.04 * r,
            0.03 * r,
            k=0.02 * s,
        ),
        Part(
            "q_hfoot_l",
            "q_hlower_l",
            P(0.10, 0.06, -0.36, True),
            P(0.10, 0.04, -0.31, True),
            0.033 * r,
            0.03 * r,
            k=0.015 * s,
        ),
    ]


def _quadruped_parts(
    size: float,
    legs: float,
    girth: float,
    neck: float,
    length: float,
    horns: bool,
    tail: str | None,
    head_and_neck: bool = True,
) -> list[Part]:
    """A quadruped's parts before mirroring (left side only), metres; arguments as :func:`quadruped`,
    ``head_and_neck`` False for a centaur's lower body."""
    s, g = size, girth
    r = s * g

    def P(x, y, z, leg=False):
        # reference coordinates: barrel ~0.55 m high; legs stretch vertically by `legs`
        yy = y * legs if leg else y + (legs - 1.0) * 0.5
        return (x * g * s, yy * s, z * length * s)

    parts = [Part("q_barrel", None, P(0, 0.55, -0.35), P(0, 0.57, 0.28), 0.15 * r, 0.16 * r, 0.8, 1.0, 0.05 * s)]
    if head_and_neck:
        parts += _quadruped_head(P, s, r, neck, horns)
    parts += _quadruped_legs(P, s, r)
    if tail == "long":
        parts.append(Part("q_tail", "q_barrel", P(0, 0.60, -0.45), P(0, 0.42, -0.74), 0.04 * r, 0.022 * r, k=0.03 * s))
    elif tail == "short":
        parts.append(Part("q_tail", "q_barrel", P(0, 0.60, -0.45), P(0, 0.56, -0.58), 0.04 * r, 0.028 * r, k=0.03 * s))
    return parts


def quadruped(
    size: float = 1.0,
    legs: float = 1.0,
    girth: float = 1.0,
    neck: float = 1.0,
    length: float = 1.0,
    horns: bool = False,
    tail: str | None = "long",
) -> list[Part]:
    """A four-legged animal standing on its feet (y ~ 0), facing +z, metres.

    ``size`` scales everything, ``legs`` the leg length, ``girth`` radii and lateral offsets,
    ``neck`` the neck length, ``length`` the body length; ``tail`` is "long", "short" or None.
    """
    return _with_mirrors(_quadruped_parts(size, legs, girth, neck, length, horns, tail))


def centaur(
    size: float = 1.2,
    legs: float = 1.1,
    girth: float = 1.0,
    length: float = 1.0,
    height: float = 1.75,
    upper_girth: float = 1.0,
    tail: str | None = "long",
) -> list[Part]:
    """A composite class: a quadruped lower body (no neck/head) with a biped upper body on its front."""
    lower = _quadruped_parts(size, legs, girth, 1.0, length, False, tail, head_and_neck=False)
    barrel = lower[0]
    front = np.array(barrel.b)
    waist = front + np.array([0.0, 0.10 * size, 0.0])
    upper = _upper_body(waist, height / 1.75, upper_girth, 1.0, False, "q_barrel")
    return _with_mirrors(lower + upper)


# --- the class catalogue -----------------------------------------------------------------------


@dataclass(frozen=True)
class ClassSpec:
    """One synthetic class: its dataset, category and body.

    Attributes:
        dataset: dataset name (lowercase alphanumeric).
        name: class name (lowercase letters; its shapes are ``<name><pose>``, the template ``<name>0``).
        category: "human", "four-legged" or "centaur" (as TOSCA's categories).
        parts: the body in its rest pose (the template pose).
    """

    dataset: str
    name: str
    category: str
    parts: tuple[Part, ...]

    @property
    def template(self) -> str:
        return f"{self.name}0"

    @property
    def node(self) -> str:
        """Network node / annotation file prefix ``<dataset>_<template>``."""
        return f"{self.dataset}_{self.template}"

    @property
    def part_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parts)


def _spec(dataset, name, category, parts) -> ClassSpec:
    return ClassSpec(dataset, name, category, tuple(parts))


CLASSES: tuple[ClassSpec, ...] = (
    _spec("synthy", "alba", "human", humanoid(1.70, 1.0)),
    _spec("synthy", "brute", "human", humanoid(1.90, 1.2, head=0.95, horns=True)),
    _spec("synthy", "cyra", "human", humanoid(1.60, 0.85, head=1.08)),
    _spec("synthy", "hound", "four-legged", quadruped(0.85, 1.0, 0.8, 0.9, 1.1, tail="long")),
    _spec("synthy", "goat", "four-legged", quadruped(0.8, 0.9, 1.0, 1.0, 1.0, horns=True, tail="short")),
    _spec("synthy", "tapir", "four-legged", quadruped(1.0, 0.75, 1.2, 0.9, 1.0, tail=None)),
    _spec("synthz", "dario", "human", humanoid(1.80, 1.05, tail=True)),
    _spec("synthz", "elin", "human", humanoid(1.75, 0.95, head=1.03)),
    _spec("synthz", "faun", "human", humanoid(1.65, 0.9, horns=True)),
    _spec("synthz", "lynx", "four-legged", quadruped(0.75, 0.85, 0.8, 0.7, 1.0, tail="long")),
    _spec("synthz", "pony", "four-legged", quadruped(1.25, 1.15, 1.0, 1.3, 1.0, tail="long")),
    _spec("synthz", "ram", "four-legged", quadruped(0.95, 0.85, 1.2, 0.8, 1.0, horns=True, tail="short")),
    _spec("synthz", "centaur", "centaur", centaur()),
)
"""All classes, in generation order. Class names are not prefixes of one another (the annotation
file lookup globs ``<ds>_<template>*``)."""


def class_spec(dataset: str, name: str) -> ClassSpec:
    """The :class:`ClassSpec` of a class; KeyError naming the known classes otherwise."""
    for spec in CLASSES:
        if spec.dataset == dataset and spec.name == name:
            return spec
    raise KeyError(f"no synthetic class {dataset}/{name}; known: {[f'{c.dataset}/{c.name}' for c in CLASSES]}")


# --- vectorised geometry of a body -------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Body:
    """Array form of a list of parts (P parts), for vectorised evaluation.

    Attributes:
        names: (P,) part names; parents: (P,) parent index (-1 for the root); parents precede children.
        a, b: (P, 3) bone ends; axis, e1, e2: (P, 3) orthonormal bone frames (axis = a->b); length: (P,).
        ra, rb, sx, sy, k: (P,) radii, cross-section factors, blend widths.
        edges: (E, 2) (part, parent) index pairs, blend widths ``edge_k`` (E,).
    """

    names: tuple[str, ...]
    parents: np.ndarray
    a: np.ndarray
    b: np.ndarray
    axis: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    length: np.ndarray
    ra: np.ndarray
    rb: np.ndarray
    sx: np.ndarray
    sy: np.ndarray
    k: np.ndarray
    edges: np.ndarray = field(default=None)
    edge_k: np.ndarray = field(default=None)

    @classmethod
    def from_parts(cls, parts) -> Body:
        names = tuple(p.name for p in parts)
        index = {n: i for i, n in enumerate(names)}
        parents = np.array([index[p.parent] if p.parent is not None else -1 for p in parts], dtype=np.int64)
        if (parents >= np.arange(len(parts))).any():
            raise ValueError("parts must list every parent before its children")
        a = np.array([p.a for p in parts], float)
        b = np.array([p.b for p in parts], float)
        d = b - a
        length = np.linalg.norm(d, axis=1)
        axis = d / length[:, None]
        # e1: anatomical left (+x) made orthogonal to the axis; +z where the bone runs along x
        ref = np.where(np.abs(axis[:, :1]) > 0.8, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
        e1 = ref - np.einsum("pi,pi->p", ref, axis)[:, None] * axis
        e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
        e2 = np.cross(axis, e1)
        child = np.flatnonzero(parents >= 0)
        edges = np.stack([child, parents[child]], axis=1)
        k = np.array([p.k for p in parts], float)
        return cls(
            names,
            parents,
            a,
            b,
            axis,
            e1,
            e2,
            length,
            np.array([p.ra for p in parts], float),
            np.array([p.rb for p in parts], float),
            np.array([p.sx for p in parts], float),
            np.array([p.sy for p in parts], float),
            k,
            edges,
            k[child],
        )

    @property
    def n_parts(self) -> int:
        return len(self.names)

    def _local(self, points: np.ndarray, parts: np.ndarray | None = None):
        """Bone-local quantities of (N, 3) points against parts (all, or the (M,) index array).

        Returns t (N, M), the clamped axial parameter in [0, 1], and s1, s2, s3 (N, M): the offset
        from the bone point at t in (e1 / sx, e2 / sy, axis) coordinates (metres). Matrix products
        only (no (N, M, 3) temporaries): e1, e2 are orthogonal to the axis, so the offset's e1/e2
        components do not depend on t.
        """
        idx = np.arange(self.n_parts) if parts is None else np.asarray(parts)
        a = self.a[idx]
        along = points @ self.axis[idx].T - np.einsum("mi,mi->m", a, self.axis[idx])
        t = np.clip(along / self.length[idx], 0.0, 1.0)
        s1 = (points @ self.e1[idx].T - np.einsum("mi,mi->m", a, self.e1[idx])) / self.sx[idx]
        s2 = (points @ self.e2[idx].T - np.einsum("mi,mi->m", a, self.e2[idx])) / self.sy[idx]
        s3 = along - t * self.length[idx]
        return t, s1, s2, s3

    def part_fields(self, points: np.ndarray, parts: np.ndarray | None = None) -> np.ndarray:
        """(N, M) part field values (metres, negative inside) of (N, 3) points."""
        idx = np.arange(self.n_parts) if parts is None else np.asarray(parts)
        t, s1, s2, s3 = self._local(points, idx)
        radius = self.ra[idx] + (self.rb[idx] - self.ra[idx]) * t
        scale = np.minimum(np.minimum(self.sx[idx], self.sy[idx]), 1.0)
        return (np.sqrt(s1 * s1 + s2 * s2 + s3 * s3) - radius) * scale

    def field_and_gradient(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N,) body field and (N, 3) its gradient (analytic, from the active edge's two parts)."""
        n = len(points)
        t, s1, s2, s3 = self._local(points)
        norm = np.maximum(np.sqrt(s1 * s1 + s2 * s2 + s3 * s3), 1e-12)
        scale = np.minimum(np.minimum(self.sx, self.sy), 1.0)
        values = (norm - (self.ra + (self.rb - self.ra) * t)) * scale
        rows = np.arange(n)
        if len(self.edges) == 0:
            active = values.argmin(axis=1)
            parts, mix = active[:, None], np.ones((n, 1))
            f = values[rows, active]
        else:
            fa = values[:, self.edges[:, 0]]
            fb = values[:, self.edges[:, 1]]
            blended = smooth_min(fa, fb, self.edge_k)
            e = blended.argmin(axis=1)
            f = blended[rows, e]
            h = np.clip(0.5 + 0.5 * (fb[rows, e] - fa[rows, e]) / self.edge_k[e], 0.0, 1.0)
            parts, mix = self.edges[e], np.stack([h, 1.0 - h], axis=1)  # d smin / d(a, b) = (h, 1 - h)
        grad = np.zeros((n, 3))
        for j in range(parts.shape[1]):
            p = parts[:, j]
            clamped = (t[rows, p] <= 0.0) | (t[rows, p] >= 1.0)
            nr = norm[rows, p]
            g = (
                (s1[rows, p] / nr / self.sx[p])[:, None] * self.e1[p]
                + (s2[rows, p] / nr / self.sy[p])[:, None] * self.e2[p]
                + np.where(clamped, s3[rows, p] / nr, -(self.rb[p] - self.ra[p]) / self.length[p])[:, None]
                * self.axis[p]
            )
            grad += (mix[:, j] * scale[p])[:, None] * g
        return f, grad

    def combine(self, part_values: np.ndarray) -> np.ndarray:
        """The body field from (N, P) part values: min over edges of the smooth union with the parent."""
        if len(self.edges) == 0:
            return part_values.min(axis=1)
        fa = part_values[:, self.edges[:, 0]]
        fb = part_values[:, self.edges[:, 1]]
        return smooth_min(fa, fb, self.edge_k).min(axis=1)

    def field(self, points: np.ndarray) -> np.ndarray:
        """(N,) body field (metres, < 0 inside) at (N, 3) points."""
        return self.combine(self.part_fields(points))

    def labels(self, points: np.ndarray) -> np.ndarray:
        """(N,) int64 part index of each point: the part whose field is smallest there."""
        return self.part_fields(points).argmin(axis=1).astype(np.int64)

    def chart(self, points: np.ndarray, part: int) -> np.ndarray:
        """(N, 3) position of the points on part ``part``'s canonical capsule (the shared domain).

        The capsule has unit radius and length :data:`CANONICAL_LENGTH` along its third axis; the
        first two axes are the bone frame's e1 (anatomical left) and e2. A point's chart position is
        ``(u1, u2, u3 + L * t)`` with t its clamped axial parameter along the bone and u the unit
        direction of its offset from the bone in the (elliptically normalised) cross-section.
        """
        t, s1, s2, s3 = self._local(points, np.array([part]))
        s = np.concatenate([s1, s2, s3], axis=1)
        u = s / np.maximum(np.linalg.norm(s, axis=1, keepdims=True), 1e-12)
        return np.stack([u[:, 0], u[:, 1], u[:, 2] + CANONICAL_LENGTH * t[:, 0]], axis=1)

    def chart_extent(self, points: np.ndarray, part: int) -> np.ndarray:
        """(2, CHART_BINS) lowest and highest axial chart coordinate of ``points`` (the vertices of one
        class's part region) per angular bin around the bone: where the region ends on each side."""
        return chart_extent(self.chart(points, part))

    def normalised_chart(self, points: np.ndarray, part: int, extent: np.ndarray) -> np.ndarray:
        """(N, 3) chart positions with the axial coordinate rescaled, per angle, so that the part's
        region (``extent`` from :meth:`chart_extent`) spans exactly [0, CANONICAL_LENGTH].

        Which stretch of a bone is visible (not buried in the neighbouring parts) depends on the
        class's proportions; after this normalisation the region boundaries of every class coincide
        in the shared domain, so the class-to-class map is a bijection between part regions.
        """
        return normalise_chart(self.chart(points, part), extent)

    def adjacency(self) -> np.ndarray:
        """(P, P) bool: parts that are equal or parent/child."""
        adj = np.eye(self.n_parts, dtype=bool)
        adj[self.edges[:, 0], self.edges[:, 1]] = True
        adj[self.edges[:, 1], self.edges[:, 0]] = True
        return adj


CHART_BINS = 32
"""Angular bins of :func:`chart_extent`."""

MIN_EXTENT = 0.25
"""Smallest axial extent (chart units) a region is stretched from; guards stubby, mostly-cap parts."""


def _chart_angle(chart: np.ndarray) -> np.ndarray:
    return np.arctan2(chart[:, 1], chart[:, 0])


def chart_extent(chart: np.ndarray) -> np.ndarray:
    """(2, CHART_BINS) min and max of the axial coordinate (column 2) of (N, 3) chart points per bin
    of their angle around the axis (bins of 2 pi / CHART_BINS from -pi); empty bins are filled by
    periodic linear interpolation between their neighbours."""
    width = 2.0 * np.pi / CHART_BINS
    bins = np.clip(((_chart_angle(chart) + np.pi) / width).astype(np.int64), 0, CHART_BINS - 1)
    lo = np.full(CHART_BINS, np.inf)
    hi = np.full(CHART_BINS, -np.inf)
    np.minimum.at(lo, bins, chart[:, 2])
    np.maximum.at(hi, bins, chart[:, 2])
    filled = np.isfinite(lo)
    if not filled.any():
        raise ValueError("chart_extent needs at least one point")
    centres = -np.pi + width * (np.arange(CHART_BINS) + 0.5)
    for arr in (lo, hi):
        arr[~filled] = np.interp(centres[~filled], centres[filled], arr[filled], period=2 * np.pi)
    return np.stack([lo, hi])


def chart_profile(chart: np.ndarray) -> np.ndarray:
    """(CHART_BINS,) mean axial coordinate of (N, 3) chart points per angular bin (a closed curve
    around the axis, e.g. a part's boundary with its parent), periodic interpolation where empty."""
    width = 2.0 * np.pi / CHART_BINS
    bins = np.clip(((_chart_angle(chart) + np.pi) / width).astype(np.int64), 0, CHART_BINS - 1)
    total = np.bincount(bins, weights=chart[:, 2], minlength=CHART_BINS)
    count = np.bincount(bins, minlength=CHART_BINS)
    if not count.any():
        raise ValueError("chart_profile needs at least one point")
    centres = -np.pi + width * (np.arange(CHART_BINS) + 0.5)
    filled = count > 0
    out = np.zeros(CHART_BINS)
    out[filled] = total[filled] / count[filled]
    out[~filled] = np.interp(centres[~filled], centres[filled], out[filled], period=2 * np.pi)
    return out


def normalise_chart(chart: np.ndarray, extent: np.ndarray) -> np.ndarray:
    """(N, 3) chart points with the axial coordinate mapped affinely, per angle, from
    [extent[0](angle), extent[1](angle)] (interpolated periodically between bin centres) onto
    [0, CANONICAL_LENGTH]; the cross-section coordinates are kept."""
    width = 2.0 * np.pi / CHART_BINS
    centres = -np.pi + width * (np.arange(CHART_BINS) + 0.5)
    angle = _chart_angle(chart)
    lo = np.interp(angle, centres, extent[0], period=2 * np.pi)
    hi = np.interp(angle, centres, extent[1], period=2 * np.pi)
    z = CANONICAL_LENGTH * (chart[:, 2] - lo) / np.maximum(hi - lo, MIN_EXTENT)
    return np.stack([chart[:, 0], chart[:, 1], z], axis=1)


def smooth_min(a: np.ndarray, b: np.ndarray, k) -> np.ndarray:
    """Polynomial smooth minimum of width ``k`` (same units as a, b); equals min(a, b) where |a-b| >= k."""
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b * (1.0 - h) + a * h - k * h * (1.0 - h)


# --- posing ------------------------------------------------------------------------------------

JOINT_LIMITS: dict[str, tuple[tuple[str, float, float], ...]] = {
    # (rotation axis in the common frame, min, max) in degrees, for the LEFT part; the right part
    # uses the mirrored rotation (angles about y and z negated). A positive x rotation moves a
    # downward-pointing bone backwards (-z).
    "b_chest": (("x", -10, 20), ("y", -25, 25), ("z", -10, 10)),
    "b_neck": (("x", -15, 20), ("y", -30, 30)),
    "b_head": (("x", -15, 15), ("z", -10, 10)),
    "b_upperarm": (("x", -45, 35), ("z", 0, 35)),
    "b_forearm": (("x", -80, 0),),
    "b_hand": (("x", -20, 20),),
    "b_thigh": (("x", -40, 15), ("z", 0, 12)),
    "b_shin": (("x", 0, 70),),
    "b_foot": (("x", -15, 20),),
    "b_tail": (("x", -30, 30), ("y", -30, 30)),
    "q_neck": (("x", -25, 25), ("y", -20, 20)),
    "q_head": (("x", -20, 20), ("y", -15, 15)),
    "q_fupper": (("x", -30, 30),),
    "q_flower": (("x", 0, 60),),
    "q_ffoot": (("x", -20, 20),),
    "q_hupper": (("x", -30, 30),),
    "q_hlower": (("x", -50, 0),),
    "q_hfoot": (("x", -20, 20),),
    "q_tail": (("x", -40, 30), ("y", -40, 40)),
}


def _rotation(axis: str, degrees: float) -> np.ndarray:
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    i = "xyz".index(axis)
    j, k = [m for m in range(3) if m != i]
    R = np.eye(3)
    R[j, j], R[j, k], R[k, j], R[k, k] = c, -s, s, c
    return R


def draw_pose(body: Body, seed: int, key: str, pose: int) -> np.ndarray:
    """(P, 3, 3) local joint rotations (column-vector convention) of pose ``pose`` (0 = rest = identity).

    Angles are uniform within :data:`JOINT_LIMITS`, drawn from a stream keyed by (seed, key, pose),
    in part order, so a pose depends only on its own key.
    """
    rotations = np.repeat(np.eye(3)[None], body.n_parts, axis=0)
    if pose == 0:
        return rotations
    rng = rng_for(seed, "synthetic-pose", key, pose)
    for p, name in enumerate(body.names):  # loop over ~25 parts, not vertices
        side = -1.0 if name.endswith("_r") else 1.0
        base = name[:-2] if name.endswith(("_l", "_r")) else name
        R = np.eye(3)
        for axis, lo, hi in JOINT_LIMITS.get(base, ()):
            angle = rng.uniform(lo, hi)
            R = R @ _rotation(axis, angle if axis == "x" else side * angle)
        rotations[p] = R
    return rotations


def skinning_weights(body: Body, rest_vertices: np.ndarray, labels: np.ndarray, sigma: float) -> np.ndarray:
    """(N, P) linear-blend-skinning weights: a softmax of -field/sigma over each vertex's part and its
    skeleton neighbours (so a hand never follows a thigh it happens to be near). ``sigma`` in metres."""
    values = body.part_fields(rest_vertices)
    allowed = body.adjacency()[labels]
    logits = np.where(allowed, -(values - values.min(axis=1, keepdims=True)) / sigma, -np.inf)
    w = np.exp(logits - logits.max(axis=1, keepdims=True))
    w[w < 1e-4] = 0.0
    return w / w.sum(axis=1, keepdims=True)


def pose_vertices(body: Body, rest_vertices: np.ndarray, weights: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    """(N, 3) posed positions: each part rotates about its joint ``a`` after its parent moved (forward
    kinematics), vertices follow by linear blend skinning with (N, P) ``weights``; then the body is
    moved vertically so that its lowest point is at y = 0 (standing on the ground)."""
    P = body.n_parts
    A = np.zeros((P, 3, 3))
    t = np.zeros((P, 3))
    for p in range(P):  # parents precede children
        R = rotations[p]
        local_t = body.a[p] - R @ body.a[p]
        q = body.parents[p]
        if q < 0:
            A[p], t[p] = R, local_t
        else:
            A[p], t[p] = A[q] @ R, A[q] @ local_t + t[q]
    blended_A = np.einsum("np,pij->nij", weights, A)
    out = np.einsum("nij,nj->ni", blended_A, rest_vertices) + weights @ t
    out[:, 1] -= out[:, 1].min()
    return out


_SEGMENT_TO_REGION = {
    "b_pelvis": "b_torso",
    "b_chest": "b_torso",
    "b_neck": "b_head",
    "b_head": "b_head",
    "b_upperarm": "b_arm",
    "b_forearm": "b_arm",
    "b_hand": "b_arm",
    "b_thigh": "b_leg",
    "b_shin": "b_leg",
    "b_foot": "b_leg",
    "b_tail": "b_tail",
    "b_horn": "b_horn",
    "q_barrel": "q_torso",
    "q_neck": "q_head",
    "q_head": "q_head",
    "q_fupper": "q_frontleg",
    "q_flower": "q_frontleg",
    "q_ffoot": "q_frontleg",
    "q_hupper": "q_hindleg",
    "q_hlower": "q_hindleg",
    "q_hfoot": "q_hindleg",
    "q_tail": "q_tail",
    "q_horn": "q_horn",
}


def semantic_part(name: str) -> str:
    """The body region a part (bone segment) belongs to: torso, head (with neck), a whole limb
    (``b_arm_l``, ``q_frontleg_r``...), tail or a horn, keeping the side suffix."""
    side = name[-2:] if name.endswith(("_l", "_r")) else ""
    base = name[: len(name) - len(side)]
    return _SEGMENT_TO_REGION[base] + side
