"""Keyframe sequence operators (Huang 1996 ch. 5): equalizer, multiresolution blend, key
compression, time warp, squeeze/stretch, band analysis. Each works on the selected channels of
the active object's action (Graph Editor: the selected F-curves; 3D view in pose mode: the
selected bones; otherwise every channel) and writes a new action unless Replace Keys is on.

Every operator starts again from its source action on each run, so changing an option in the
redo panel (F9 / Adjust Last Operation) re-runs it from the source: a live preview, never
compounding."""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty, StringProperty

from ..humananim_addon import action_api, sequence
from ..humananim_addon.actions import scene_fps
from ..solver.errors import MotionError
from .common import JobOperator, run_reporting, with_qa

CHANNELS = (("AUTO", "Auto", "Graph Editor: selected F-curves; pose mode: selected bones; else everything"),
            ("CURVES", "Selected F-Curves", "The F-curves selected in the Graph Editor"),
            ("BONES", "Selected Bones", "The channels of the selected pose bones"),
            ("ALL", "All Channels", "Every F-curve of the action"))


def active_action(context):
    obj = context.active_object
    ad = obj.animation_data if obj is not None else None
    return ad.action if ad is not None else None


class SequenceOperator:
    """Shared options: which channels, new action or in place, and the source kept for redo."""

    bl_options = {"REGISTER", "UNDO"}

    channels: EnumProperty(name="Channels", items=CHANNELS, default="AUTO")
    replace: BoolProperty(name="Replace Keys", default=False,
                          description="Rewrite the keys of the source action instead of writing a new action")
    source_action: StringProperty(name="Source Action", options={"HIDDEN", "SKIP_SAVE"},
                                  description="Set on the first run, so a redo starts from the same action")

    @classmethod
    def poll(cls, context):
        return active_action(context) is not None

    def source(self, context):
        """The action to start from: remembered on the first run (redo never compounds)."""
        action = bpy.data.actions.get(self.source_action) if self.source_action else None
        if action is None:
            action = active_action(context)
            if action is None:
                raise MotionError("the active object has no action")
            self.source_action = action.name
        return action

    def selection(self, context, action):
        return sequence.selection_for_context(context, context.active_object, action, self.channels)

    def draw_common(self, layout):
        layout.prop(self, "channels")
        layout.prop(self, "replace")


def _with_note(text, summary, operator=None, context=None):
    """The message with the selection's note, and with the motion QA of the result."""
    text = f"{text} ({summary['selection_note']})" if summary.get("selection_note") else text
    if operator is None:
        return text
    return with_qa(operator, context, context.active_object, summary, text)


class HUMANANIM_OT_equalize(SequenceOperator, bpy.types.Operator):
    """Equalize the motion's frequency bands: a gain per band of the Laplacian pyramid (1 keeps, 0 removes, above 1 exaggerates)"""

    bl_idname = "humananim.equalize"
    bl_label = "Motion Equalizer"
    measures_motion = True

    mode: EnumProperty(name="Mode", items=(
        ("GAINS", "Band Gains", "A gain per band, finest first"),
        ("DENOISE", "Remove Jitter", "Remove every band above a frequency")), default="GAINS")
    levels: IntProperty(name="Bands", default=5, min=1, max=sequence.MAX_LEVELS,
                        description="Pyramid levels: bands halving in frequency (fewer on short clips)")
    gains: FloatVectorProperty(name="Gains", size=sequence.MAX_LEVELS + 1, default=(1.0,) * (sequence.MAX_LEVELS + 1),
                               min=0.0, soft_max=3.0, description="Gain of each band, finest (fastest) first, the mean pose last")
    cutoff_hz: FloatProperty(name="Cutoff", default=10.0, min=0.01, soft_max=60.0, subtype="NONE",
                             description="Hz: bands wholly above are removed")

    def execute(self, context):
        def work():
            obj, action = context.active_object, self.source(context)
            sel = self.selection(context, action)
            levels = sequence.default_levels(len(sequence.action_frames(action)), self.levels)
            gains = list(self.gains)[:levels] + [self.gains[self.levels]]  # the top keeps its own slider
            s = sequence.equalize(obj, context.scene, action, sel, gains=gains, levels=levels,
                                  cutoff_hz=self.cutoff_hz if self.mode == "DENOISE" else None,
                                  replace=self.replace)
            return _with_note(f"'{s['action']}': {s['groups']} channels over {levels} bands, largest change "
                              f"{s['largest_change_deg']:.2f} deg, {s['largest_change_cm']:.2f} cm", s, self, context)
        return run_reporting(self, work)

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "mode")
        layout.prop(self, "levels")
        if self.mode == "DENOISE":
            layout.prop(self, "cutoff_hz")
        else:
            labels = sequence.band_labels(scene_fps(context.scene), self.levels)
            col = layout.column(align=True)
            for i in range(self.levels):
                col.prop(self, "gains", index=i, text=labels[i])
            col.prop(self, "gains", index=self.levels, text=labels[-1])
        self.draw_common(layout)


