"""The sidebar (N-panel) tab "animspace": the connection and one sub-panel per workflow."""
import functools
from typing import Callable

import bpy

from . import mesh_data, registry


class ANIMSPACE_UL_models(bpy.types.UIList):
    def draw_item(self, context, layout, data, item, icon, active_data, active_property, index=0, flt_flag=0):
        row = layout.row(align=True)
        row.label(text=item.name)
        detail = f"{item.kind.lower()}, {item.point_count} pts"
        if item.key_point_count:
            detail += f", {item.key_point_count} keys"
        if item.bone_count:
            detail += f", {item.bone_count} bones"
        if item.lod_level_count:
            detail += f", {item.lod_level_count} levels"
        row.label(text=detail)


class _Panel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "animspace"


class _SubPanel(_Panel):
    """A workflow's sub-panel under the connection's."""
    bl_parent_id = "ANIMSPACE_PT_connection"


def _settings_draw(draw: Callable) -> Callable:
    """A panel's ``draw(self, context)`` made from ``draw(context, layout, settings)``, given the
    panel's layout and the scene's settings."""

    @functools.wraps(draw)
    def panel_draw(self, context):
        draw(context, self.layout, context.scene.animspace)

    return panel_draw


def _props(layout, settings, *props: str):
    """``settings``' properties ``props`` into ``layout``, one after the other; returns it."""
    for prop in props:
        layout.prop(settings, prop)
    return layout


class ANIMSPACE_PT_connection(_Panel, bpy.types.Panel):
    bl_label = "animspace"

    @_settings_draw
    def draw(context, layout, settings):
        _props(layout, settings, "address", "token_file", "use_tls")
        if settings.use_tls:
            _props(layout.box(), settings, "root_certificates_file", "client_certificate_file", "client_key_file",
                   "server_name")
        layout.prop(settings, "deadline_s")
        row = layout.row()
        row.operator("animspace.connect", icon="URL")
        row.label(text=f"Health: {settings.health}")
        layout.template_list("ANIMSPACE_UL_models", "", settings, "models", settings, "model_index", rows=3)
        if settings.last_error:
            layout.label(text=settings.last_error, icon="ERROR")


class ANIMSPACE_PT_soft_cache(_SubPanel, bpy.types.Panel):
    bl_label = "Soft-cache playback"

    @_settings_draw
    def draw(context, layout, settings):
        layout.prop_search(settings, "pmsc_model", settings, "models")
        _props(layout, settings, "source", "output")
        _props(layout.row(), settings, "live_soft_cache", "complete_misses")
        _props(layout, settings, "answers_as_coordinates")
        row = layout.row()
        row.operator("animspace.soft_cache_frame")
        row.operator("animspace.soft_cache_bake")
        box = layout.box()
        box.label(text=f"Verdict: {settings.status if settings.status != 'NONE' else '—'}"
                       + (" (logged)" if settings.logged else ""))
        check = f"{settings.check_point_error:.6g}" if settings.checked else "—"
        box.label(text=f"e_key: {settings.key_point_error:.6g}    e_check: {check}    α: {settings.blend_weight:.4g}")
        box.label(text=f"Colour attribute: {mesh_data.VERDICT_ATTRIBUTE}")


class ANIMSPACE_PT_skinning(_SubPanel, bpy.types.Panel):
    bl_label = "Animation space"

    @_settings_draw
    def draw(context, layout, settings):
        layout.prop_search(settings, "model", settings, "models")
        layout.operator("animspace.build_skinned")
        _props(layout.row(), settings, "live_skinning").operator("animspace.pose_skinned")
        layout.operator("animspace.bake_skinned")


class ANIMSPACE_PT_lod(_SubPanel, bpy.types.Panel):
    bl_label = "Level of detail"

    @_settings_draw
    def draw(context, layout, settings):
        layout.prop(settings, "lod_selection", expand=True)
        if settings.lod_selection == "LEVEL":
            layout.prop(settings, "lod_level")
        elif settings.lod_selection == "BUDGET":
            layout.prop(settings, "max_vertices")
        else:
            layout.prop(settings, "tolerance_px")
        layout.operator("animspace.import_lod")
        obj = context.active_object
        if obj is not None and obj.animspace.role == "LOD":
            layout.label(text=f"Level {obj.animspace.lod_level}: ε^l {obj.animspace.epsilon:.6g}")


class ANIMSPACE_PT_training(_SubPanel, bpy.types.Panel):
    bl_label = "Train from animation"

    @_settings_draw
    def draw(context, layout, settings):
        _props(layout, settings, "train_command", "train_repository", "train_model", "train_sequence_folder")
        _props(layout.row(), settings, "train_bones", "train_align")
        layout.prop(settings, "train_load")
        row = layout.row()
        row.operator("animspace.train_from_animation", text="fit").tool = "FIT"
        row.operator("animspace.train_from_animation", text="train-pmsc").tool = "TRAIN_PMSC"


class ANIMSPACE_PT_thumbnail(_SubPanel, bpy.types.Panel):
    bl_label = "Thumbnail"

    @_settings_draw
    def draw(context, layout, settings):
        _props(layout.row(align=True), settings, "width_px", "height_px")
        layout.prop(settings, "show_wireframe")
        layout.operator("animspace.thumbnail", icon="IMAGE_DATA")


_CLASSES = (ANIMSPACE_UL_models, ANIMSPACE_PT_connection, ANIMSPACE_PT_soft_cache, ANIMSPACE_PT_skinning,
            ANIMSPACE_PT_lod, ANIMSPACE_PT_training, ANIMSPACE_PT_thumbnail)

register, unregister = registry.for_classes(_CLASSES)
