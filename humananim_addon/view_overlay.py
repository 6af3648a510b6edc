"""A drawing over the 3D viewport that can be switched on and off (one draw handler)."""

import bpy


class ViewOverlay:
    """`draw()` called in every 3D view after the scene (POST_VIEW) while enabled."""

    def __init__(self, draw):
        self._draw = draw
        self._handle = None

    def is_enabled(self):
        return self._handle is not None

    def enable(self):
        if self._handle is None:
            self._handle = bpy.types.SpaceView3D.draw_handler_add(self._draw, (), "WINDOW", "POST_VIEW")

    def disable(self):
        if self._handle is not None:
            bpy.types.SpaceView3D.draw_handler_remove(self._handle, "WINDOW")
            self._handle = None
