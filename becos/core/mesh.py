"""Triangle meshes: the in-memory type, reading mesh files, a cache of parsed arrays, and the
repairs applied to a COPY of a mesh before remeshing.

Vertex order is always the file's order (ground truth is indexed by it): files are read with trimesh
``process=False, maintain_order=True`` and never merged, re-ordered or repaired in place. Unreadable
input is an :class:`~becos.errors.InputFileError` from :func:`read_mesh` (file, problem, fix);
:func:`surface_for_remeshing` drops repeated-index and duplicate faces, unreferenced vertices and small
extra components on a copy that remembers each vertex's and face's input row. Each fault and its
treatment: docs/design/data.md and docs/faults.md.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from becos.atomic import save_npz as atomic_save_npz
from becos.core.formats import check_file, not_a_mesh_file
from becos.core.formats.off import off_data_lines, read_plain_off
from becos.core.formats.problems import TRUNCATED_FIX
from becos.errors import InputFileError

MESH_SUFFIXES = (".off", ".ply", ".obj")

ZERO_AREA_RTOL = 1e-12
"""A face is degenerate (zero area) when ``area <= ZERO_AREA_RTOL × (its longest edge)²`` (scale-free;
the smallest ratio on the 76 TOSCA meshes is 1.6e-4)."""

MAX_DROPPED_AREA_SHARE = 0.05
""":func:`surface_for_remeshing` keeps the largest connected component; extra components holding more
than this share of the total area are an error rather than specks to drop."""


@dataclass(frozen=True, eq=False)
class TriMesh:
    """A triangle mesh.

    Attributes:
        vertices: (V, 3) float64 positions, in the units and frame of whoever built the mesh.
        faces: (F, 3) int64 vertex indices, counter-clockwise seen from outside where oriented.
    """

    vertices: np.ndarray
    faces: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "vertices", np.ascontiguousarray(self.vertices, dtype=np.float64))
        object.__setattr__(self, "faces", np.ascontiguousarray(self.faces, dtype=np.int64))

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_faces(self) -> int:
        return len(self.faces)

    def with_vertices(self, vertices: np.ndarray) -> TriMesh:
        """The same connectivity with new (V, 3) positions."""
        return TriMesh(vertices, self.faces)


def check_mesh_arrays(path: str | Path, vertices: np.ndarray, faces: np.ndarray) -> None:
    """Raise :class:`InputFileError` unless the arrays form a usable triangle mesh."""
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) == 0:
        raise InputFileError(
            path,
            f"no vertices could be read (vertex array shape {vertices.shape})",
            "check that the file is a complete OFF/PLY/OBJ mesh (re-download or re-extract it)",
        )
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise InputFileError(
            path,
            f"no triangles could be read (face array shape {faces.shape})",
            "check that the file is a complete triangle mesh (re-download or re-extract it)",
        )
    if not np.isfinite(vertices).all():
        bad = int((~np.isfinite(vertices)).any(axis=1).sum())
        raise InputFileError(
            path,
            f"{bad} vertices have NaN or infinite coordinates",
            "re-export or re-download the mesh; becos cannot guess the positions",
        )
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InputFileError(
            path,
            f"face indices span [{faces.min()}, {faces.max()}] but the file has {len(vertices)} vertices",
            "the file is truncated or corrupt: re-download it",
        )
    flat = flatness(vertices)
    if flat <= FLAT_RTOL:
        raise InputFileError(
            path,
            f"all its {len(vertices)} vertices lie in one plane (thickness {flat:.2g} of its "
            f"largest extent): a flattened or 2-D mesh, and becos matches 3-D surfaces",
            "use the dataset's original 3-D mesh (re-download or re-extract it)",
        )


def read_mesh(path: str | Path) -> TriMesh:
    """Read an OFF, PLY or OBJ triangle mesh keeping the file's vertex and face order.

    Raises:
        InputFileError: missing file, unknown type, unreadable or inconsistent content.
    """
    path = Path(path)
    odd = not_a_mesh_file(path)  # a folder, a named pipe, a link to /dev/zero: named, never opened
    if odd is not None:
        raise InputFileError(path, *odd)
    if not path.is_file():
        raise InputFileError(
            path,
            "mesh file not found",
            "check the dataset folder in the config (data_dir) and that the download is complete",
        )
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise InputFileError(path, f"unknown mesh type '{path.suffix}'", f"convert it to one of {MESH_SUFFIXES}")
    if path.suffix.lower() == ".off":
        plain = read_plain_off(path.read_bytes())  # without trimesh (~1 s of a remesh job) and its header check
        if plain is not None:
            check_mesh_arrays(path, *plain)
            return TriMesh(*plain)
    import trimesh

    try:
        loaded = trimesh.load(path, process=False, maintain_order=True, force="mesh", skip_materials=True)
        vertices = np.asarray(loaded.vertices, dtype=np.float64)
        faces = np.asarray(loaded.faces, dtype=np.int64)
    except Exception as exc:  # trimesh raises many types on corrupt input
        _raise_precise(path, exc)
        raise InputFileError(
            path,
            f"could not be parsed as a mesh ({type(exc).__name__}: {exc})",
            "the file is truncated or corrupt: re-download or re-extract it",
        ) from exc
    check_mesh_arrays(path, vertices, faces)
    if path.suffix.lower() == ".off":
        _check_off_header(path, len(vertices), len(faces))
    return TriMesh(vertices, faces)


def _raise_precise(path: Path, exc: Exception) -> None:
    """When the cheap check of :func:`becos.core.formats.check_file` names a line at fault that is not a
    cut file (a vertex line with 2 values, a quad face), raise its error instead of the parser's."""
    try:
        check_file(path)
    except InputFileError as precise:
        if precise.fix != TRUNCATED_FIX:
            raise precise from exc


