"""The Batch panel's settings and its background job, as Blender sees them (the thin bpy part).

The job itself is `job.BatchJob` (a `python -m humananim batch` process); `poll_job` copies its
state into the settings the panel draws. In the UI a timer calls it every half second, so
Blender never waits on the batch; headless (no timers) the tests call it directly."""

import bpy

from . import job as batch_job

JOBS = {}  # {"current": BatchJob}: the one batch this Blender session started
POLL_SECONDS = 0.5


class HumanAnimBatchSettings(bpy.types.PropertyGroup):
    inputs: bpy.props.StringProperty(
        name="Inputs", subtype="NONE", default="//mocap",
        description="A folder, a glob (//mocap/*.bvh) or a CSV/JSON manifest; several separated by ';'")
    pipeline: bpy.props.StringProperty(
        name="Pipeline", default="control --load-left 5 -> compress --degrees 0.5",
        description="Commands of `python -m humananim`, separated by '->'; each reads the previous one's result")
    out_dir: bpy.props.StringProperty(name="Output Folder", subtype="DIR_PATH", default="//batch")
    engine: bpy.props.EnumProperty(
        name="Engine", items=[("LOCAL", "Local Workers", "A Dask LocalCluster on this computer"),
                              ("CLUSTER", "Dask Cluster", "An existing Dask scheduler and its workers")])
    workers: bpy.props.IntProperty(name="Workers", default=0, min=0, max=256,
                                   description="Worker processes, one take at a time each (0: one per core)")
    scheduler: bpy.props.StringProperty(name="Scheduler", default="tcp://127.0.0.1:8786",
                                        description="The address `dask scheduler` printed")
    retries: bpy.props.IntProperty(name="Retries", default=1, min=0, max=10,
                                   description="Runs again after a crash or a timeout")
    timeout: bpy.props.FloatProperty(name="Timeout", default=600.0, min=1.0, unit="TIME_ABSOLUTE",
                                     description="Seconds a take may run")
    python: bpy.props.StringProperty(
        name="Batch Python", subtype="FILE_PATH", default="",
        description="An interpreter with bpy, dask and humananim (empty: $HUMANANIM_BATCH_PYTHON)")
    # the running job's state, written by poll_job
    running: bpy.props.BoolProperty(default=False)
    fraction: bpy.props.FloatProperty(default=0.0, min=0.0, max=1.0)
    status: bpy.props.StringProperty(default="")
    error: bpy.props.StringProperty(default="")
    report: bpy.props.StringProperty(default="")
    done: bpy.props.IntProperty(default=0)
    failed: bpy.props.IntProperty(default=0)
    total: bpy.props.IntProperty(default=0)

    @classmethod
    def register(cls):
        bpy.types.Scene.humananim_batch = bpy.props.PointerProperty(type=cls)

    @classmethod
    def unregister(cls):
        del bpy.types.Scene.humananim_batch


def start_job(settings):
    """Start the batch of these settings in the background; returns the BatchJob."""
    python = batch_job.batch_python(bpy.path.abspath(settings.python) if settings.python else "")
    if not python:
        raise ValueError("set Batch Python to an interpreter with bpy and dask (see docs/batch.md)")
    current = JOBS.get("current")
    if current is not None and current.poll()["running"]:
        raise ValueError("a batch is already running")
    inputs = ";".join(bpy.path.abspath(s.strip()) for s in settings.inputs.split(";") if s.strip())
    out_dir = bpy.path.abspath(settings.out_dir)
    argv = batch_job.batch_argv(inputs, settings.pipeline, out_dir,
                                workers=settings.workers if settings.engine == "LOCAL" else 0,
                                scheduler=settings.scheduler if settings.engine == "CLUSTER" else "",
                                retries=settings.retries, timeout=settings.timeout)
    JOBS["current"] = batch_job.BatchJob(python, argv, out_dir)
    settings.running, settings.fraction, settings.error, settings.report = True, 0.0, "", ""
    settings.status = "starting..."
    return JOBS["current"]


def poll_job(settings):
    """Copy the job's state into the settings; the seconds until the next poll, or None when the
    job has ended (a timer callback's contract)."""
    current = JOBS.get("current")
    if current is None:
        settings.running = False
        return None
    state = current.poll()
    progress = state["progress"]
    if progress:
        settings.done, settings.failed, settings.total = progress["done"], progress["failed"], progress["total"]
        settings.fraction = (progress["done"] + progress["failed"]) / max(1, progress["total"])
    settings.status = state["line"]
    if state["running"]:
        return POLL_SECONDS
    settings.running = False
    if state["error"]:
        settings.error = state["error"]
    if state["summary"]:
        s = state["summary"]
        settings.status = f"{s['done']} of {s['takes']} done, {s['failed']} failed in {s['seconds']:.0f} s"
        settings.report = state["report"]
    _redraw()
    return None


def _redraw():
    wm = getattr(bpy.context, "window_manager", None)
    for window in (wm.windows if wm else []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()
