"""Virtual scanner cameras: pinhole cameras on a sphere around a shape normalised to a unit box.

Frame: :func:`normalise_to_unit_box` centres a shape on its bounding box and divides by the box's
largest side; cameras sit on the sphere of radius ``distance`` (default 1) around the origin, look at
it, and have a square 90° field of view. ``up_axis`` ('x', 'y' (default), 'z') is the shape's up.
Regimes ``high``/``medium``/``low`` bound the azimuth and elevation differences of a P2P pair's two
cameras (elevations −15° to +60°); ``reference-high``/``-medium`` reproduce the reference's
``cam_generator``. Every draw comes from the generator passed in. Formulas, bounds and why:
docs/design/partiality.md.
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
