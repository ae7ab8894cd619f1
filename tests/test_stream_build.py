"""The streaming build: chunks, local worker processes, a Dask cluster, and the
chunked STL/PLY readers. Every build here must equal the one-pass build bit
for bit (sums are exact, aniso3d.build.stream), so comparisons are equality."""

from __future__ import annotations

import io
import math
import os
import signal
import sys
import tracemalloc

import numpy as np
import pytest
import trimesh

import aniso3d.build.mesh_stream as mesh_stream
from aniso3d import AnisoTexture, Mesh, ResourceError, build_texture, load_mesh, scenes
from aniso3d.app.cli import main
from aniso3d.app.common import Progress
from aniso3d.build import stream
from aniso3d.build.clip import make_grid
from aniso3d.build.mesh import concatenate
from aniso3d.build.mesh_stream import CLOSED_BYTES_PER_FACE, MeshSource, PlySource, StlSource, open_source
from aniso3d.build.texture import CHUNK_BYTES_PER_TRIANGLE, plan_chunk_size, sphere_directions

RES = 32


def assert_same(a: AnisoTexture, b: AnisoTexture) -> None:
    """Bit-for-bit equality of two textures, arrays and metadata."""
    for name in AnisoTexture._ARRAYS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape, name
        assert np.array_equal(x, y), name
    assert a.voxel_size == b.voxel_size
    assert a.meta == b.meta


@pytest.fixture(scope="module")
def mesh() -> Mesh:
    """A small tree (leaves cross voxel faces) plus a coarse sphere whose large
    triangles each span many voxels, in several materials: 1052 triangles."""
    tree = scenes.tree(levels=3, leaves_per_twig=10)
    ball = scenes.sphere(0.8, center=(0.5, 4.0, 0.2), subdivisions=3, kd=(0.9, 0.2, 0.1), ks=0.6, shininess=80.0)
    return concatenate([tree, ball], name="tree+ball")


@pytest.fixture(scope="module")
def one_pass(mesh) -> AnisoTexture:
    stats = {}
    tex = build_texture(mesh, RES, 16, stats=stats)
    assert stats["chunks"] == 1
    return tex


# --------------------------------------------------------------- chunking


def budget_for(chunk: int, workers: int) -> int:
    return chunk * CHUNK_BYTES_PER_TRIANGLE * (workers + 1)


@pytest.mark.parametrize("workers", [1, 2])
def test_hundred_triangle_chunks_equal_the_one_pass_build(mesh, one_pass, workers):
    budget = budget_for(100, workers)
    assert plan_chunk_size(mesh.n_faces, budget, workers) == 100
    stats = {}
    tex = build_texture(mesh, RES, 16, memory_budget=budget, workers=workers, stats=stats)
    assert stats["chunk_size"] == 100 and stats["chunks"] == math.ceil(mesh.n_faces / 100)
    assert stats["executor"] == ("in process" if workers == 1 else "process pool")
    assert_same(tex, one_pass)
    # and it is the texture, not merely a repeatable one: facet area is conserved
    assert tex.total_area() == pytest.approx(mesh.area(), rel=1e-12)


def test_chunks_really_share_voxels(mesh):
    # The equality above means something only if chunks add to the same
    # voxels and entries: check that neighbouring chunks overlap.
    grid = make_grid(mesh.bounds, RES)
    dirs = sphere_directions(16)
    src = MeshSource(mesh)
    a = stream.chunk_partial(src.read(0, 100), grid, dirs)
    b = stream.chunk_partial(src.read(100, 200), grid, dirs)
    assert len(np.intersect1d(a.voxel_keys, b.voxel_keys)) > 5
    assert len(np.intersect1d(a.entry_keys, b.entry_keys)) > 5


def test_texture_does_not_depend_on_face_order_or_grouping(mesh, one_pass):
    # Integer sums commute: shuffled faces, odd chunk sizes and a list of
    # meshes all give the same bits.
    order = np.random.default_rng(7).permutation(mesh.n_faces)
    shuffled = Mesh(mesh.vertices, mesh.faces[order], mesh.kd[order], mesh.ks[order], mesh.shininess[order],
                    mesh.name)  # fmt: skip
    assert_same(build_texture(shuffled, RES, 16, chunk_size=37), one_pass)
    half = mesh.n_faces // 2
    parts = [Mesh(mesh.vertices, mesh.faces[s], mesh.kd[s], mesh.ks[s], mesh.shininess[s], mesh.name)
             for s in (slice(0, half), slice(half, None))]  # fmt: skip
    assert_same(build_texture(parts, RES, 16, chunk_size=300), build_texture(concatenate(parts, mesh.name), RES, 16))
    listed = build_texture(parts, RES, 16, chunk_size=300)
    for name in AnisoTexture._ARRAYS:
        assert np.array_equal(getattr(listed, name), getattr(one_pass, name)), name


