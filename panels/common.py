"""Drawing the panels share: a list with its add and remove buttons, and the list of pushes,
impulses and forces on bones."""

import bpy


class HUMANANIM_UL_forces(bpy.types.UIList):
    def draw_item(self, _context, layout, _data, item, _icon, _active, _prop):
        row = layout.row(align=True)
        row.label(text=f"{item.bone or '?'} @ {item.frame}", icon="FORCE_FORCE")
        row.prop(item, "magnitude", text="")


def edited_list(layout, list_type, props, items, index, add, remove, rows=2, list_id=""):
    """A UIList of props.<items> with its add and remove operators beside it: (the buttons' column,
    for more buttons, and the active item or None)."""
    row = layout.row()
    row.template_list(list_type, list_id, props, items, props, index, rows=rows)
    buttons = row.column(align=True)
    buttons.operator(add, icon="ADD", text="")
    buttons.operator(remove, icon="REMOVE", text="")
    listed, i = getattr(props, items), getattr(props, index)
    return buttons, (listed[i] if 0 <= i < len(listed) else None)


def draw_force_list(layout, context, props, items, index, add, remove, label):
    """The list with its add and remove buttons, and the selected item's settings below."""
    layout.label(text=label)
    _, item = edited_list(layout, "HUMANANIM_UL_forces", props, items, index, add, remove, list_id=items)
    if item is None:
        return
    sub = layout.column()
    sub.use_property_split = True
    sub.prop(item, "empty")
    sub.prop_search(item, "bone", context.active_object.data, "bones")
    sub.prop(item, "frame")
    sub.prop(item, "duration")
    sub.prop(item, "magnitude", text="Impulse (N s)" if item.duration == 0.0 else "Force (N)")


def draw_loads_and_pushes(layout, context, props, options, items, index, what, label, after_ground=()):
    """The settings Simulate and Dynamic Control share (humananim_addon.forces.LoadsAndPushes): the
    source action and frames, the job's own `options` (property names, in order), the ground, the
    `after_ground` options, the scene's gravity, and the job's list of arrow forces (`items`,
    `index`, operators humananim.add_<what> and humananim.remove_<what>) under `label`."""
    col = layout.column()
    col.use_property_split = True
    col.prop(props, "action")
    row = col.row(align=True)
    row.prop(props, "frame_start")
    row.prop(props, "frame_end")
    for name in options:
        col.prop(props, name)
    col.prop(props, "ground")
    if props.ground == "HEIGHT":
        col.prop(props, "ground_height")
    for name in after_ground:
        col.prop(props, name)
    col.prop(context.scene, "gravity")
    draw_force_list(layout, context, props, items, index, f"humananim.add_{what}", f"humananim.remove_{what}", label)


CLASSES = (HUMANANIM_UL_forces,)


def draw_button_and_report(layout, operator, lines, hint):
    """A job panel's body: its button, then the last result's report lines (`lines`: None when
    nothing has run on the active object yet, and `hint` says what the button does)."""
    layout.operator(operator)
    if lines is None:
        layout.label(text=hint, icon="INFO")
        return
    col = layout.column(align=True)
    for line in lines:
        col.label(text=line)
