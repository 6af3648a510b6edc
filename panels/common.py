"""Drawing the panels share: the list of pushes, impulses and forces on bones."""

import bpy


class HUMANANIM_UL_forces(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.label(text=f"{item.bone or '?'} @ {item.frame}", icon="FORCE_FORCE")
        row.prop(item, "magnitude", text="")


def draw_force_list(layout, context, props, items, index, add, remove, label):
    """The list with its add and remove buttons, and the selected item's settings below."""
    layout.label(text=label)
    row = layout.row()
    row.template_list("HUMANANIM_UL_forces", items, props, items, props, index, rows=2)
    buttons = row.column(align=True)
    buttons.operator(add, icon="ADD", text="")
    buttons.operator(remove, icon="REMOVE", text="")
    listed, i = getattr(props, items), getattr(props, index)
    if not 0 <= i < len(listed):
        return
    item = listed[i]
    sub = layout.column()
    sub.use_property_split = True
    sub.prop(item, "empty")
    sub.prop_search(item, "bone", context.active_object.data, "bones")
    sub.prop(item, "frame")
    sub.prop(item, "duration")
    sub.prop(item, "magnitude", text="Impulse (N s)" if item.duration == 0.0 else "Force (N)")


CLASSES = (HUMANANIM_UL_forces,)
