"""Clean Up Capture in Blender (issue 26): the active action (or a file's) read as trajectories
through the rig layer (on a control rig, the deform bones as Blender evaluates them), repaired by
solver.cleanup, written as a NEW action (the source untouched; on a control rig, its controls
keyed) with the contacts found
as pose markers the Motion Queue reads ("foot.L=supporting" where a foot lands, "foot.L=angular"
where it lifts), and the repair report stored on the armature for the panel. One home for the
operator and the command line."""

import json
import time

import bpy

from ...solver.cleanup import Options, clean_up
from ...solver.errors import MotionError
from .. import action_api
from ..rig.capability import RigView

PROPERTY = "humananim_cleanup"  # the last clean-up report, JSON, on the armature object


def clean_action(obj, scene, action, options=None, name=None):
    """Clean `action` on armature `obj`; returns the summary (its `report`: per repair what
    changed and the QA measures before and after)."""
    t0 = time.perf_counter()
    options = options or Options()
    # a control rig: the deform bones as Blender evaluates them, the result keyed on its controls
    rig = RigView(obj, scene)
    traj = rig.read(action)
    if traj.frame_count < 3:
        raise MotionError(f"'{action.name}' has {traj.frame_count} frames: cleaning needs at least 3")
    cleaned, report = clean_up(rig.skeleton, traj, options)
    result = write_result(rig, cleaned, name or f"{action.name}.clean", action)
    markers = write_contact_markers(result, report.get("contacts", {}))
    summary = {"command": "cleanup", "armature": obj.name, "source_action": action.name, "action": result.name,
               "frame_range": [float(traj.frames[0]), float(traj.frames[-1])], "fps": traj.fps,
               "markers": markers, "report": report, "ms": round(1000 * (time.perf_counter() - t0), 1),
               **rig.summary()}
    obj[PROPERTY] = json.dumps(report)
    return summary


def write_result(rig, traj, name, source):
    """The cleaned motion written back as a NEW action through the rig layer (rig.capability's
    RigView): on a plain FK skeleton its bones keyed, on a control rig its controls keyed and
    Blender's evaluation of the deform bones checked against the cleaned pose (a rig that can't
    show it is refused, nothing written). The one place the clean-up writes to Blender."""
    return rig.write(traj, name, "ACTION", source)


def ground_from_object(ground_obj, depsgraph=None):
    """A solver ground (solver.cleanup.ground.TriangleMesh) from a mesh object as it is evaluated
    (modifiers applied), in world space."""
    import numpy as np
    from ...solver.cleanup.ground import TriangleMesh
    if ground_obj is None or ground_obj.type != "MESH":
        raise MotionError(f"the ground '{getattr(ground_obj, 'name', ground_obj)}' is not a mesh object")
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    evaluated = ground_obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        mesh.calc_loop_triangles()
        co = np.empty(3 * len(mesh.vertices))
        mesh.vertices.foreach_get("co", co)
        tris = np.empty(3 * len(mesh.loop_triangles), dtype=np.int32)
        mesh.loop_triangles.foreach_get("vertices", tris)
    finally:
        evaluated.to_mesh_clear()
    if not len(tris):
        raise MotionError(f"the ground '{ground_obj.name}' has no faces")
    m = np.array(ground_obj.matrix_world)
    world = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    try:
        return TriangleMesh(world, tris.reshape(-1, 3))
    except ValueError as error:
        raise MotionError(f"the ground '{ground_obj.name}': {error}") from None


def write_contact_markers(action, contacts):
    """Pose markers for the contacts {side: [[first, last frame], ...]}: the foot supports from
    its first frame and is free (angular) after its last. Returns how many were written."""
    count = 0
    for side, runs in contacts.items():
        for first, last in runs:
            _marker(action, first, f"foot.{side}=supporting")
            _marker(action, last + 1, f"foot.{side}=angular")
            count += 2
    return count


def _marker(action, frame, name):
    m = action.pose_markers.new(name)
    m.frame = int(round(frame))
    return m


def stored(obj):
    """The last clean-up report on `obj`, or None."""
    from ..qa import job as qa
    return qa.stored(obj, PROPERTY)


def lines(report):
    """One line per repair for the panel and the command's text summary."""
    out = []
    for r in report.get("repairs", []):
        if not r.get("enabled"):
            out.append(f"{r['repair']}: off")
            continue
        head = f"{r['repair']}: {r['frame_count']} frames, {len(r['bones'])} bones, largest {r['max_change_deg']:.1f} deg"
        if r["repair"] == "glitches":
            head += f", {len(r['events'])} glitches"
        elif r["repair"] == "floor":
            onto = (f"{100 * r['ground_m']:.1f} cm" if r.get("ground_m") is not None
                    else f"the ground {r.get('ground', {}).get('kind', 'surface')}")
            head += f", floor {100 * r['floor_m']:+.1f} cm moved to {onto}"
            if r.get("pelvis_lowered_cm"):
                head += f", pelvis lowered up to {r['pelvis_lowered_cm']:.1f} cm"
            if r.get("hovering_contacts"):
                head += f", {r['hovering_contacts']} contacts above it left"
        elif r["repair"] == "physics":
            head += (f", balance error up to {r['balance_error_max_cm']:.1f} cm (frame {r['balance_error_frame']:g}),"
                     f" {r['out_of_balance_frames']} frames over 1 cm" if r.get("balance_error_frame") is not None
                     else ", balanced throughout")
        qa = [f"{k} {r['qa_before'][k]['value']:g}->{r['qa_after'][k]['value']:g} {r['qa_after'][k]['unit']}"
              for k in ("slide", "penetration", "pop_velocity") if k in r.get("qa_after", {})
              and r["qa_before"][k]["value"] is not None and r["qa_after"][k]["value"] is not None]
        out.append(head + ("; " + ", ".join(qa) if qa else ""))
    return out


def active_action(obj):
    ad = obj.animation_data if obj is not None else None
    return ad.action if ad is not None else None


def assign(obj, action):
    action_api.assign_action(obj, action, action_api.object_slot(action, obj))