class HUMANANIM_OT_multires_blend(SequenceOperator, bpy.types.Operator):
    """Join the active action and a second one (or two NLA strips) band by band, so the transition suits every frequency"""

    bl_idname = "humananim.multires_blend"
    bl_label = "Multiresolution Blend"
    measures_motion = True

    second: EnumProperty(name="Blend With", items=(
        ("ACTION", "Action", "The active action, then another action"),
        ("NLA", "NLA Strips", "The two selected NLA strips (else the first two), placed as in the NLA")),
        default="ACTION")
    action_b: StringProperty(name="Second Action", description="The action that follows the active one")
    start: IntProperty(name="Start", default=0,
                       description="Frame of the active action where the second starts (unset: its end minus the window)")
    window: IntProperty(name="Window", default=12, min=0, description="Transition length in frames (0: the whole overlap)")
    method: EnumProperty(name="Method", items=(
        ("MULTIRESOLUTION", "Multiresolution", "Blend each band of the pyramids (Huang table 5-5)"),
        ("WEIGHTED", "Weighted Sum", "A plain eased cross-fade (eq. 5-8)")), default="MULTIRESOLUTION")
    mask: EnumProperty(name="Mask", items=(
        ("WINDOW", "Same Window", "Every band crosses over in the same window (the thesis)"),
        ("GAUSSIAN", "Widening", "Slower bands cross over in wider windows (Burt and Adelson)")), default="WINDOW")
    levels: IntProperty(name="Levels", default=0, min=0, max=sequence.MAX_LEVELS, description="0: from the window")

    def execute(self, context):
        def work():
            obj, scene = context.active_object, context.scene
            range_a = range_b = None
            if self.second == "NLA":
                a, range_a, b, range_b, start = sequence.nla_pair(obj)
                self.source_action = a.name
            else:
                a = self.source(context)
                b = bpy.data.actions.get(self.action_b)
                if b is None:
                    raise MotionError(f"no action named '{self.action_b}' to blend with" if self.action_b
                                      else "choose the second action")
                start = self.start if self.properties.is_property_set("start") else a.frame_range[1] - self.window
            sel = self.selection(context, a)
            s = sequence.blend(obj, scene, a, b, start, self.window, self.method, self.mask, self.levels or None,
                               sel, range_a, range_b, self.replace)
            return _with_note(f"'{s['action']}': '{s['source_action']}' then '{s['action_b']}' from frame "
                              f"{s['start']:g}, frames {s['frames'][0]:g}-{s['frames'][1]:g}", s, self, context)
        return run_reporting(self, work)

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "second")
        if self.second == "ACTION":
            layout.prop_search(self, "action_b", bpy.data, "actions")
            layout.prop(self, "start")
        layout.prop(self, "window")
        layout.prop(self, "method")
        if self.method == "MULTIRESOLUTION":
            layout.prop(self, "mask")
            layout.prop(self, "levels")
        self.draw_common(layout)


