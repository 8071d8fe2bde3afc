"""Replays a run's point cache in Blender the way the README's steps do, and
checks every frame against the cache. Run headless:

    blender -b --factory-startup --python-exit-code 1 --python tests/blender/mesh_cache.py -- OUT STEM

OUT is a run's output folder with `[output] pc2 = true`; STEM is `skin` or
`surface`. Prints `RESULT ...` and exits with 1 when a frame differs.
"""
import struct
import sys

import bpy

out, stem = sys.argv[sys.argv.index("--") + 1:][:2]
for o in list(bpy.data.objects):
    bpy.data.objects.remove(o)
# README step 1: the rest shape, Z up, Y forward (no axis conversion).
bpy.ops.wm.obj_import(filepath=f"{out}/{stem}_rest.obj", forward_axis="Y", up_axis="Z")
obj = bpy.context.selected_objects[0]
# Steps 2 and 3: a Mesh Cache modifier on the .pc2, starting at frame 1.
mod = obj.modifiers.new("cache", "MESH_CACHE")
mod.cache_format = "PC2"
mod.filepath = f"{out}/{stem}.pc2"
mod.frame_start = 1
data = open(f"{out}/{stem}.pc2", "rb").read()
(points,) = struct.unpack("<i", data[16:20])
(samples,) = struct.unpack("<i", data[28:32])
worst = 0.0
for frame in range(1, samples + 1):
    bpy.context.scene.frame_set(frame)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    if len(mesh.vertices) != points:
        print(f"RESULT {stem}: {len(mesh.vertices)} vertices in Blender, {points} in the cache")
        sys.exit(1)
    base = 32 + 12 * points * (frame - 1)
    for i, v in enumerate(mesh.vertices):
        cached = struct.unpack("<3f", data[base + 12 * i : base + 12 * i + 12])
        co = obj.matrix_world @ v.co
        worst = max(worst, max(abs(co[k] - cached[k]) for k in range(3)))
    evaluated.to_mesh_clear()
print(f"RESULT {stem}: {samples} frames of {points} points, worst difference {worst:.3e} m")
sys.exit(0 if worst <= 1e-6 else 1)
