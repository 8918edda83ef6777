"""Reading meshes: file order kept, cache, and errors that name the file, the problem and the fix."""

import shutil

import numpy as np
import pytest

from becos.core.mesh import MeshCache, read_mesh
from becos.errors import InputFileError


def test_read_keeps_file_order_and_cache_returns_same_arrays(tosca_dir, tmp_path):
    mesh = read_mesh(tosca_dir / "wolf0.off")
    assert mesh.vertices.shape == (4344, 3) and mesh.faces.shape == (8684, 3)
    with open(tosca_dir / "wolf0.off") as fh:
        fh.readline()
        fh.readline()
        first = np.array(fh.readline().split(), dtype=float)
    assert np.allclose(mesh.vertices[0], first)
    cache = MeshCache(tmp_path / "cache")
    a = cache.load(tosca_dir / "wolf0.off")
    b = MeshCache(tmp_path / "cache").load(tosca_dir / "wolf0.off")  # a new process would read the .npz
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    assert len(list((tmp_path / "cache").glob("*.npz"))) == 1


@pytest.mark.parametrize(
    "fault, message",
    [
        ("missing", "mesh file not found"),
        ("empty", "could not be parsed|no vertices"),
        ("truncated", "OFF header announces|face indices span|could not be parsed|no triangles"),
        ("garbage", "could not be parsed|no vertices|no triangles"),
        ("nan", "NaN or infinite"),
    ],
)
def test_bad_mesh_files_raise_errors_naming_the_file(fault, message, tosca_dir, tmp_path):
    path = tmp_path / "wolf0.off"
    if fault != "missing":
        shutil.copy(tosca_dir / "wolf0.off", path)
        text = path.read_text()
        if fault == "empty":
            path.write_text("")
        elif fault == "truncated":
            lines = text.splitlines()
            # keep the header and half the vertices, then the faces: indices beyond the vertices read
            n_vertices = int(lines[1].split()[0])
            path.write_text("\n".join(lines[: 2 + n_vertices // 2] + lines[2 + n_vertices :]) + "\n")
        elif fault == "garbage":
            path.write_bytes(np.random.default_rng(0).bytes(5000))
        elif fault == "nan":
            lines = text.splitlines()
            lines[2] = "nan 0 0"
            path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputFileError, match=message) as info:
        read_mesh(path)
    assert str(path) in str(info.value) and "Fix:" in str(info.value)


@pytest.mark.parametrize("name", ["wolf0", "centaur0"])
def test_plain_off_reader_gives_trimeshs_arrays_and_other_files_fall_back(name, tosca_dir, tmp_path):
    """The numpy reader of plain triangle OFF files (no trimesh import in a remesh job) reads exactly
    the bytes trimesh reads; a file with a comment, a quad or a ragged vertex line goes to trimesh."""
    import trimesh

    from becos.core.formats.off import read_plain_off

    path = tosca_dir / f"{name}.off"
    loaded = trimesh.load(path, process=False, maintain_order=True, force="mesh", skip_materials=True)
    plain = read_plain_off(path.read_bytes())
    assert plain is not None
    assert plain[0].dtype == np.float64 and plain[0].tobytes() == np.asarray(loaded.vertices, np.float64).tobytes()
    assert plain[1].dtype == np.int64 and plain[1].tobytes() == np.asarray(loaded.faces, np.int64).tobytes()
    mesh = read_mesh(path)
    assert mesh.vertices.tobytes() == plain[0].tobytes() and mesh.faces.tobytes() == plain[1].tobytes()

    lines = path.read_text().splitlines()
    n_vertices = int(lines[1].split()[0])
    variants = {
        "comment": [lines[0], "# a comment", *lines[1:]],
        "quad": lines[:-1] + ["4 0 1 2 3"],
        "ragged": lines[:2] + [lines[2] + " 1.0", " ".join(lines[3].split()[:2])] + lines[4:],
        "extra_line": lines + [lines[-1]],
    }
    for label, text in variants.items():
        other = tmp_path / f"{label}.off"
        other.write_text("\n".join(text) + "\n")
        assert read_plain_off(other.read_bytes()) is None, label
    # layouts the block parser leaves to the token-by-token one read the same arrays all the same
    from becos.core.formats.off import _contiguous_arrays, _triangle_arrays
    from becos.core.formats.text import TextLines

    data = path.read_bytes()
    assert _contiguous_arrays(data) is not None
    token_arrays = _triangle_arrays(data, TextLines(data))
    assert all(a.tobytes() == b.tobytes() for a, b in zip(token_arrays, plain))
    layouts = {
        "crlf": data.replace(b"\n", b"\r\n"),
        "blank_line": data.replace(b"\n", b"\n\n", 3),
        "no_final_newline": data.rstrip(),
        "trailing_blank_lines": data + b"\n \n",
        "tabs": data.replace(b" ", b"\t"),
    }
    for label, other in layouts.items():
        read = read_plain_off(other)
        assert read is not None and all(a.tobytes() == b.tobytes() for a, b in zip(read, plain)), label
    # the commented file is still read (by trimesh), with the same arrays
    again = read_mesh(tmp_path / "comment.off")
    assert np.array_equal(again.vertices, mesh.vertices) and np.array_equal(again.faces, mesh.faces)
    assert n_vertices == mesh.n_vertices


def test_text_lines_split_on_the_whitespace_python_splits_on():
    """TextLines' data lines and token counts are those of ``bytes.split`` on every byte value: its
    whitespace test (two comparisons on uint8, wrapping below 9) names exactly space and bytes 9-13."""
    from becos.core.formats.text import TextLines

    rng = np.random.default_rng(0)
    alphabet = np.array([*range(256)] + [ord(" ")] * 200 + [ord("\n")] * 60 + [ord("#")] * 5, dtype=np.uint8)
    data = rng.choice(alphabet, size=20_000).tobytes()
    lines = TextLines(data)
    expected = [line for line in data.split(b"\n") if line.split() and not line.startswith(b"#")]
    assert [data[a:b] for a, b in zip(lines.starts, lines.ends)] == expected
    assert lines.token_counts(0, len(lines)).tolist() == [len(line.split()) for line in expected]


@pytest.mark.parametrize("word", [b"nan", b"NaN", b"-inf", b"INF", b"Infinity", b"+iNf"])
def test_every_spelling_of_a_non_finite_coordinate_is_found(word):
    """check_finite_text skips its regex when the block holds no n/N: every spelling it must find holds one."""
    from becos.core.formats.problems import FormatProblem
    from becos.core.formats.text import check_finite_text

    data = b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 " + word + b"\n3 0 1 2\n"
    line_starts = np.concatenate(([0], np.flatnonzero(np.frombuffer(data, dtype=np.uint8) == 10) + 1))
    with pytest.raises(FormatProblem, match="vertex line 3 holds a NaN or infinite coordinate"):
        check_finite_text(data, data.index(b"0 0 0"), data.index(b"3 0 1 2"), 2, line_starts, "vertex line")
    check_finite_text(data.replace(word, b"1e3"), 0, len(data) - 8, 2, line_starts, "vertex line")  # finite: quiet