def test_merges_in_any_grouping_are_exact(mesh, one_pass):
    # The Dask tree reduction's step, in two different groupings.
    grid = make_grid(mesh.bounds, RES)
    dirs = sphere_directions(16)
    src = MeshSource(mesh)
    src.find_closed()
    parts = [stream.chunk_partial(stream.read_chunk(src, a, b), grid, dirs)
             for a, b in stream.plan_chunks(mesh.n_faces, 150)]  # fmt: skip
    left = stream.merge_partials(stream.merge_partials(*parts[:3]), *parts[3:])
    right = stream.merge_partials(*parts[::-1])
    for p in (left, right):
        arrays = stream.finalize_partial(p, grid, dirs)
        for name in ("density", "entry_area", "entry_centroid", "entry_kd", "entry_normal", "coords"):
            assert np.array_equal(arrays[name], getattr(one_pass, name)), name


def test_exact_sums_against_python_integers():
    rng = np.random.default_rng(3)
    v = rng.normal(size=2000) * np.exp2(rng.integers(-60, 40, 2000))
    want = sum(int(x * 2**200) for x in v.tolist())  # every value is a multiple of 2^-200
    assert stream.exact_sum(v) == want << (1074 - 200)
    assert stream.exact_to_float(stream.exact_sum(v)) == math.fsum(v.tolist())
    # fixed point: limbs round each value to 2^-84, sums add exactly in any order
    x = rng.uniform(-3, 3, (500, 2))
    hi, lo = stream._join3(*(np.add.reduceat(limb, [0], axis=0) for limb in stream._split3(x, stream.FRAC_BITS)))
    exact = [sum(round(float(t) * 2**84) for t in col) for col in x.T]  # Python ints
    for c in range(2):
        assert int(hi[0, c]) * 2**64 + int(lo[0, c]) == exact[c]
    # the two-limb split of small values is the same integer
    small = x[np.abs(x).max(axis=1) < stream.SMALL_VALUE]
    two = stream._join2(*(np.add.reduceat(limb, [0], axis=0) for limb in stream._split2(small, stream.FRAC_BITS)))
    three = stream._join3(*(np.add.reduceat(limb, [0], axis=0) for limb in stream._split3(small, stream.FRAC_BITS)))
    assert np.array_equal(two[0], three[0]) and np.array_equal(two[1], three[1])


def test_geometry_outside_the_bounds_sums_large_pieces_exactly(mesh):
    # Bounds that cut the mesh: the outer cells take whole triangles, pieces of
    # many voxel areas (the three-limb path); still chunk-independent, and the
    # area is all there.
    box = np.array([[-0.1, 1.0, -0.1], [0.1, 1.2, 0.1]])
    a = build_texture(mesh, 8, 16, bounds=box)
    assert a.entry_area.max() > stream.SMALL_VALUE
    assert_same(build_texture(mesh, 8, 16, bounds=box, chunk_size=64), a)
    assert a.total_area() == pytest.approx(mesh.area(), rel=1e-12)


def test_chunked_build_holds_one_chunk_at_a_time():
    # The point of chunks: working memory follows the chunk, not the mesh.
    tree = scenes.tree(levels=5, leaves_per_twig=20)  # 14k triangles
    peaks = {}
    for size in (None, 1000):
        tracemalloc.start()
        try:
            build_texture(tree, RES, 16, chunk_size=size)
            peaks[size] = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    assert peaks[1000] < 0.4 * peaks[None], peaks


# ---------------------------------------------------------------- readers