class HUMANANIM_OT_compress_keys(SequenceOperator, JobOperator, bpy.types.Operator):
    """Replace dense keys by few Bezier keys that stay within the tolerances on every frame"""

    bl_idname = "humananim.compress_keys"
    bl_label = "Compress Keys"
    measures_motion = True
    bl_options = {"REGISTER", "UNDO"}

    degrees: FloatProperty(name="Rotation", default=0.5, min=0.001, soft_max=10.0,
                           description="Largest rotation error of any bone on any frame, in degrees")
    centimetres: FloatProperty(name="Location", default=0.5, min=0.001, soft_max=10.0,
                               description="Largest location error on any frame, in centimetres")
    value_tolerance: FloatProperty(name="Other Curves", default=0.001, min=0.0, precision=4,
                                   description="Largest error of curves that are no rotation or location, in their units")
    tail_cm: FloatProperty(name="Bone Tails", default=0.0, min=0.0, soft_max=10.0,
                           description="Also keep every bone's tail, and a point 10 cm beyond it, within this "
                                       "many centimetres on every frame (0: off)")
    feet_mm: FloatProperty(name="Planted Feet", default=sequence.FEET_MM, min=0.0, soft_max=20.0,
                           description="Keep every foot point the source plants within this many millimetres of "
                                       "the source, by tightening only the legs' tolerances (0: off)")
    method: EnumProperty(name="Method", items=(
        ("HERMITE", "Hermite Keys", "Key reduction by cubic Hermite segments (Huang 5.8): fewest keys"),
        ("PYRAMID", "Pyramid Levels", "Keys on the coarsest pyramid level within the tolerance (Huang 5.5)")),
        default="HERMITE")

    def job(self, context):
        obj, action = context.active_object, self.source(context)
        sel = self.selection(context, action)
        s = yield from sequence.iter_compress(obj, context.scene, action, sel, self.degrees, self.centimetres,
                                              self.value_tolerance, self.method, self.replace, self.tail_cm,
                                              self.feet_mm)
        text = (f"'{s['action']}': {s['keys_before']} -> {s['keys_after']} keys ({s['ratio']:g}x), largest error "
                f"{s['max_error_deg']:.3f} deg, {s['max_error_cm']:.3f} cm")
        if "tail_error_cm" in s:
            text += f", bone tail {s['tail_error_cm']:.2f} cm, 10 cm beyond {s['tail_10cm_error_cm']:.2f} cm"
        if "feet_error_mm" in s:
            text += f", planted feet within {s['feet_error_mm']:.1f} mm"
        return _with_note(text, s, self, context)

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        for name in ("method", "degrees", "centimetres", "tail_cm", "feet_mm", "value_tolerance"):
            layout.prop(self, name)
        self.draw_common(layout)


class HUMANANIM_OT_time_warp(SequenceOperator, bpy.types.Operator):
    """Retime the action through a smooth monotone warp: markers named 'warp:<old frame>' say where that moment now happens"""

    bl_idname = "humananim.time_warp"
    bl_label = "Time Warp"
    measures_motion = True

    constraints: EnumProperty(name="Constraints", items=(
        ("MARKERS", "Warp Markers", "Timeline and pose markers named 'warp:<old frame>', placed at the new frame"),
        ("MAP", "Frame Map", "Pairs OLD:NEW typed below")), default="MARKERS")
    warp_map: StringProperty(name="Map", description="OLD:NEW frame pairs, e.g. '40:30, 80:90'")
    keep_ends: BoolProperty(name="Keep Ends", default=True,
                            description="The action's first and last frames stay where they are unless constrained")
    resample: BoolProperty(name="Key Every Frame", default=False,
                           description="Key the warped motion on every frame instead of moving the existing keys")

    def execute(self, context):
        def work():
            obj, scene, action = context.active_object, context.scene, self.source(context)
            pairs = (sequence.marker_constraints(scene, action) if self.constraints == "MARKERS"
                     else sequence.parse_map(self.warp_map))
            sel = self.selection(context, action)
            s = sequence.warp(obj, scene, action, sel, pairs, self.keep_ends, self.resample, self.replace)
            moves = ", ".join(f"{o:g}->{n:g}" for o, n in s["constraints"])
            return _with_note(f"'{s['action']}': {moves}; frames {s['frames'][0]:g}-{s['frames'][1]:g}", s, self, context)
        return run_reporting(self, work)

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "constraints")
        if self.constraints == "MAP":
            layout.prop(self, "warp_map")
        layout.prop(self, "keep_ends")
        layout.prop(self, "resample")
        self.draw_common(layout)


class HUMANANIM_OT_add_warp_marker(bpy.types.Operator):
    """Add a timeline marker 'warp:<frame>' at the current frame; move it to where this moment should happen, then Time Warp"""

    bl_idname = "humananim.add_warp_marker"
    bl_label = "Add Warp Marker"
    bl_options = {"REGISTER", "UNDO"}

    on_action: BoolProperty(name="On the Action", default=False,
                            description="Add a pose marker of the action instead of a scene marker")

    @classmethod
    def poll(cls, context):
        return context.scene is not None

    def execute(self, context):
        frame = context.scene.frame_current
        if self.on_action:
            action = active_action(context)
            if action is None:
                self.report({"WARNING"}, "the active object has no action")
                return {"CANCELLED"}
            marker = action.pose_markers.new(f"warp:{frame}")
        else:
            marker = context.scene.timeline_markers.new(f"warp:{frame}", frame=frame)
        marker.frame = frame
        self.report({"INFO"}, f"'{marker.name}': move it to the frame where this moment should happen")
        return {"FINISHED"}


