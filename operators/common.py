"""What every HumanAnim operator shares: the armature poll, user-error reporting, long jobs."""

import logging
import time

import bpy

from ..solver.errors import HumanAnimError
from ..solver.progress import run_to_end

log = logging.getLogger(__name__)

CHUNK_SECONDS = 0.05  # work per timer tick, so the UI stays responsive


def active_armature(context):
    obj = context.active_object
    return obj if obj is not None and obj.type == "ARMATURE" else None


class Message(str):
    """An operator's report with its level: WARNING when the result fails the motion QA."""

    level = "INFO"


def remember_sources(operator):
    """Digests of every action before an operator that makes a motion runs (`measures_motion`),
    so its QA can show the source untouched."""
    if getattr(operator, "measures_motion", False):
        from ..humananim_addon.qa.job import digest_actions
        operator._qa_digests = digest_actions()


def with_qa(operator, context, obj, summary, text, ground=None):
    """The operator's message with the motion QA of its result (`summary`'s action on `obj`),
    which is stored on the armature for the QA panel: a WARNING naming the worst bone and frames
    when it fails a threshold."""
    from ..humananim_addon.qa import job as qa
    from ..solver.qa import summary_line
    report = qa.measure_summary(obj, context.scene, summary, getattr(operator, "_qa_digests", None), ground)
    if not report.get("measures"):
        return text
    message = Message(f"{text} | {summary_line(report)}"
                      + (f": {report['warnings'][0]}" if report["warnings"] else ""))
    message.level = "WARNING" if report["passed"] is False else "INFO"
    return message


def run_reporting(operator, work):
    """Run `work()`; a user error becomes one message in the UI and the log, no traceback."""
    remember_sources(operator)
    try:
        message = work()
    except HumanAnimError as error:
        return _fail(operator, error)
    return _finish(operator, message)


def _fail(operator, error):
    log.error("%s: %s", operator.bl_idname, error)
    operator.report({"ERROR"}, str(error))
    return {"CANCELLED"}


def _finish(operator, message):
    if message:
        level = getattr(message, "level", "INFO")
        log.log(logging.WARNING if level == "WARNING" else logging.INFO, "%s: %s", operator.bl_idname, message)
        operator.report({level}, str(message))
    return {"FINISHED"}


class AddOnActiveBone:
    """Adds a force on the active bone at the current frame: an arrow Empty the animator then moves
    and turns. A subclass names it (`what`) and says how (`add = staticmethod(f)`, f(obj, scene,
    bone, frame))."""

    bl_options = {"REGISTER", "UNDO"}
    what = "force"

    @classmethod
    def poll(cls, context):
        obj = active_armature(context)
        return obj is not None and obj.data.bones.active is not None

    def execute(self, context):
        obj, scene = active_armature(context), context.scene
        bone = obj.data.bones.active.name
        self.add(obj, scene, bone, scene.frame_current)
        self.report({"INFO"}, f"{self.what} on '{bone}' at frame {scene.frame_current}: move and turn the arrow")
        return {"FINISHED"}


class RemoveActiveItem:
    """Removes the active item of a list: the subclass names the scene's settings (`settings`, or
    overrides `settings_of` for settings elsewhere), the collection (`items`) and its active
    index (`index`)."""

    bl_options = {"REGISTER", "UNDO"}
    settings = items = index = ""

    @classmethod
    def settings_of(cls, context):
        return getattr(context.scene, cls.settings)

    @classmethod
    def poll(cls, context):
        props = cls.settings_of(context)
        return props is not None and 0 <= getattr(props, cls.index) < len(getattr(props, cls.items))

    def execute(self, context):
        props = self.settings_of(context)
        items, i = getattr(props, self.items), getattr(props, self.index)
        items.remove(i)
        setattr(props, self.index, min(i, len(items) - 1))
        return {"FINISHED"}


class JobOperator:
    """An operator whose work is a generator `job(context)`: it yields progress in [0, 1] and
    returns the report message. It writes its result only after its last step, so Esc (which
    closes the generator) leaves nothing half-written. In the background (batch jobs, the bpy
    module) `execute` runs it to the end; in the UI `invoke` runs it in chunks on a timer with
    a progress bar in the HumanAnim panel."""

    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        return run_reporting(self, lambda: run_to_end(self.job(context)))

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        start_job(self, context)
        self._timer = context.window_manager.event_timer_add(0.01, window=context.window)
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            return cancel_job(self, context)
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        return step_job(self, context)


def start_job(op, context):
    remember_sources(op)
    op._steps = op.job(context)
    set_progress(context, op.bl_label, 0.0)


def step_job(op, context):
    """Advance the job for one chunk of time; FINISHED, CANCELLED or RUNNING_MODAL."""
    deadline = time.perf_counter() + CHUNK_SECONDS
    try:
        while time.perf_counter() < deadline:
            set_progress(context, op.bl_label, next(op._steps))
    except StopIteration as done:
        _end_job(op, context)
        return _finish(op, done.value)
    except HumanAnimError as error:
        _end_job(op, context)
        return _fail(op, error)
    return {"RUNNING_MODAL"}


def cancel_job(op, context):
    op._steps.close()  # the job's finally blocks restore what it changed
    _end_job(op, context)
    op.report({"WARNING"}, f"{op.bl_label}: cancelled, nothing written")
    return {"CANCELLED"}


def _end_job(op, context):
    timer = getattr(op, "_timer", None)
    if timer is not None:
        context.window_manager.event_timer_remove(timer)
    set_progress(context, "", -1.0)


def set_progress(context, label, fraction):
    """Shown by the panels while a job runs; -1 hides it."""
    wm = context.window_manager
    if hasattr(wm, "humananim_progress"):
        wm.humananim_progress = fraction
        wm.humananim_job = label
    for area in getattr(context.screen, "areas", ()):
        if area.type == "VIEW_3D":
            area.tag_redraw()


class ArmatureJob(JobOperator):
    """A job on the active armature's motion whose result the motion QA measures: a
    subclass names the bridge's job (`run = staticmethod(f)`, f(obj, scene) a generator of progress
    that returns the summary) and its one-line report (`message(summary)`)."""

    measures_motion = True

    @classmethod
    def poll(cls, context):
        return active_armature(context) is not None

    def job(self, context):
        obj = active_armature(context)
        summary = yield from self.run(obj, context.scene)
        return with_qa(self, context, obj, summary, self.message(summary))


def arrow_list_operators(what, label, settings, items, index, add):
    """The Add and Remove operators of a job's list of forces drawn as arrows (Simulate's pushes,
    Dynamic Control's impulses): `add(obj, scene, bone, frame)` makes one; removing keeps its Empty."""
    add_op = type(f"HUMANANIM_OT_add_{what}", (AddOnActiveBone, bpy.types.Operator), {
        "__doc__": f"Add {label} on the active bone: an arrow Empty in front of it, pointing into the body",
        "bl_idname": f"humananim.add_{what}", "bl_label": f"Add {what.title()}", "what": what,
        "add": staticmethod(add)})
    remove_op = type(f"HUMANANIM_OT_remove_{what}", (RemoveActiveItem, bpy.types.Operator), {
        "__doc__": f"Remove the selected {what} (its arrow Empty stays in the scene)",
        "bl_idname": f"humananim.remove_{what}", "bl_label": f"Remove {what.title()}",
        "settings": settings, "items": items, "index": index})
    return add_op, remove_op
