"""The Python module against the CLI (issue 24 part 7): what `scanpress.read` returns is what `scanpress decode`
writes, levels and boxes select as the CLI does, arrays encoded by the module read back to the same surface, and bad
input raises with the file named. Run by scripts/test.sh: PYTHONPATH=build/python, SCANPRESS_BIN=build/bin/scanpress."""
import os
import subprocess

import numpy as np
import pytest

import scanpress

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BIN = os.environ.get("SCANPRESS_BIN", os.path.join(REPO, "build", "bin", "scanpress"))
BUNNY = os.path.join(REPO, "data", "bun_zipper.ply.zst")


def cli(*args):
    r = subprocess.run([BIN, *map(str, args)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return r


def read_ply(path, vertex_records=False):
    """A binary little-endian PLY as scanpress writes it: float or double x, y, z (then any other vertex
    properties), faces as a uchar count and int indices. `vertex_records`: also the vertex records (a numpy
    structured array, one field per property)."""
    with open(path, "rb") as f:
        header = []
        while True:
            line = f.readline().decode().strip()
            header.append(line)
            if line == "end_header":
                break
        body = f.read()
    nv = nf = 0
    vprops, element = [], None
    for line in header:
        w = line.split()
        if w[0] == "element":
            element = w[1]
            if element == "vertex":
                nv = int(w[2])
            if element == "face":
                nf = int(w[2])
        elif w[0] == "property" and element == "vertex":
            vprops.append((w[2], {"float": "<f4", "double": "<f8", "uchar": "u1"}[w[1]]))
    vdt = np.dtype(vprops)
    verts = np.frombuffer(body, dtype=vdt, count=nv)
    faces = np.frombuffer(body, dtype=np.dtype([("n", "u1"), ("i", "<i4", (3,))]), count=nf, offset=nv * vdt.itemsize)
    assert (faces["n"] == 3).all()
    pos = np.stack([verts["x"], verts["y"], verts["z"]], axis=1).astype(np.float64)
    if vertex_records:
        return pos, faces["i"].astype(np.uint32), verts
    return pos, faces["i"].astype(np.uint32)


def surface(positions, faces):
    """Triangles as sorted tuples of float32 corner positions: the same surface whatever the vertex order."""
    p = positions.astype(np.float32)
    tris = [tuple(sorted(tuple(p[v]) for v in f)) for f in faces]
    return sorted(tris)


@pytest.fixture(scope="module")
def bunny(tmp_path_factory):
    d = tmp_path_factory.mktemp("bunny")
    spz = d / "b.spz"
    cli("encode", BUNNY, spz, "--codec", "kdtree", "--bits", "12", "--tile-triangles", "16384", "--quiet")
    return d, spz


def test_read_equals_the_cli_decode(bunny):
    d, spz = bunny
    cli("decode", spz, d / "b.ply", "--quiet")
    pos, faces = read_ply(d / "b.ply")
    m = scanpress.read(str(spz))
    assert m["positions"].dtype == np.float64 and m["positions"].shape == pos.shape
    assert m["faces"].dtype == np.uint32 and np.array_equal(m["faces"], faces)
    assert np.array_equal(m["positions"].astype(np.float32), pos.astype(np.float32))
    assert m["uvs"] is None
    assert m["tiles"] == len(scanpress.info(str(spz))["tiles"]) > 1
    # The bunny's confidence and intensity (float PLY properties), as the CLI's PLY has them, bit for bit.
    _, _, verts = read_ply(d / "b.ply", vertex_records=True)
    assert sorted(m["scalars"]) == ["confidence", "intensity"]
    for name in ("confidence", "intensity"):
        assert m["scalars"][name].dtype == np.float32
        assert np.array_equal(m["scalars"][name].view(np.uint32), verts[name].view(np.uint32))


def test_read_gives_texture_coordinates(tmp_path):
    # A seam along vertices 2 and 3: their corners name two coordinates each, so the reader splits them (wedges).
    obj = tmp_path / "q.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 2 1 0\n"
                   "vt 0 0\nvt 0.5 0\nvt 0.5 1\nvt 0 1\nvt 0.75 0.25\nvt 1 0.25\nvt 1 0.75\nvt 0.75 0.75\n"
                   "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\nf 2/5 5/6 6/7\nf 2/5 6/7 3/8\n")
    spz = tmp_path / "q.spz"
    cli("encode", obj, spz, "--codec", "kdtree", "--quiet")
    m = scanpress.read(str(spz))
    assert m["uvs"].dtype == np.float64 and m["uvs"].shape == (8, 2)
    corners = sorted((tuple(m["positions"][v].round(3)), tuple(m["uvs"][v])) for f in m["faces"] for v in f)
    want = sorted([((0, 0, 0), (0, 0)), ((1, 0, 0), (0.5, 0)), ((1, 1, 0), (0.5, 1)), ((0, 0, 0), (0, 0)),
                   ((1, 1, 0), (0.5, 1)), ((0, 1, 0), (0, 1)), ((1, 0, 0), (0.75, 0.25)), ((2, 0, 0), (1, 0.25)),
                   ((2, 1, 0), (1, 0.75)), ((1, 0, 0), (0.75, 0.25)), ((2, 1, 0), (1, 0.75)),
                   ((1, 1, 0), (0.75, 0.75))])
    assert corners == want
    assert sorted(m["scalars"]) == ["u", "v"]


def test_levels_tiles_and_boxes_select_as_the_cli(bunny):
    d, spz = bunny
    info = scanpress.info(str(spz))
    whole = scanpress.read(str(spz))
    coarse = scanpress.read(str(spz), level=6)
    assert coarse["level"] == 6 and 0 < len(coarse["positions"]) < len(whole["positions"])
    cli("decode", spz, d / "l6.ply", "--level", "6", "--quiet")
    assert surface(*read_ply(d / "l6.ply")) == surface(coarse["positions"], coarse["faces"])
    one = scanpress.read(str(spz), tiles=[info["tiles"][0]["id"]])
    assert one["tiles"] == 1 and len(one["faces"]) < len(whole["faces"])
    lo, hi = whole["positions"].min(axis=0), whole["positions"].max(axis=0)
    box = tuple(lo) + tuple(lo + (hi - lo) / 2)
    part = scanpress.read(str(spz), box=box)
    cut = scanpress.read(str(spz), box=box, crop=True)
    assert 0 < len(cut["faces"]) < len(part["faces"]) <= len(whole["faces"])
    used = cut["positions"][np.unique(cut["faces"])]
    assert (used >= np.array(lo) - 1e-9).all() and (used <= np.array(box[3:]) + 1e-9).all()
    cli("decode", spz, d / "crop.ply", "--box", ",".join(map(repr, box)), "--crop", "--quiet")
    assert surface(*read_ply(d / "crop.ply")) == surface(cut["positions"], cut["faces"])


def test_arrays_encode_and_read_back(tmp_path):
    # A sphere with normals and colors, as a trimesh or Open3D user has it in arrays.
    n = 40
    th, ph = np.meshgrid(np.linspace(0.1, np.pi - 0.1, n), np.linspace(0, 2 * np.pi, n, endpoint=False), indexing="ij")
    pos = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=-1).reshape(-1, 3)
    faces = []
    for i in range(n - 1):
        for j in range(n):
            a, b, c, d = i * n + j, i * n + (j + 1) % n, (i + 1) * n + j, (i + 1) * n + (j + 1) % n
            faces += [(a, c, b), (b, c, d)]
    faces = np.array(faces)
    normals = pos.astype(np.float32)
    colors = (np.abs(pos) * 255).astype(np.uint8)
    out = tmp_path / "s.spz"
    r = scanpress.encode(str(out), pos, faces, normals=normals, colors=colors, codec="edgebreaker", bits=16)
    assert r["faces"] == len(faces) and r["bytes"] == os.path.getsize(out) and r["codec"] == "edgebreaker"
    back = scanpress.read(str(out))
    cell = 2.0 / 2 ** 16
    assert back["faces"].shape == faces.shape
    # Same triangles: each decoded vertex is within a cell of one original vertex (brute force), and through that
    # match the faces, normals and colors are the originals'.
    dist = np.linalg.norm(back["positions"][:, None, :] - pos[None, :, :], axis=2)
    match = dist.argmin(axis=1)
    assert dist[np.arange(len(match)), match].max() <= cell
    assert len(np.unique(match)) == len(pos)
    assert {tuple(sorted(match[f])) for f in back["faces"]} == {tuple(sorted(f)) for f in faces}
    assert np.abs(back["normals"] - normals[match]).max() < 2e-3
    assert np.array_equal(back["colors"], colors[match])
    # A point cloud (no faces) and an error target.
    pc = scanpress.encode(str(tmp_path / "pc.spz"), pos, None, codec="kdtree")
    assert pc["faces"] == 0 and len(scanpress.read(str(tmp_path / "pc.spz"))["positions"]) == len(pos)
    t = scanpress.encode(str(tmp_path / "t.spz"), pos, faces, max_error=1e-3, codec="auto")
    assert t["codec"] in ("pm", "edgebreaker")


def test_bad_input_raises_naming_the_file(tmp_path):
    with pytest.raises(OSError, match="nowhere.spz"):
        scanpress.read(str(tmp_path / "nowhere.spz"))
    data = open(os.path.join(REPO, "tests", "golden", "pm-v1.spz"), "rb").read()
    (tmp_path / "cut.spz").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="cut.spz"):
        scanpress.read(str(tmp_path / "cut.spz"))
    pos = np.zeros((3, 3))
    with pytest.raises(ValueError, match="faces\\[0\\] names vertex 7"):
        scanpress.encode(str(tmp_path / "x.spz"), pos, np.array([[0, 1, 7]]))
    with pytest.raises(ValueError, match="shape"):
        scanpress.encode(str(tmp_path / "x.spz"), np.zeros((3, 2)), None)
    with pytest.raises(ValueError, match="unknown codec"):
        scanpress.encode(str(tmp_path / "x.spz"), pos, np.array([[0, 1, 2]]), codec="zip")
    assert not (tmp_path / "x.spz").exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
