"""Writes the format fixtures of the loader tests with other tools' writers
(plyfile, meshio), from data/meshes/bunny.obj. Run from this folder:
    pip install plyfile meshio numpy && python3 make_fixtures.py
"""
import numpy as np
import meshio
from plyfile import PlyData, PlyElement

def read_obj(path):
    v, f = [], []
    for line in open(path):
        t = line.split()
        if not t:
            continue
        if t[0] == "v":
            v.append([float(x) for x in t[1:4]])
        elif t[0] == "f":
            f.append([int(x.split("/")[0]) - 1 for x in t[1:]])
    return np.array(v), f

v, f = read_obj("../bunny.obj")
tris = np.array([t for t in f if len(t) == 3])

def write_ply(path, text, byte_order):
    vert = np.array([tuple(p) for p in v], dtype=[("x", "f8"), ("y", "f8"), ("z", "f8")])
    # Extra properties and elements a reader has to skip.
    nx = np.zeros(len(v), dtype=[("x", "f8"), ("y", "f8"), ("z", "f8"), ("red", "u1")])
    nx["x"], nx["y"], nx["z"], nx["red"] = v[:, 0], v[:, 1], v[:, 2], 200
    face = np.empty(len(tris), dtype=[("vertex_indices", "i4", (3,)), ("flags", "u2")])
    face["vertex_indices"] = tris
    face["flags"] = 7
    edge = np.array([(0, 1), (1, 2)], dtype=[("vertex1", "i4"), ("vertex2", "i4")])
    PlyData(
        [PlyElement.describe(nx, "vertex"), PlyElement.describe(face, "face"),
         PlyElement.describe(edge, "edge")],
        text=text, byte_order=byte_order,
        comments=["written by plyfile for the hexmss loader tests"],
    ).write(path)

write_ply("bunny_ascii.ply", True, "=")
write_ply("bunny_le.ply", False, "<")
write_ply("bunny_be.ply", False, ">")

surface = meshio.Mesh(v, [("triangle", tris)])
meshio.write("bunny_legacy_binary.vtk", surface, binary=True)
meshio.write("bunny_legacy_ascii.vtk", surface, binary=False)
meshio.write("bunny.vtu", surface, binary=True, compression=None)

# A box 0.2 x 0.1 x 0.1 m filled with tetrahedra (5 per cube of a 4 x 2 x 2
# grid), the kind of volume mesh an FEM user has.
n = (4, 2, 2)
h = 0.05
pts = np.array([[i * h, j * h, k * h] for k in range(n[2] + 1) for j in range(n[1] + 1)
                for i in range(n[0] + 1)])
def node(i, j, k):
    return i + (n[0] + 1) * (j + (n[1] + 1) * k)
tets = []
for k in range(n[2]):
    for j in range(n[1]):
        for i in range(n[0]):
            c = [node(i + a, j + b, k + d) for d in (0, 1) for b in (0, 1) for a in (0, 1)]
            # Alternate the split so that neighbouring cubes share face diagonals.
            if (i + j + k) % 2 == 0:
                tets += [[c[0], c[1], c[2], c[4]], [c[1], c[3], c[2], c[7]],
                         [c[1], c[4], c[5], c[7]], [c[2], c[4], c[7], c[6]],
                         [c[1], c[2], c[4], c[7]]]
            else:
                tets += [[c[0], c[1], c[3], c[5]], [c[0], c[3], c[2], c[6]],
                         [c[0], c[5], c[4], c[6]], [c[3], c[5], c[6], c[7]],
                         [c[0], c[3], c[5], c[6]]]
meshio.write("box_tets.vtu", meshio.Mesh(pts, [("tetra", np.array(tets))]), binary=False)
