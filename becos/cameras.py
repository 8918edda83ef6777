"""Virtual scanner cameras: pinhole cameras on a sphere around a shape normalised to a unit box.

Frame and units
---------------
A shape is first normalised by :func:`normalise_to_unit_box`: centred on the centre of its
axis-aligned bounding box and divided by the box's largest side, so it fits in
``[-0.5, 0.5]^3`` with one side exactly 1. Cameras live in that normalised frame, on the sphere of
radius ``distance`` (default 1, i.e. one box side from the centre) around the origin, and look at
the origin. They are pinhole cameras with a square 90° field of view (horizontal = vertical, like
the reference's square 5000×5000 image with a 90° horizontal FOV).

Spherical coordinates
---------------------
``up_axis`` (``'x'``, ``'y'`` (default) or ``'z'``) is the shape's up direction ``u``. Two further
axes ``(e1, e2)`` complete it cyclically (y-up: ``e1 = z``, ``e2 = x``; z-up: ``x, y``; x-up:
``y, z``). A camera at azimuth ``θ`` (about ``u``, from ``e1`` towards ``e2``) and elevation ``φ``
(from the equator towards ``+u``) sits at::

    position = distance · (cos φ · (cos θ · e1 + sin θ · e2) + sin φ · u)

and its up vector is ``∂position/∂φ`` normalised, ``-sin φ · (cos θ · e1 + sin θ · e2) + cos φ · u``:
exactly orthogonal to the viewing direction and of unit length for every ``θ, φ``, so it never
degenerates, not even for a camera on the up axis (``φ = ±π/2``), where it becomes the azimuth
direction.

How cameras are drawn
---------------------
*First camera*: azimuth uniform on ``[0, 2π)``; elevation in the band
``[ELEVATION_MIN, ELEVATION_MAX] = [-π/12, π/3]`` (−15° to +60°), with density ∝ ``cos φ`` (the
camera *direction* is uniform in area over that zone of the sphere, so no direction of the band is
favoured). Why this band: a scanner (a person with a depth camera, a turntable rig) looks at an
object standing on the floor from around it, from slightly below its centre up to well above it,
but never from under the floor. With the shape's box centred at the origin the floor lies at
``-h/2`` (h = height / largest side ≤ 1), i.e. at height ≥ -0.5; TOSCA's humans have h ≈ 1 and
its four-legged shapes h ≈ 0.6–0.8, so the floor is at ≈ -0.3 to -0.5 and a camera at distance 1
is above it while ``sin φ > -0.3`` (φ > -17°). The lower bound −15° keeps every camera of either
shape above the floor; the upper bound +60° keeps views that still show the sides of the shape
(a top-down view sees only a back or the top of a head, which no real scan of a standing body is).

*Pairs* (P2P: one camera per shape, in a shared frame): the pair ``(θ1, φ1), (θ2, φ2)`` is drawn
uniformly (directions area-uniform as above, both elevations inside the band) among the pairs
that satisfy the regime's bounds on the azimuth difference (wrapped to ``[0, π]``) and on the
elevation difference — by rejection from independent draws. The two cameras are therefore
exchangeable (neither shape is favoured), each is marginally close to the first-camera
distribution, and the bounds hold exactly:

========  ==========================  ============================
regime    |θ1 - θ2| (wrapped) ≤        |φ1 - φ2| ≤
========  ==========================  ============================
high      π/4                          π/8
medium    π/2                          π/4
low       π (independent)              band width (independent)
========  ==========================  ============================

In practice the pair is drawn as: ``θ1`` uniform, ``θ2 = θ1 + U(-Δθ, Δθ)`` (exactly the uniform
distribution on the allowed set, since azimuth wraps), and ``(φ1, φ2)`` by rejection from
independent band draws until ``|φ1 - φ2| ≤ Δφ``. Every draw comes from the generator passed in;
callers derive it from the pair's id (``becos.seeding.rng_for(seed, pair_id, "cameras", k)``), never
from a shared stream.

Reference-like regimes (``reference-high``, ``reference-medium``)
-----------------------------------------------------------------
The reference generator's ``cam_generator`` (reference-facts §7.7), reproduced formula for formula
with our generator. Per pair, 7 uniform draws in this order: ``a`` (2,), ``b`` (2,), ``c``, coin
``s``, ``d``; with ``r = π/8`` (high) or ``π/4`` (medium)::

    α_i = clip(a_i · 2r + c · 2(π − r), 0, 2π)
    φ_i = clip(b_i · r − r/2 + (±1 by s < 0.5) · d · (π − r)/2, −π/2, π/2)
    point_i = (cos φ_i sin α_i, cos φ_i cos α_i, sin φ_i)

in the reference's frame, where shapes are y-up: its elevation φ is measured towards **z** (a
horizontal axis), so its "azimuth" α turns about z and the camera circle passes over the top and
under the bottom of the shape. α_i share the offset ``c`` and differ by ``(a_1 − a_2) · 2r``
(triangular on ``[−2r, 2r]``); φ_i differ by ``(b_1 − b_2) · r`` (triangular on ``[−r, r]``). Each
camera alone covers the whole sphere (uniform in α and nearly so in φ, so denser near ±z).
Measured pair angles (2000 draws, facts §7.7): high median 13.3°, max 47°; medium median 28°, max 92°.

The reference's axes ``(x, y, z)`` map to ours as ``(e2, u, e1)`` (y-up: the identity), the camera
sits at ``distance · point`` and its up vector is ``u`` (the reference's +y) made orthogonal to the
viewing direction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ELEVATION_MIN = -np.pi / 12
"""Lowest camera elevation (radians, from the equator towards +up): −15°."""
ELEVATION_MAX = np.pi / 3
"""Highest camera elevation (radians): +60°."""

REGIMES: dict[str, tuple[float, float]] = {
    "high": (np.pi / 4, np.pi / 8),
    "medium": (np.pi / 2, np.pi / 4),
    "low": (np.pi, np.inf),
}
"""regime -> (max azimuth difference, max elevation difference), radians."""
REFERENCE_REGIMES: dict[str, float] = {
    "reference-high": np.pi / 8,
    "reference-medium": np.pi / 4,
}
"""Reference-like regime -> the reference's ``r`` (radians), see the module doc."""
CAMERA_REGIMES: tuple[str, ...] = (*REGIMES, *REFERENCE_REGIMES)
"""Every accepted ``cam_pos_regime`` (becos/data/schema.yaml lists the same)."""

