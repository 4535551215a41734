"""Blender meshes ⇄ numpy arrays, through foreach_get/foreach_set (never the glTF importer, which
Debian's Blender 3.4 cannot run against Debian's numpy 1.24). Positions are in the object's own
space, which is the model's space: the add-on puts objects, not points, where they belong."""
from typing import Optional

import bpy
import numpy as np

# The verdict as a colour attribute (linear RGBA): green hit, amber blend, red miss.
VERDICT_ATTRIBUTE = "animspace_verdict"
VERDICT_COLOURS = {
    "HIT": (0.05, 0.60, 0.10, 1.0),
    "BLEND": (0.90, 0.55, 0.00, 1.0),
    "MISS": (0.80, 0.02, 0.02, 1.0),
}


def positions(mesh: bpy.types.Mesh) -> np.ndarray:
    """V×3 float32 vertex positions."""
    out = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", out)
    return out.reshape(-1, 3)


def evaluated_positions(obj: bpy.types.Object, depsgraph: bpy.types.Depsgraph) -> np.ndarray:
    """V×3 float32 positions of ``obj`` after its modifiers and shape keys (a Mesh Cache modifier's
    frame, an armature's deformation) at the depsgraph's frame."""
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        return positions(mesh)
    finally:
        evaluated.to_mesh_clear()


def set_positions(mesh: bpy.types.Mesh, points: np.ndarray) -> None:
    """Writes V×3 positions; the count must be the mesh's (asserted by the callers' checks)."""
    assert points.shape == (len(mesh.vertices), 3), (points.shape, len(mesh.vertices))
    mesh.vertices.foreach_set("co", np.ascontiguousarray(points, dtype=np.float32).ravel())
    mesh.update()


def set_normals(mesh: bpy.types.Mesh, normals: Optional[np.ndarray]) -> None:
    """Per-vertex normals (V×3) as custom split normals, or back to Blender's own when None."""
    if normals is None:
        if mesh.has_custom_normals:
            mesh.free_normals_split()
        return
    unit = np.asarray(normals, dtype=np.float64)
    unit = unit / np.maximum(np.linalg.norm(unit, axis=1, keepdims=True), 1e-30)
    if hasattr(mesh, "use_auto_smooth"):  # Blender before 4.1 draws custom normals only with it on
        mesh.use_auto_smooth = True
    mesh.normals_split_custom_set_from_vertices([tuple(n) for n in unit])


def set_verdict(mesh: bpy.types.Mesh, status: str) -> None:
    """Colours every vertex by the pose's verdict (attribute ``animspace_verdict``, point domain)."""
    attribute = mesh.color_attributes.get(VERDICT_ATTRIBUTE)
    if attribute is None or attribute.domain != "POINT" or attribute.data_type != "FLOAT_COLOR":
        if attribute is not None:
            mesh.color_attributes.remove(attribute)
        attribute = mesh.color_attributes.new(VERDICT_ATTRIBUTE, "FLOAT_COLOR", "POINT")
    colour = VERDICT_COLOURS[status]
    attribute.data.foreach_set("color", np.tile(np.asarray(colour, dtype=np.float32), len(mesh.vertices)))
    mesh.color_attributes.active_color = attribute
    mesh.update()


def new_mesh(name: str, points: np.ndarray, faces: np.ndarray) -> bpy.types.Mesh:
    """A mesh of V×3 ``points`` and F×3 vertex-index ``faces`` (counter-clockwise, as the wire's)."""
    mesh = bpy.data.meshes.new(name)
    vertex_count, face_count = int(points.shape[0]), int(faces.shape[0])
    mesh.vertices.add(vertex_count)
    mesh.vertices.foreach_set("co", np.ascontiguousarray(points, dtype=np.float32).ravel())
    mesh.loops.add(face_count * 3)
    mesh.loops.foreach_set("vertex_index", np.ascontiguousarray(faces, dtype=np.int32).ravel())
    mesh.polygons.add(face_count)
    mesh.polygons.foreach_set("loop_start", np.arange(0, face_count * 3, 3, dtype=np.int32))
    mesh.polygons.foreach_set("loop_total", np.full(face_count, 3, dtype=np.int32))
    mesh.polygons.foreach_set("use_smooth", np.ones(face_count, dtype=bool))  # characters are smooth surfaces
    mesh.update(calc_edges=True)  # no validate(): it would drop degenerate faces and change the counts
    return mesh


def link(context, obj: bpy.types.Object) -> None:
    """Puts a new object in the scene's active collection."""
    collection = context.collection or context.scene.collection
    collection.objects.link(obj)
