# Blender's own unwrappers on a mesh, headless, for `animspace-bench atlas` (issue #37): the
# baselines our atlas is compared with. Run as
#   blender -b --factory-startup --python bench/blender_unwrap.py -- IN.obj OUT.txt METHOD MARGIN [SEAMS.txt]
# METHOD: smart (bpy.ops.uv.smart_project, Blender's defaults but the island margin) or angle
# (bpy.ops.uv.unwrap(method='ANGLE_BASED') after marking as seams the edges listed in SEAMS.txt,
# one "a b" vertex pair per line, zero-based OBJ vertex indices). OUT.txt: one line per face, in
# the OBJ's face order: its three zero-based vertex indices, then u v of each corner.
import sys

import bmesh
import bpy

argv = sys.argv[sys.argv.index("--") + 1:]
obj_path, out_path, method, margin = argv[0], argv[1], argv[2], float(argv[3])
seams_path = argv[4] if len(argv) > 4 else None

for o in list(bpy.data.objects):
    bpy.data.objects.remove(o, do_unlink=True)
bpy.ops.wm.obj_import(filepath=obj_path, forward_axis="Y", up_axis="Z")
obj = bpy.context.selected_objects[0]
bpy.context.view_layer.objects.active = obj
mesh = obj.data
if len(mesh.polygons) == 0:
    sys.exit("no faces imported")

if seams_path:
    pairs = set()
    with open(seams_path) as f:
        for line in f:
            a, b = map(int, line.split())
            pairs.add((min(a, b), max(a, b)))
    for e in mesh.edges:
        a, b = e.vertices
        e.use_seam = (min(a, b), max(a, b)) in pairs

bpy.ops.object.mode_set(mode="EDIT")
bpy.ops.mesh.select_all(action="SELECT")
if method == "smart":
    bpy.ops.uv.smart_project(island_margin=margin)
elif method == "angle":
    bpy.ops.uv.unwrap(method="ANGLE_BASED", margin=margin)
else:
    sys.exit("unknown method " + method)
bpy.ops.object.mode_set(mode="OBJECT")

uv = mesh.uv_layers.active.data
with open(out_path, "w") as out:
    for p in mesh.polygons:
        if p.loop_total != 3:
            sys.exit("face %d is not a triangle" % p.index)
        loops = list(range(p.loop_start, p.loop_start + 3))
        vs = [mesh.loops[l].vertex_index for l in loops]
        out.write(" ".join(str(v) for v in vs) + " " +
                  " ".join("%.9g %.9g" % (uv[l].uv[0], uv[l].uv[1]) for l in loops) + "\n")