_AXES = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera.

    Attributes:
        position: (3,) float64 eye position, in the frame of the mesh it looks at.
        target: (3,) float64 point it looks at (the origin for drawn cameras).
        up: (3,) float64 unit up vector, orthogonal to the viewing direction.
        fov_deg: full field of view in degrees, the same horizontally and vertically (square image).
    """

    position: np.ndarray
    target: np.ndarray
    up: np.ndarray
    fov_deg: float = 90.0

    def __post_init__(self):
        for name in ("position", "target", "up"):
            value = np.asarray(getattr(self, name), dtype=np.float64).reshape(3).copy()
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def forward(self) -> np.ndarray:
        """(3,) unit viewing direction, from the eye towards the target."""
        d = self.target - self.position
        return d / np.linalg.norm(d)

    def basis(self) -> np.ndarray:
        """(3, 3) rows ``right, up, forward``: an orthonormal camera basis (up re-orthogonalised).

        ``right = forward × up`` is the viewer's right hand, so the triple is left-handed (det -1),
        like image coordinates (column to the right, row upwards) plus depth."""
        f = self.forward
        u = self.up - (self.up @ f) * f
        u /= np.linalg.norm(u)
        r = np.cross(f, u)
        return np.stack([r, u, f])

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) camera coordinates ``(right, up, forward)`` of (N, 3) world points (eye at 0)."""
        return (np.asarray(points, dtype=np.float64) - self.position) @ self.basis().T

    def in_frustum(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: the point is in front of the eye and inside the square field of view."""
        c = self.to_camera(points)
        half = np.tan(np.radians(self.fov_deg) / 2.0)
        depth = c[:, 2]
        return (depth > 0) & (np.abs(c[:, 0]) <= half * depth) & (np.abs(c[:, 1]) <= half * depth)

    def transformed(
        self, rotation: np.ndarray | None = None, translation: np.ndarray | None = None, scale: float = 1.0
    ) -> Camera:
        """The same camera in another frame, where a point ``p`` becomes ``scale · p @ R.T + t``."""
        rotation = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
        translation = np.zeros(3) if translation is None else np.asarray(translation, dtype=np.float64)
        return Camera(
            scale * self.position @ rotation.T + translation,
            scale * self.target @ rotation.T + translation,
            self.up @ rotation.T,
            self.fov_deg,
        )


def axis_frame(up_axis: str = "y") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(e1, e2, u)``: unit vectors of azimuth 0, of azimuth π/2 and of up for ``up_axis``."""
    if up_axis not in _AXES:
        raise ValueError(f"up_axis must be one of 'x', 'y', 'z', got {up_axis!r}")
    k = _AXES[up_axis]
    eye = np.eye(3)
    # cyclic: y-up -> (z, x); z-up -> (x, y); x-up -> (y, z)
    return eye[(k + 1) % 3], eye[(k + 2) % 3], eye[k]


def camera_from_angles(
    azimuth: float, elevation: float, up_axis: str = "y", distance: float = 1.0, fov_deg: float = 90.0
) -> Camera:
    """The camera at ``azimuth``, ``elevation`` (radians) looking at the origin (see module doc)."""
    e1, e2, u = axis_frame(up_axis)
    horizontal = np.cos(azimuth) * e1 + np.sin(azimuth) * e2
    position = distance * (np.cos(elevation) * horizontal + np.sin(elevation) * u)
    up = -np.sin(elevation) * horizontal + np.cos(elevation) * u
    return Camera(position, np.zeros(3), up, fov_deg)


def camera_angles(camera: Camera, up_axis: str = "y") -> tuple[float, float]:
    """``(azimuth in [0, 2π), elevation in [-π/2, π/2])`` of a camera's position about the origin."""
    e1, e2, u = axis_frame(up_axis)
    p = camera.position / np.linalg.norm(camera.position)
    elevation = float(np.arcsin(np.clip(p @ u, -1.0, 1.0)))
    azimuth = float(np.arctan2(p @ e2, p @ e1) % (2 * np.pi))
    return azimuth, elevation


def _band_elevations(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n,) elevations in [ELEVATION_MIN, ELEVATION_MAX] with density ∝ cos φ (area-uniform)."""
    lo, hi = np.sin(ELEVATION_MIN), np.sin(ELEVATION_MAX)
    return np.arcsin(rng.uniform(lo, hi, size=n))


def draw_camera(rng: np.random.Generator, up_axis: str = "y", distance: float = 1.0) -> Camera:
    """One camera (e.g. for a partial-to-full pair): uniform azimuth, area-uniform elevation in the band."""
    axis_frame(up_axis)
    azimuth = rng.uniform(0.0, 2 * np.pi)
    elevation = _band_elevations(rng, 1)[0]
    return camera_from_angles(azimuth, elevation, up_axis, distance)


def draw_camera_pair(
    rng: np.random.Generator, regime: str = "high", up_axis: str = "y", distance: float = 1.0
) -> tuple[Camera, Camera]:
    """Two cameras (one per shape of a partial-to-partial pair, in a shared frame) for ``regime``.

    See the module doc for the distribution. Both cameras look at the origin from ``distance``.
    """
    if regime in REFERENCE_REGIMES:
        return tuple(
            _camera_at(p, up_axis, distance) for p in reference_directions(rng, REFERENCE_REGIMES[regime], up_axis)
        )
    if regime not in REGIMES:
        raise ValueError(f"regime must be one of {list(CAMERA_REGIMES)}, got {regime!r}")
    axis_frame(up_axis)
    max_azimuth, max_elevation = REGIMES[regime]
    azimuth1 = rng.uniform(0.0, 2 * np.pi)
    azimuth2 = (azimuth1 + rng.uniform(-max_azimuth, max_azimuth)) % (2 * np.pi)
    while True:  # acceptance ≥ ~0.5 per pair for 'high'; 16 candidates per round
        phi = _band_elevations(rng, 32).reshape(16, 2)
        ok = np.flatnonzero(np.abs(phi[:, 0] - phi[:, 1]) <= max_elevation)
        if len(ok):
            elevation1, elevation2 = phi[ok[0]]
            break
    return (
        camera_from_angles(azimuth1, elevation1, up_axis, distance),
        camera_from_angles(azimuth2, elevation2, up_axis, distance),
    )


def reference_directions(rng: np.random.Generator, r: float, up_axis: str = "y") -> np.ndarray:
    """(2, 3) unit directions (origin -> camera) of one reference ``cam_generator`` pair for ``r``.

    Seven uniform draws from ``rng`` (module doc); rows are the x and y cameras, in our frame for
    ``up_axis`` (y-up: the reference's own coordinates, elevation towards +z).
    """
    e1, e2, u = axis_frame(up_axis)
    a, b = rng.random(2), rng.random(2)
    c, coin, d = rng.random(3)
    alpha = np.clip(a * 2 * r + c * 2 * (np.pi - r), 0.0, 2 * np.pi)
    sign = 1.0 if coin < 0.5 else -1.0
    phi = np.clip(b * r - r / 2 + sign * d * (np.pi - r) / 2, -np.pi / 2, np.pi / 2)
    point = np.stack([np.cos(phi) * np.sin(alpha), np.cos(phi) * np.cos(alpha), np.sin(phi)], axis=1)
    point /= np.linalg.norm(point, axis=1, keepdims=True)
    return point @ np.stack([e2, u, e1])


def _camera_at(direction: np.ndarray, up_axis: str, distance: float, fov_deg: float = 90.0) -> Camera:
    """The camera at ``distance · direction`` looking at the origin, up = ``u`` made orthogonal to the
    view (the reference's up +y); for a view along ``±u`` itself, up = ``e1``."""
    e1, _, u = axis_frame(up_axis)
    direction = np.asarray(direction, dtype=np.float64)
    up = u - (u @ direction) * direction
    norm = np.linalg.norm(up)
    up = up / norm if norm > 1e-9 else e1
    return Camera(distance * direction, np.zeros(3), up, fov_deg)


def normalise_to_unit_box(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Centre (N, 3) ``vertices`` on their bounding-box centre and scale the box's largest side to 1.

    Returns:
        normalised: (N, 3) float64 ``(vertices - centre) / scale``.
        centre: (3,) bounding-box centre, in the input's units.
        scale: the box's largest side, in the input's units (``vertices = normalised * scale + centre``).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    centre = (lo + hi) / 2.0
    scale = float((hi - lo).max())
    if not scale > 0:
        raise ValueError("cannot normalise a shape whose bounding box has no extent")
    return (vertices - centre) / scale, centre, scale