def _check_off_header(path: Path, n_vertices: int, n_faces: int) -> None:
    """A truncated OFF can still parse (face lines read as vertices): compare with the header's counts
    (:func:`becos.core.formats.off.off_data_lines`), and the data lines with the counts."""
    try:
        header_vertices, header_faces, have = off_data_lines(path.read_bytes())
    except ValueError:
        raise InputFileError(
            path, "the OFF header has no vertex and face counts", "the file is corrupt: re-download or re-extract it"
        ) from None
    if (header_vertices, header_faces) != (n_vertices, n_faces):
        _raise_precise(path, None)  # e.g. a quad that trimesh split into two triangles
        raise InputFileError(
            path,
            f"the OFF header announces {header_vertices} vertices and {header_faces} faces "
            f"but {n_vertices} and {n_faces} were read (truncated or corrupt file)",
            "re-download or re-extract the file",
        )
    if have > n_vertices + n_faces:  # trimesh stops at the announced counts: the rest would be dropped silently
        raise InputFileError(
            path,
            f"the OFF header announces {n_vertices} vertices and {n_faces} faces but "
            f"{have} data lines follow, {have - n_vertices - n_faces} more than announced (a "
            f"reader ignores them; after the vertex block there are {have - n_vertices} lines)",
            f"if the file is otherwise intact, correct the header's counts (e.g. '{n_vertices} "
            f"{have - n_vertices} 0' when the extra lines are faces); else re-download or "
            f"re-extract it",
        )


class MeshCache:
    """Parse each mesh file once: arrays are kept in ``cache_dir`` as .npz, keyed by path, size, mtime,
    ctime and inode (an edit that restores the modification time is parsed again).

    Parsing a 50k-vertex OFF with trimesh takes ~0.4 s; reading the cached arrays a few ms.
    ``cache_dir=None`` keeps only an in-process cache.
    """

    def __init__(self, cache_dir: str | Path | None = None, max_in_memory: int = 32):
        self.cache_dir = Path(cache_dir) if cache_dir is not None else None
        self.max_in_memory = max_in_memory
        self._memory: OrderedDict[str, TriMesh] = OrderedDict()

    def _key(self, path: Path) -> str:
        stat = path.stat()
        text = f"{path.resolve()}|{stat.st_size}|{stat.st_mtime_ns}|{stat.st_ctime_ns}|{stat.st_ino}"
        return hashlib.sha1(text.encode()).hexdigest()[:20]

    def load(self, path: str | Path) -> TriMesh:
        """The mesh in ``path`` (see :func:`read_mesh`), from the cache when the file is unchanged."""
        path = Path(path)
        if not path.is_file():
            return read_mesh(path)  # raises the explanatory error
        key = self._key(path)
        if key in self._memory:
            self._memory.move_to_end(key)
            return self._memory[key]
        mesh = None
        if self.cache_dir is not None:
            cached = self.cache_dir / f"{path.stem}-{key}.npz"
            if cached.is_file():
                with np.load(cached) as data:
                    mesh = TriMesh(data["vertices"], data["faces"])
            else:
                mesh = read_mesh(path)
                atomic_save_npz(cached, vertices=mesh.vertices, faces=mesh.faces)
        else:
            mesh = read_mesh(path)
        self._memory[key] = mesh
        while len(self._memory) > self.max_in_memory:  # a long job must not hold every mesh it met
            self._memory.popitem(last=False)
        return mesh