@pytest.fixture(scope="module")
def files(tmp_path_factory, mesh):
    """The mesh as binary PLY (face colours), binary PLY (vertex colours,
    float64 vertices), binary STL, ASCII PLY and a PLY of quads."""
    d = tmp_path_factory.mktemp("files")
    tm = mesh.to_trimesh()
    paths = {"ply": d / "faces.ply", "stl": d / "tree.stl", "ascii": d / "ascii.ply", "quads": d / "quads.ply"}
    tm.export(paths["ply"])
    tm.export(paths["stl"])
    paths["ascii"].write_bytes(trimesh.exchange.ply.export_ply(tm, encoding="ascii"))
    vc = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    vc.visual.vertex_colors = np.random.default_rng(1).integers(0, 256, (len(mesh.vertices), 4), dtype=np.uint8)
    paths["vertex"] = d / "vertex.ply"
    vc.export(paths["vertex"], vertex_normal=False)
    # float64 vertex coordinates (trimesh writes float32)
    raw = paths["vertex"].read_bytes()
    head, body = raw.split(b"end_header\n", 1)
    n_v = len(mesh.vertices)
    vrec = np.frombuffer(body[: n_v * 16], dtype=[("xyz", "<f4", 3), ("rgba", "u1", 4)])
    v64 = np.zeros(n_v, dtype=[("xyz", "<f8", 3), ("rgba", "u1", 4)])
    v64["xyz"] = mesh.vertices + 1e-9  # not representable in float32
    v64["rgba"] = vrec["rgba"]
    paths["double"] = d / "double.ply"
    paths["double"].write_bytes(head.replace(b"property float ", b"property double ") + b"end_header\n"
                                + v64.tobytes() + body[n_v * 16:])  # fmt: skip
    # quads: two triangles of the mesh's first 40 faces joined as 4-gons
    q = np.concatenate([mesh.faces[:40:2], mesh.faces[1:40:2, 2:3]], axis=1)
    quads = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {n_v}\nproperty float x\nproperty float y\n"
        f"property float z\nelement face {len(q)}\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode() + mesh.vertices.astype("<f4").tobytes()
    quads += b"".join(np.uint8(4).tobytes() + f.astype("<i4").tobytes() for f in q)
    paths["quads"].write_bytes(quads)
    return paths


def read_all(source, step: int):
    parts = [source.read(a, min(source.n_faces, a + step)) for a in range(0, source.n_faces, step)]
    return {n: np.concatenate([getattr(p, n) for p in parts]) for n in ("triangles", "kd", "ks", "shininess")}


@pytest.mark.parametrize("kind, cls", [("ply", PlySource), ("stl", StlSource), ("vertex", PlySource),
                                       ("double", PlySource)])  # fmt: skip
def test_chunked_readers_equal_trimesh_loading(files, kind, cls):
    path = files[kind]
    source = open_source(path)
    assert isinstance(source, cls) and source.portable and "in chunks" in source.note
    want = load_mesh(path)
    assert source.n_faces == want.n_faces and source.n_vertices == len(want.vertices)
    got = read_all(source, 97)
    assert np.array_equal(got["triangles"], want.triangles)
    for name in ("kd", "ks", "shininess"):
        assert got[name].dtype == getattr(want, name).dtype and np.array_equal(got[name], getattr(want, name)), name
    assert np.array_equal(source.bounds(), want.bounds)
    if kind in ("ply", "vertex"):
        assert len(np.unique(got["kd"], axis=0)) > 3  # colours really came through


@pytest.mark.parametrize("kind", ["ply", "stl", "double"])
def test_build_from_a_path_equals_the_loaded_build(files, kind, monkeypatch):
    want = build_texture(load_mesh(files[kind]), RES, 16)

    def no_whole_load(*a, **k):
        raise AssertionError("a streamed format was loaded whole")

    monkeypatch.setattr(mesh_stream, "load_mesh", no_whole_load)
    stats = {}
    got = build_texture(files[kind], RES, 16, chunk_size=101, stats=stats)
    assert stats["chunks"] == math.ceil(want.meta["n_triangles"] / 101) and "in chunks" in stats["reader"]
    assert_same(got, want)


@pytest.mark.parametrize("kind, why", [("ascii", "ascii PLY"), ("quads", "faces that are not all triangles")])
def test_other_files_are_loaded_whole_and_say_so(files, kind, why):
    source = open_source(files[kind])
    assert source.note == f"loaded whole ({why})" and not source.portable
    assert_same(build_texture(files[kind], RES, 16, chunk_size=50), build_texture(load_mesh(files[kind]), RES, 16))


