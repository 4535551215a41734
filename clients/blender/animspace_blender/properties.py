"""What the add-on keeps in a .blend: the connection and each workflow's settings on the scene
(``scene.animspace``), and on each object the add-on made, which model it shows and how
(``object.animspace``). Quantities keep the proto's / Python client's names (docs/ARCHITECTURE.md,
"One name per quantity")."""
import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty,
                       StringProperty)

ROLES = [
    ("NONE", "None", "Not made by animspace"),
    ("SOFT_CACHE_OUTPUT", "Soft-cache output", "The whole pose answered for a source mesh's key points"),
    ("SKINNED", "Animation-space mesh", "Posed by the server from its armature's pose"),
    ("LOD", "Level of detail", "One level imported from GetLod"),
]

STATUSES = [
    ("NONE", "—", "Not evaluated yet"),
    ("HIT", "HIT", "error estimate e (e_key, joined by e_check) ≤ ε_min: the subspace estimate"),
    ("BLEND", "BLEND", "ε_min < e < ε_max: α·full + (1−α)·estimate"),
    ("MISS", "MISS", "e ≥ ε_max: the full values"),
]


def _is_mesh(_settings, obj) -> bool:
    return obj.type == "MESH"


def _is_armature(_settings, obj) -> bool:
    return obj.type == "ARMATURE"


class AnimspaceModelItem(bpy.types.PropertyGroup):
    """One served model as ListModels describes its default version (``name`` is the model's)."""
    kind: StringProperty(name="Kind")
    version: IntProperty(name="Version")
    point_count: IntProperty(name="Points")
    key_point_count: IntProperty(name="Key points")
    bone_count: IntProperty(name="Bones")
    lod_level_count: IntProperty(name="Levels")
    server_engine: StringProperty(name="Server engine")
    has_tangents: BoolProperty(name="Tangents", description="Stores tangent planes, so it can pose normals")


class AnimspaceSceneSettings(bpy.types.PropertyGroup):
    # Connection (animspace.Client's arguments).
    address: StringProperty(name="Server", default="127.0.0.1:50051",
                            description="gRPC target of animspaced, host:port")
    token_file: StringProperty(name="Token file", subtype="FILE_PATH",
                               description="File holding the bearer token (the daemon's --auth-token-file); "
                                           "empty: no token")
    use_tls: BoolProperty(name="TLS", description="Connect with TLS (the daemon's --tls-cert/--tls-key)")
    root_certificates_file: StringProperty(name="CA", subtype="FILE_PATH",
                                           description="PEM of the CA that signed the server's certificate "
                                                       "(empty: the system's roots)")
    client_certificate_file: StringProperty(name="Client certificate", subtype="FILE_PATH",
                                            description="PEM chain, for a daemon started with --tls-client-ca")
    client_key_file: StringProperty(name="Client key", subtype="FILE_PATH")
    server_name: StringProperty(name="Server name",
                                description="Name the server's certificate carries, when it differs from the host")
    deadline_s: FloatProperty(name="Deadline (s)", default=10.0, min=0.1, max=3600.0,
                              description="Deadline of every call, seconds")
    health: StringProperty(name="Health", default="not checked")
    models: CollectionProperty(type=AnimspaceModelItem)
    model_index: IntProperty(name="Model")

    # The model the animation-space, LOD and thumbnail workflows use.
    model: StringProperty(name="Model", description="A model with a skeleton (ANIMATION_SPACE, or PMSC with an "
                                                    "animation-space engine) for posing, levels and thumbnails")

    # Soft-cache playback (PMSC).
    pmsc_model: StringProperty(name="PMSC model", description="A model of kind PMSC")
    source: PointerProperty(name="Source", type=bpy.types.Object, poll=_is_mesh,
                            description="Mesh whose vertices are the model's points (e.g. a Mesh Cache modifier "
                                        "reading a PC2); its evaluated key points are sent")
    output: PointerProperty(name="Output", type=bpy.types.Object, poll=_is_mesh,
                            description="Mesh the answered points are written into (made from the source "
                                        "when empty)")
    live_soft_cache: BoolProperty(name="On frame change", description="Evaluate the source's key points whenever "
                                                                     "the frame changes")
    complete_misses: BoolProperty(name="Complete misses", default=False,
                                  description="On a BLEND or MISS send the evaluated full mesh back (CompleteMiss): "
                                              "the answer blends it in and the server logs it for retraining")
    answers_as_coordinates: BoolProperty(
        name="Answers as coordinates", default=True,
        description="Take answers the client can rebuild as subspace coordinates (M numbers instead of every "
                    "point) and rebuild them here with the model's basis, fetched once and cached on disk "
                    "($ANIMSPACE_BASIS_CACHE, else ~/.cache/animspace/bases); off: every point as float32")
    status: EnumProperty(name="Verdict", items=STATUSES, default="NONE")
    key_point_error: FloatProperty(name="e_key", description="RMS key-point error of the last pose, model units",
                                   precision=6)
    check_point_error: FloatProperty(name="e_check", description="Largest distance of the last pose's estimate "
                                                                 "from its check points, model units", precision=6)
    checked: BoolProperty(name="Checked", description="The last pose was judged with its check points")
    blend_weight: FloatProperty(name="α", description="Blend weight of the last pose", precision=4)
    logged: BoolProperty(name="Logged", description="The last completed miss went to the model's miss log")

    # Animation space.
    live_skinning: BoolProperty(name="On frame change",
                                description="Pose every animation-space mesh from its armature whenever the frame "
                                            "changes")

    # Levels of detail.
    lod_selection: EnumProperty(name="Select by", items=[
        ("LEVEL", "Level", "A level by index (0 = full detail)"),
        ("BUDGET", "Vertex budget", "The finest level with at most this many vertices"),
        ("VIEW", "Camera", "The coarsest level whose error projects under the tolerance in the active camera's view "
                           "(Merry 2007 eq. 7.2)"),
    ], default="LEVEL")
    lod_level: IntProperty(name="Level", min=0, default=0)
    max_vertices: IntProperty(name="Max vertices", min=1, default=300)
    tolerance_px: FloatProperty(name="Tolerance (px)", min=0.001, default=1.0)

    # Train from animation (training.py): the offline trainers of the command line.
    train_command: StringProperty(name="animspace command", default="animspace", subtype="FILE_PATH",
                                  description="The animspace command line (build/bin/animspace), or its name on PATH")
    train_repository: StringProperty(name="Repository", subtype="DIR_PATH",
                                     description="Model repository the new version is written into (the daemon's "
                                                 "--model-repository)")
    train_model: StringProperty(name="Model name", description="The model the new version is written under")
    train_bones: IntProperty(name="Bones", min=1, max=500, default=20,
                             description="fit: rigid parts to find (bones besides the fixed root)")
    train_align: BoolProperty(name="Remove rigid motion",
                              description="train-pmsc: remove each frame's rigid motion before the subspace (--align)")
    train_sequence_folder: StringProperty(name="Sequence folder", subtype="DIR_PATH",
                                          description="Keep the sequence sent (reference.obj + frames.pc2) here; "
                                                      "empty: a temporary folder, removed after")
    train_load: BoolProperty(name="Load into the server",
                             description="Ask the connected daemon to load the new version (LoadModel, an admin "
                                         "RPC) — when it serves that repository")

    # Thumbnails.
    width_px: IntProperty(name="Width", min=1, default=256)
    height_px: IntProperty(name="Height", min=1, default=256)
    show_wireframe: BoolProperty(name="Wireframe")

    # The last failure of a handler (a handler cannot report; the panel shows this instead).
    last_error: StringProperty(name="Last error")