# ----------------------------------------------------------------------------------------------
# faults of a mesh's connectivity, and the repaired copy used for remeshing


def vertex_set_keys(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """(F,) keys, equal exactly for faces with the same vertex set (any order / winding) and sortable:
    int64 below 2**21 vertices, else a structured (a, b, c) array."""
    s = np.sort(np.asarray(faces, dtype=np.int64), axis=1)
    n = max(int(n_vertices), 1)
    if n < 2**21:  # three 21-bit fields fit in an int64
        return (s[:, 0] * n + s[:, 1]) * n + s[:, 2]
    return np.ascontiguousarray(s).view([("a", np.int64), ("b", np.int64), ("c", np.int64)]).ravel()


def repeated_index_faces(faces: np.ndarray) -> np.ndarray:
    """(F,) bool: the face names one vertex twice (``[a, a, b]``)."""
    f = np.asarray(faces)
    return (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 0] == f[:, 2])


def zero_area_triangles(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(...,) bool: triangle (a, b, c) has ``area <= ZERO_AREA_RTOL × longest edge²`` (collinear or
    coincident corners); corners (..., 3), broadcast."""
    doubled_area = np.linalg.norm(np.cross(b - a, c - a), axis=-1)
    longest = np.maximum(np.maximum(((b - a) ** 2).sum(-1), ((c - b) ** 2).sum(-1)), ((a - c) ** 2).sum(-1))
    return 0.5 * doubled_area <= ZERO_AREA_RTOL * longest


def zero_area_faces(mesh: TriMesh) -> np.ndarray:
    """(F,) bool: :func:`zero_area_triangles` of every face (faces with a repeated index included: their
    area is 0)."""
    tri = mesh.vertices[mesh.faces]
    return zero_area_triangles(tri[:, 0], tri[:, 1], tri[:, 2])


def degenerate_faces(mesh: TriMesh) -> np.ndarray:
    """(F,) bool: a repeated vertex index or zero area (see :data:`ZERO_AREA_RTOL`)."""
    return repeated_index_faces(mesh.faces) | zero_area_faces(mesh)


def duplicate_faces(faces: np.ndarray, n_vertices: int, among: np.ndarray | None = None) -> np.ndarray:
    """(F,) int64: for a face with the same vertex set as an EARLIER row (any winding), that row's
    index; -1 for first occurrences. ``among`` (F,) bool restricts the comparison to those rows
    (others get -1)."""
    faces = np.asarray(faces, dtype=np.int64)
    rows = np.arange(len(faces)) if among is None else np.flatnonzero(among)
    out = np.full(len(faces), -1, dtype=np.int64)
    if len(rows) == 0:
        return out
    keys = vertex_set_keys(faces[rows], n_vertices)
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    first_row = rows[first][inverse.ravel()]
    dup = first_row != rows
    out[rows[dup]] = first_row[dup]
    return out


def surface_faces(mesh: TriMesh) -> np.ndarray:
    """(F,) bool: faces that may carry surface points: not degenerate and not a duplicate of an
    earlier row. All True for a clean mesh."""
    usable = ~degenerate_faces(mesh)
    if usable.any():
        usable &= duplicate_faces(mesh.faces, mesh.n_vertices, among=usable) < 0
    return usable


def _unique_pairs(pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(pairs, axis=0, return_counts=True)`` for (N, 2) non-negative int64 pairs, through
    one int64 key per pair (a sort of scalars: ~10x faster than the row-wise unique)."""
    n = int(pairs.max()) + 1 if len(pairs) else 1
    keys, counts = np.unique(pairs[:, 0] * n + pairs[:, 1], return_counts=True)
    return np.stack([keys // n, keys % n], axis=1), counts


def undirected_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(E, 2) sorted unique undirected edges and (E,) how many faces use each."""
    e = np.sort(np.asarray(faces, dtype=np.int64)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    return _unique_pairs(e)


def edge_neighbours(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Across each edge of each face: the face on the other side and its corner off the edge.

    Edge k of face f joins its corners k and k+1 (mod 3). Returns (F, 3) int64 ``neighbour`` (the other
    face using that edge) and (F, 3) int64 ``far`` (that face's corner not on the edge); both -1 where
    the edge is a boundary or non-manifold edge (used by one face, or by more than two)."""
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return np.zeros((0, 3), dtype=np.int64), np.zeros((0, 3), dtype=np.int64)
    a, b, c = f.ravel(), f[:, [1, 2, 0]].ravel(), f[:, [2, 0, 1]].ravel()  # half-edge (a, b), c across
    n = int(f.max()) + 1
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    if n <= 1 << 16 and f.min() >= 0:
        # lexicographic by two stable passes on 16-bit keys, which numpy sorts by radix: ~3x one argsort
        by_hi = np.argsort(hi.astype(np.uint16), kind="stable")
        order = by_hi[np.argsort(lo.astype(np.uint16)[by_hi], kind="stable")]
    else:
        order = np.argsort(lo * n + hi)
    key = (lo * n + hi)[order]
    same = key[1:] == key[:-1]
    pair = same.copy()  # sorted entries i, i+1 are an edge's only two half-edges
    pair[1:] &= ~same[:-1]
    pair[:-1] &= ~same[1:]
    i = np.flatnonzero(pair)
    first, second = order[i], order[i + 1]
    neighbour, far = np.full(len(a), -1, dtype=np.int64), np.full(len(a), -1, dtype=np.int64)
    neighbour[first], neighbour[second] = second // 3, first // 3
    far[first], far[second] = c[second], c[first]
    return neighbour.reshape(-1, 3), far.reshape(-1, 3)


def edge_neighbours_by_part(
    faces: np.ndarray, face_offsets: np.ndarray, vertex_offsets: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`edge_neighbours` of meshes stacked into one array, computed mesh by mesh: the same result
    when no face of a part uses a vertex outside the part, and faster than one sort of every half-edge
    of the stack (1.5x on TOSCA store blocks: a part's keys are small and fit 16 bits).

    Args:
        faces: (F, 3) int64 faces numbered in the stack's vertices; part i's faces are rows
            ``face_offsets[i]:face_offsets[i + 1]`` and use vertices ``vertex_offsets[i]:vertex_offsets[i + 1]``.
        face_offsets, vertex_offsets: (n + 1,) int64 offsets of the n parts.
    """
    f = np.asarray(faces, dtype=np.int64)
    neighbour, far = np.full(f.shape, -1, dtype=np.int64), np.full(f.shape, -1, dtype=np.int64)
    for first, last, vertex_start in zip(face_offsets[:-1], face_offsets[1:], vertex_offsets[:-1], strict=True):
        if last > first:
            part_neighbour, part_far = edge_neighbours(f[first:last] - vertex_start)
            neighbour[first:last] = np.where(part_neighbour >= 0, part_neighbour + first, -1)
            far[first:last] = np.where(part_far >= 0, part_far + vertex_start, -1)
    return neighbour, far


def misoriented_edge_count(faces: np.ndarray) -> int:
    """Directed edges used by two faces (two neighbours wound against each other); 0 when consistent."""
    directed = np.asarray(faces, dtype=np.int64)[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    _, counts = _unique_pairs(directed)
    return int((counts > 1).sum())


def face_components(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, int]:
    """(F,) int64 vertex-connected component of each face, numbered 0..k-1, and k."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    f = np.asarray(faces, dtype=np.int64)
    e = f[:, [0, 1, 1, 2]].reshape(-1, 2)
    graph = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_vertices, n_vertices))
    _, labels = connected_components(graph, directed=False)
    ids, face_label = np.unique(labels[f[:, 0]], return_inverse=True)
    return face_label.ravel().astype(np.int64), len(ids)


def non_manifold_vertices(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """(K,) int64 vertices whose faces form more than one fan (they touch only at the vertex, a
    "bow-tie"): the link of each vertex (the edges opposite it) is split into connected parts."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return np.zeros(0, dtype=np.int64)
    # spokes (v, w): vertex v seen along its edge to w; each face joins, around each corner v, the
    # spokes to its two other corners
    centre = f.ravel()
    left, right = f[:, [1, 2, 0]].ravel(), f[:, [2, 0, 1]].ravel()
    spokes, index = np.unique(
        np.concatenate([centre * n_vertices + left, centre * n_vertices + right]), return_inverse=True
    )
    k = len(centre)
    graph = sp.coo_matrix((np.ones(k), (index[:k], index[k:])), shape=(len(spokes), len(spokes)))
    _, label = connected_components(graph, directed=False)
    fans = np.unique((spokes // n_vertices) * (int(label.max()) + 1) + label) // (int(label.max()) + 1)
    vertex, count = np.unique(fans, return_counts=True)
    return vertex[count > 1]


FLAT_RTOL = 1e-6
"""A mesh whose vertices lie within ``FLAT_RTOL × its largest extent`` of one plane is flat (a 2-D or
flattened mesh); the thinnest of the 76 TOSCA meshes is 0.165 of its largest extent."""


def flatness(vertices: np.ndarray) -> float:
    """Thickness of the point set along its thinnest principal direction over its largest extent
    (0 for points in one plane)."""
    v = np.asarray(vertices, dtype=np.float64)
    centred = v - v.mean(axis=0)
    _, _, vt = np.linalg.svd(centred.T @ centred)
    extent = np.ptp(centred @ vt.T, axis=0)
    return float(extent[-1] / extent[0]) if extent[0] > 0 else 0.0


@dataclass(frozen=True, eq=False)
class MeshRepair:
    """What :func:`surface_for_remeshing` changed on its copy, and how the copy maps back.

    Attributes:
        vertex_index: (V_copy,) int64 input vertex of each copy vertex (increasing: input order kept).
        face_index: (F_copy,) int64 input face row of each copy face (increasing; columns unchanged).
        n_input_vertices, n_input_faces: sizes of the input.
        repeated_index_faces: faces dropped for naming a vertex twice.
        zero_area_faces: other faces of zero area (collinear or coincident corners). They are KEPT in
            the copy (dropping them would cut slits that the remesh turns into holes); closest-point
            queries skip them (:class:`becos.core.geometry.SurfaceLocator`), so no map point lies in one.
        duplicate_faces: faces dropped for repeating an earlier row's vertex set.
        unreferenced_vertices: input vertices used by no face at all.
        orphaned_vertices: vertices used only by dropped degenerate or duplicate faces.
        components: connected components of the remaining faces (1 after the repair).
        dropped_component_faces, dropped_component_vertices: faces and vertices of the smaller
            components that were dropped.
        dropped_area_share: their share of the total area (0..1).
        misoriented_edges: directed edges used twice in the input (inconsistent winding); NOT
            changed here, :func:`becos.build.remesh.remesh` re-orients its own copy.
    """

    vertex_index: np.ndarray
    face_index: np.ndarray
    n_input_vertices: int
    n_input_faces: int
    repeated_index_faces: int = 0
    zero_area_faces: int = 0
    duplicate_faces: int = 0
    unreferenced_vertices: int = 0
    orphaned_vertices: int = 0
    components: int = 1
    dropped_component_faces: int = 0
    dropped_component_vertices: int = 0
    dropped_area_share: float = 0.0
    misoriented_edges: int = 0

    @property
    def changed(self) -> bool:
        """True when the copy differs from the input (something was dropped)."""
        return len(self.vertex_index) != self.n_input_vertices or len(self.face_index) != self.n_input_faces

    @property
    def needs_attention(self) -> bool:
        """True when anything is reported: a change, zero-area faces, or faces to re-orient."""
        return self.changed or self.zero_area_faces > 0 or self.misoriented_edges > 0

    def counts(self) -> dict:
        """The counts as a JSON-able dict (no arrays)."""
        d = asdict(self)
        d.pop("vertex_index")
        d.pop("face_index")
        return d

    def summary(self) -> str:
        """One line naming every repair, e.g. ``dropped 5 faces with a repeated vertex index; ...``."""
        parts = []
        if self.repeated_index_faces:
            parts.append(f"dropped {self.repeated_index_faces} faces with a repeated vertex index")
        if self.zero_area_faces:
            parts.append(
                f"found {self.zero_area_faces} zero-area faces (kept, so the surface stays closed, but "
                f"no surface point is placed in them)"
            )
        if self.duplicate_faces:
            parts.append(f"dropped {self.duplicate_faces} duplicate faces (same vertices as an earlier row)")
        if self.dropped_component_faces:
            parts.append(
                f"kept the largest of {self.components} connected components, dropping "
                f"{self.dropped_component_faces} faces and {self.dropped_component_vertices} vertices "
                f"({100 * self.dropped_area_share:.2f}% of the area; those vertices get no counterpart)"
            )
        if self.unreferenced_vertices:
            parts.append(
                f"ignored {self.unreferenced_vertices} unreferenced vertices (used by no face; they get no counterpart)"
            )
        if self.orphaned_vertices:
            parts.append(
                f"ignored {self.orphaned_vertices} vertices used only by dropped faces (they get no counterpart)"
            )
        if self.misoriented_edges:
            parts.append(f"re-orients inconsistently wound faces ({self.misoriented_edges} directed edges used twice)")
        if not parts:
            return "no repair needed"
        return "; ".join(parts) + (
            " — on a copy: the file is unchanged and the maps refer to its vertex order and face rows"
        )


def surface_for_remeshing(
    mesh: TriMesh, *, source: str | Path | None = None, max_dropped_area_share: float = MAX_DROPPED_AREA_SHARE
) -> tuple[TriMesh, MeshRepair]:
    """A copy of ``mesh`` that a remesher can take: faces with a repeated vertex index, duplicate
    faces, unreferenced vertices and small extra connected components dropped (zero-area faces with
    three distinct vertices stay: they close the surface; no map point is placed in them). The
    input is not modified.

    The copy keeps the input's vertex order and face-row order among what is kept (both index
    arrays of the report are increasing) and each kept face's columns; so a point (face k,
    weights w) of the copy is the point (``face_index[k]``, w) of the input, and copy vertex j is
    input vertex ``vertex_index[j]``. When nothing needs dropping the input object itself is
    returned (the remesh of a clean mesh is unchanged by this step).

    Components are vertex-connected over the kept faces; the one with the largest area is kept.

    Args:
        mesh: the input (any units; areas are compared as shares only).
        source: the file the mesh came from, named in the error.
        max_dropped_area_share: the largest area share (0..1) the dropped components may hold.

    Returns:
        (copy, report); see :class:`MeshRepair`.

    Raises:
        InputFileError: no usable face is left, the extra components hold more than
            ``max_dropped_area_share`` of the area (the file holds several shapes), edges are
            shared by more than two faces, or a vertex joins several fans of faces (non-manifold; the
            remesher cannot orient such a surface).
    """
    n, faces = mesh.n_vertices, mesh.faces
    where = Path(source) if source is not None else Path(f"<mesh with {n} vertices and {len(faces)} faces>")
    repeated = repeated_index_faces(faces)
    zero = zero_area_faces(mesh) & ~repeated
    keep = ~repeated
    dup = duplicate_faces(faces, n, among=keep) >= 0
    keep &= ~dup
    if not (keep & ~zero).any():
        raise InputFileError(
            where,
            f"none of its {len(faces)} faces has a non-zero area",
            "re-export the mesh; becos needs a triangle surface",
        )
    referenced = np.zeros(n, dtype=bool)
    referenced[faces.ravel()] = True
    clean_used = np.zeros(n, dtype=bool)
    clean_used[faces[keep].ravel()] = True
    n_surface_components, dropped_faces, share = _keep_largest_component(mesh, keep, where, max_dropped_area_share)
    kept = faces[keep]
    _require_manifold(kept, n, where)
    used = np.zeros(n, dtype=bool)
    used[kept.ravel()] = True
    dropped_vertices = int((clean_used & ~used).sum())
    report_kw = dict(
        orphaned_vertices=int((referenced & ~clean_used).sum()),
        n_input_vertices=n,
        n_input_faces=len(faces),
        repeated_index_faces=int(repeated.sum()),
        zero_area_faces=int(zero.sum()),
        duplicate_faces=int(dup.sum()),
        unreferenced_vertices=int((~referenced).sum()),
        components=int(n_surface_components),
        dropped_component_faces=dropped_faces,
        dropped_component_vertices=dropped_vertices,
        dropped_area_share=share,
        misoriented_edges=misoriented_edge_count(kept),
    )
    if keep.all() and used.all():
        return mesh, MeshRepair(np.arange(n), np.arange(len(faces)), **report_kw)
    vertex_index = np.flatnonzero(used)
    new_index = np.full(n, -1, dtype=np.int64)
    new_index[vertex_index] = np.arange(len(vertex_index))
    face_index = np.flatnonzero(keep)
    copy = TriMesh(mesh.vertices[vertex_index], new_index[faces[face_index]])
    return copy, MeshRepair(vertex_index, face_index, **report_kw)


def _keep_largest_component(
    mesh: TriMesh, keep: np.ndarray, where: Path, max_dropped_area_share: float
) -> tuple[int, int, float]:
    """Clear in ``keep`` ((F,) bool, the faces kept so far) the faces outside the vertex-connected
    component of largest area. Returns (components, faces dropped, dropped area share 0..1).

    Raises:
        InputFileError: the dropped components hold more than ``max_dropped_area_share`` of the area.
    """
    kept_faces = mesh.faces[keep]
    face_label, n_surface_components = face_components(kept_faces, mesh.n_vertices)
    if n_surface_components <= 1:
        return n_surface_components, 0, 0.0
    tri = mesh.vertices[kept_faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    per_comp = np.bincount(face_label, weights=area, minlength=n_surface_components)
    main = int(per_comp.argmax())
    share = float(1.0 - per_comp[main] / per_comp.sum())
    if share > max_dropped_area_share:
        sizes = ", ".join(f"{100 * a / per_comp.sum():.1f}%" for a in sorted(per_comp, reverse=True)[:5])
        raise InputFileError(
            where,
            f"has {n_surface_components} connected components; besides the largest "
            f"they hold {100 * share:.1f}% of the area (shares: {sizes}), more than the "
            f"{100 * max_dropped_area_share:.0f}% becos drops as specks",
            "a shape must be one connected surface: remove the extra pieces (e.g. MeshLab: "
            "Filters > Cleaning and Repairing > Remove Isolated pieces) or split the file "
            "into separate shapes",
        )
    in_main = face_label == main
    rows = np.flatnonzero(keep)
    keep[rows[~in_main]] = False
    return n_surface_components, int((~in_main).sum()), share


def _require_manifold(faces: np.ndarray, n_vertices: int, where: Path) -> None:
    """Raise :class:`InputFileError` (naming ``where``) when an edge of (F, 3) ``faces`` is shared by more
    than two faces, or a vertex joins several fans of faces: the remesher cannot orient such a surface."""
    non_manifold = int((undirected_edges(faces)[1] > 2).sum())
    if non_manifold:
        raise InputFileError(
            where,
            f"{non_manifold} edges are shared by more than two faces (non-manifold) after "
            f"dropping duplicate and repeated-index faces; becos cannot remesh such a surface",
            "repair the mesh (e.g. MeshLab: Filters > Cleaning and Repairing > Repair non Manifold "
            "Edges) or leave the shape out",
        )
    bow_ties = non_manifold_vertices(faces, n_vertices)
    if len(bow_ties):
        raise InputFileError(
            where,
            f"{len(bow_ties)} vertices are non-manifold (their faces form several fans that "
            f"touch only at the vertex, e.g. vertex {int(bow_ties[0])} of the file) after dropping "
            f"duplicate and repeated-index faces; becos cannot remesh such a surface",
            "use the dataset's original mesh (re-download it), or repair it (e.g. MeshLab: Filters > "
            "Cleaning and Repairing > Repair non Manifold Vertices) or leave the shape out",
        )
