"""The thesis's scene (Oshita 2003, sec. 3.6): one character punches another. The puncher's fist
is a collider sphere of the fist's (effective) mass driven at a given speed into the victim's
stomach and back; the victim's dynamic controller receives the hit through its swept contacts
(motion_control.collisions.Collisions.collide) and the reactions of sec. 3.5 follow from what the hit did
to its root. Used by the tests, the benchmark and the CLI's demo; in Blender the fist is the
attacker's armature or a mesh set as the Dynamic Control panel's collider."""

import numpy as np

from ..motion_control import Collider
from .keyframed import forward_of


def target_point(sk, tr, frame, bone=None):
    """World midpoint (3,) of `bone` (default: the lowest spine bone above the hips, the stomach)
    at `frame`."""
    j = sk.index(bone if bone is not None else sk.roles.chain("spine")[0])
    w = tr.world_frames(sk)[frame]
    return w[j][:3, 3] + 0.5 * sk.lengths[j] * w[j][:3, 1]


def punch_path(times, hit_time, speed, reach, depth, hold=0.1, pull=1.5):
    """Distance travelled (F,) and velocity (F,) along the punch's line: at rest `reach` metres
    before the contact point, out at `speed` m/s to `depth` past the contact (reached at hit_time
    + depth / speed), held there `hold` s (a fist sampled at 30 fps shows its extension on a frame
    however fast it flies), then back at `pull` m/s to where it started."""
    t0 = hit_time - reach / speed
    t1 = hit_time + depth / speed
    t2 = t1 + hold
    out = np.clip(times - t0, 0.0, None) * speed
    back = reach + depth - (times - t2) * pull
    x = np.where(times <= t1, out, np.where(times <= t2, reach + depth, np.maximum(back, 0.0)))
    v = np.where(times < t0, 0.0, np.where(times <= t1, speed, np.where((times > t2) & (back > 0.0), -pull, 0.0)))
    return np.minimum(x, reach + depth), v


def punch_collider(sk, tr, speed, mass=3.0, hit_time=0.3, radius=0.05, reach=0.4, depth=0.05,
                   direction=None, bone=None, body_radius=0.1):
    """A fist (one sphere of `radius`, `mass` kg) punching the stomach (or `bone`) of the motion
    `tr` from the front (or along the world `direction` it travels) at `speed` m/s: its surface
    touches the bone's contact sphere (`body_radius`) at `hit_time` s (rounded to a frame).
    Returns a Collider on tr's frames."""
    times = tr.times - tr.times[0]
    f = int(np.clip(round(hit_time * tr.fps), 0, tr.frame_count - 1))
    hit_time = times[f]  # the contact on a frame, and the fist at full speed over the next one:
    depth = max(depth, speed / tr.fps)  # its sampled path then carries its speed into the body
    target = target_point(sk, tr, f, bone)
    d = -forward_of(sk, tr) if direction is None else np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    contact = target - d * (body_radius + radius)  # the fist's centre when it touches
    x, v = punch_path(times, hit_time, speed, reach, depth)
    start = contact - d * reach
    pos = start[None] + x[:, None] * d[None]
    vel = v[:, None] * d[None]
    return Collider(pos[:, None, :], np.array([radius]), vel[:, None, :], mass=float(mass))