class AnimspaceObjectSettings(bpy.types.PropertyGroup):
    role: EnumProperty(name="Role", items=ROLES, default="NONE")
    model: StringProperty(name="Model")
    model_version: IntProperty(name="Model version")
    armature: PointerProperty(name="Armature", type=bpy.types.Object, poll=_is_armature,
                              description="The armature whose pose poses this animation-space mesh")
    include_normals: BoolProperty(name="Normals", description="Pose normals too (the model stores tangent planes)")
    lod_level: IntProperty(name="Level")
    epsilon: FloatProperty(name="ε^l", description="The level's error bound, model units", precision=6)
    tolerated_error: FloatProperty(name="Tolerated error", description="Eq. 7.2's ε for the camera's view",
                                   precision=6)


class AnimspaceBoneSettings(bpy.types.PropertyGroup):
    """Ĝ_j of the model's bone j (Merry 2007 §2.1): the posed G_j is this bone's motion since the
    rest pose times Ĝ_j, whatever head, tail and roll Blender gave the bone."""
    index: IntProperty(name="Bone index", default=-1)
    rest_transform: bpy.props.FloatVectorProperty(name="Ĝ_j", size=12,
                                                  description="Top three rows of Ĝ_j, row-major")


_CLASSES = (AnimspaceModelItem, AnimspaceSceneSettings, AnimspaceObjectSettings, AnimspaceBoneSettings)


def register() -> None:
    for cls in _CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.animspace = PointerProperty(type=AnimspaceSceneSettings)
    bpy.types.Object.animspace = PointerProperty(type=AnimspaceObjectSettings)
    bpy.types.Bone.animspace = PointerProperty(type=AnimspaceBoneSettings)


def unregister() -> None:
    del bpy.types.Bone.animspace
    del bpy.types.Object.animspace
    del bpy.types.Scene.animspace
    for cls in reversed(_CLASSES):
        bpy.utils.unregister_class(cls)