class HUMANANIM_OT_squeeze_stretch(SequenceOperator, bpy.types.Operator):
    """Move the keys at one frame to a new frame; keys between two limits keep their proportions (squeeze and stretch)"""

    bl_idname = "humananim.squeeze_stretch"
    bl_label = "Squeeze/Stretch Keys"

    frame: FloatProperty(name="Key Frame", description="The keys to move (unset: the current frame)")
    new_frame: FloatProperty(name="New Frame", description="Where they go")
    left_limit: FloatProperty(name="Left Limit", description="Keys before it stay (unset: the action's start)")
    right_limit: FloatProperty(name="Right Limit", description="Keys after it stay (unset: the action's end)")

    def invoke(self, context, event):
        action = active_action(context)
        for name, value in (("frame", context.scene.frame_current), ("new_frame", context.scene.frame_current),
                            ("left_limit", action.frame_range[0]), ("right_limit", action.frame_range[1])):
            if not self.properties.is_property_set(name):
                setattr(self, name, value)
        return context.window_manager.invoke_props_dialog(self) if context.window else self.execute(context)

    def execute(self, context):
        def work():
            obj, scene, action = context.active_object, context.scene, self.source(context)
            is_set = self.properties.is_property_set
            frame = self.frame if is_set("frame") else scene.frame_current
            left = self.left_limit if is_set("left_limit") else action.frame_range[0]
            right = self.right_limit if is_set("right_limit") else action.frame_range[1]
            sel = self.selection(context, action)
            s = sequence.squeeze_stretch(obj, scene, action, sel, frame, self.new_frame, left, right, self.replace)
            return _with_note(f"'{s['action']}': keys at {frame:g} moved to {self.new_frame:g} between "
                              f"{left:g} and {right:g} ({s['keys_moved']} keys moved)", s)
        return run_reporting(self, work)

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        for name in ("frame", "new_frame", "left_limit", "right_limit"):
            layout.prop(self, name)
        self.draw_common(layout)


class HUMANANIM_OT_analyse_bands(bpy.types.Operator):
    """Measure the energy (RMS) of each frequency band of the active F-curve, or of the active bone's rotation"""

    bl_idname = "humananim.analyse_bands"
    bl_label = "Analyse Bands"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        return active_action(context) is not None

    def execute(self, context):
        def work():
            obj, scene, action = context.active_object, context.scene, active_action(context)
            group = analysed_group(context, obj, action)
            props = scene.humananim_sequence
            labels, energies, units = sequence.band_energies(obj, scene, action, group, props.levels or None)
            sequence.store_bands(props, group.label, labels, energies, units)
            return f"{group.label}: " + ", ".join(f"{e:.3g}" for e in energies) + (f" {units}" if units else "")
        return run_reporting(self, work)


def analysed_group(context, obj, action):
    """The active F-curve (Graph Editor) with its whole rotation, else the active pose bone's
    rotation (or location), else the first curve of the action."""
    scene = context.scene
    fc = getattr(context, "active_editable_fcurve", None)
    curves = action_api.fcurves_of(action, obj)
    if fc is not None and any(c == fc for c in curves):
        sel = sequence.select_channels(obj, scene, action, "PATHS", paths=[fc.data_path])
        for g in sel.groups:
            if any(c is not None and c.array_index == fc.array_index for c in g.fcurves):
                return g
    bone = obj.data.bones.active if obj.type == "ARMATURE" else None
    if bone is not None:
        sel = sequence.select_channels(obj, scene, action, "BONES", [bone.name])
        mine = [g for g in sel.groups if g.bone == bone.name]
        if mine:
            return next((g for g in mine if g.kind in ("quaternion", "euler", "axis_angle")), mine[0])
    if not curves:
        raise MotionError(f"'{action.name}' has no F-curves")
    return sequence.select_channels(obj, scene, action, "PATHS", paths=[curves[0].data_path]).groups[0]


CLASSES = (HUMANANIM_OT_equalize, HUMANANIM_OT_multires_blend, HUMANANIM_OT_compress_keys, HUMANANIM_OT_time_warp,
           HUMANANIM_OT_add_warp_marker, HUMANANIM_OT_squeeze_stretch, HUMANANIM_OT_analyse_bands)
