"""The live capture's viewport drawing: the hand's bones in its grasp state's colour and its
sensors as points (lighter when touching), drawn with the gpu module over the 3D view while a
capture runs (job.LIVE)."""

import logging

import numpy as np

from ...solver.hands.grasp_automaton import SENSOR_COLOURS
from ..view_overlay import ViewOverlay

log = logging.getLogger(__name__)


# -- the overlay: the hand's state colour and its sensors (lighter when touching) ----------------------------
def enable_overlay():
    _OVERLAY.enable()


def disable_overlay():
    _OVERLAY.disable()


def overlay_geometry(live):
    """[(kind, coords, colour)]: the hand's bones as lines in the state's colour, sensors as points."""
    out = []
    for state, colour, centres, touching, world, ga in (live.overlay or []):
        sk = live.skeleton
        joints = [j for chain in ga.chains.values() for j in chain] + ([ga.hand] if ga.hand is not None else [])
        segs = []
        for j in joints:
            head = world[j, :3, 3]
            segs += [head, head + world[j, :3, 1] * sk.lengths[j]]
        out.append(("LINES", np.array(segs), colour))
        for flag in (False, True):
            pts = centres[touching == flag]
            if len(pts):
                out.append(("POINTS", pts, SENSOR_COLOURS[flag]))
    return out


def _draw():
    from .job import LIVE
    try:
        if LIVE is None or not LIVE.overlay:
            return
        import gpu
        from gpu_extras.batch import batch_for_shader
        gpu.state.blend_set("ALPHA")
        gpu.state.depth_test_set("NONE")
        for kind, coords, colour in overlay_geometry(LIVE):
            if kind == "LINES":
                shader = gpu.shader.from_builtin("POLYLINE_UNIFORM_COLOR")
                vp = gpu.state.viewport_get()
                shader.bind()
                shader.uniform_float("viewportSize", (vp[2], vp[3]))
                shader.uniform_float("lineWidth", 4.0)
            else:
                shader = gpu.shader.from_builtin("UNIFORM_COLOR")
                shader.bind()
                gpu.state.point_size_set(9.0)
            shader.uniform_float("color", colour)
            batch_for_shader(shader, kind, {"pos": np.asarray(coords, np.float32)}).draw(shader)
        gpu.state.blend_set("NONE")
    except Exception:
        log.exception("capture overlay")


_OVERLAY = ViewOverlay(_draw)