def test_chunk_paths_run_in_worker_processes(files):
    stats = {}
    got = build_texture(files["ply"], RES, 16, workers=2, chunk_size=200, stats=stats)
    assert stats["executor"] == "process pool" and stats["chunks"] == math.ceil(stats["n_faces"] / 200) > 2
    assert_same(got, build_texture(load_mesh(files["ply"]), RES, 16))


# --------------------------------------------------------------- progress


def test_progress_shows_triangles_done_and_time_left():
    p = Progress("building", enabled=True, stream=io.StringIO(), total=4_194_300)
    line = p.line(0.25, "clip", 10.0)
    assert "1,048,575/4,194,300 triangles" in line and "~30s left" in line
    assert "left" not in p.line(1.0, "register", 40.0)
    calls = []
    build_texture(scenes.tree(levels=3, leaves_per_twig=10), RES, 16, chunk_size=100,
                  progress=lambda f, s: calls.append(f))  # fmt: skip
    assert calls == sorted(calls) and calls[-1] == 1.0 and len(calls) >= 6


def test_cli_workers_build_equals_the_library(files, tmp_path, capsys):
    out = tmp_path / "t.a3d"
    # room for the closed faces' pass over every triangle (else none is
    # closed, unlike the library's build in memory)
    n = load_mesh(files["ply"]).n_faces
    budget = max(budget_for(200, 2), n * CLOSED_BYTES_PER_FACE)
    size = plan_chunk_size(n, budget, 2)
    code = main(["build", str(files["ply"]), "-o", str(out), "-r", str(RES), "-k", "16", "--workers", "2",
                 "--memory-budget", f"{budget}", "-q"])  # fmt: skip
    stdout, err = capsys.readouterr()
    assert code == 0, err
    assert 1 < size < n
    assert f"{-(-n // size)} of up to {size} triangles, on 2 local worker processes" in stdout
    assert "binary PLY, read in chunks" in stdout
    assert_same(AnisoTexture.load(out), build_texture(load_mesh(files["ply"]), RES, 16).as_stored())


def test_missing_dask_is_one_clear_error(files, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails
    code = main(["build", str(files["ply"]), "-o", str(tmp_path / "t.a3d"), "--scheduler", "local", "-q"])
    _, err = capsys.readouterr()
    assert code == 2 and err.count("\n") == 1 and "pip install 'aniso3d[cluster]'" in err
    with pytest.raises(ResourceError, match=r"aniso3d\[cluster\]"):
        build_texture(files["ply"], RES, 16, client=object())


# ------------------------------------------------------------------- Dask


@pytest.fixture(scope="module")
def client():
    distributed = pytest.importorskip("distributed")
    with stream.local_cluster(2) as c, distributed.Client(c) as cl:
        assert c.workers and all(w.process.is_alive() for w in c.workers.values())  # processes, not threads
        yield cl


def test_dask_build_equals_the_local_build(client, mesh, one_pass, files):
    stats = {}
    assert_same(build_texture(mesh, RES, 16, client=client, chunk_size=100, stats=stats), one_pass)
    assert stats["executor"] == "dask" and stats["workers"] == 2 and stats["chunks"] == math.ceil(mesh.n_faces / 100)
    # a path: each worker reads its own chunk
    assert_same(build_texture(files["stl"], RES, 16, client=client, chunk_size=100),
                build_texture(load_mesh(files["stl"]), RES, 16))  # fmt: skip


class KillingSource(MeshSource):
    """A mesh whose first chunk read kills the process reading it (a Dask
    worker), once: the marker file says it has happened."""

    portable = True

    def __init__(self, mesh: Mesh, marker: str):
        super().__init__(mesh)
        self.marker = marker

    def read(self, start: int, stop: int):
        try:
            fd = os.open(self.marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            return super().read(start, stop)
        os.write(fd, str(os.getpid()).encode())
        os.close(fd)
        os.kill(os.getpid(), signal.SIGKILL)


def test_a_worker_killed_mid_job_changes_nothing(client, mesh, one_pass, tmp_path):
    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the workers cannot import this module
    try:
        marker = tmp_path / "killed"
        pids = set(client.run(os.getpid).values())
        got = build_texture(KillingSource(mesh, str(marker)), RES, 16, client=client, chunk_size=100)
    finally:
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    assert int(marker.read_text()) in pids  # a worker really died, with its chunk
    assert_same(got, one_pass)
