"""Add-on preferences: which Blender renders the passes, and what is kept on disk."""

import bpy
from bpy.props import BoolProperty, IntProperty, StringProperty

from ._siblings import ADDON_MODULE


class WELCH_BIAS_AP_preferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_MODULE

    blender_binary: StringProperty(
        name="Blender Executable",
        description="Blender that renders the passes in the background; empty uses the running Blender",
        subtype="FILE_PATH",
        default="",
    )
    keep_temporary_files: BoolProperty(
        name="Keep Temporary Files",
        description="Keep the copies of the blend file that the background renders opened",
        default=False,
    )
    runs_to_keep: IntProperty(
        name="Runs to Keep",
        description="Number of most recent run folders (statistics files) kept on disk",
        default=10,
        min=1,
        soft_max=100,
    )

    def draw(self, _context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "blender_binary")
        layout.prop(self, "keep_temporary_files")
        layout.prop(self, "runs_to_keep")


def get(context):
    """The add-on's preferences, or None when the package is registered outside the add-on system (tests)."""
    addon = context.preferences.addons.get(ADDON_MODULE)
    return addon.preferences if addon is not None else None


classes = (WELCH_BIAS_AP_preferences,)

register, unregister = bpy.utils.register_classes_factory(classes)
