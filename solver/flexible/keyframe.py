"""Key-framing mode amplitudes (thesis §4.10.1), optionally holding a chosen point in place,
then handing over to the simulation at a chosen time (Fig. 4.12: the table is key-framed to
jump off a cliff, then the simulator takes over)."""

from dataclasses import dataclass

import numpy as np

from .body import FlexibleError, quat_matrix
from .ffd import lattice_weights
from .simulate import State


@dataclass
class Track:
    """Sampled motion: times (F,), t (F, 3), quat (F, 4), gamma (F, D); `handover` is the
    index of the first simulated sample (len(times) if nothing was simulated)."""
    times: np.ndarray
    t: np.ndarray
    quat: np.ndarray
    gamma: np.ndarray
    handover: int


def amplitudes_at(key_times, key_values, times):
    """Piecewise-linear amplitudes (F, D) from keys (K,) x (K, D), held before/after the keys."""
    key_times = np.asarray(key_times, float)
    key_values = np.atleast_2d(np.asarray(key_values, float))
    if len(key_times) != len(key_values):
        raise FlexibleError("one set of amplitudes per key time is needed")
    if np.any(np.diff(key_times) <= 0):
        raise FlexibleError("key times must increase")
    times = np.atleast_1d(np.asarray(times, float))
    return np.stack([np.interp(times, key_times, key_values[:, k]) for k in range(key_values.shape[1])], 1)


def keyframed(body, start, key_times, key_values, times, hold_uvw=None):
    """Rigid pose and amplitudes at `times`. With hold_uvw (lattice parameters of a point) the
    translation follows the deformation so that point stays where it was at the first time."""
    gamma = amplitudes_at(key_times, key_values, times)
    F = len(gamma)
    R = quat_matrix(start.quat)
    t = np.repeat(np.asarray(start.t, float)[None], F, axis=0)
    if hold_uvw is not None:
        w = lattice_weights(np.asarray(hold_uvw, float)[None], body.dims)[0]
        rest = w @ body.rest_lattice
        offs = np.einsum("n,dnc->dc", w, body.modes)
        y = rest + gamma @ offs                        # the held point in the body frame
        anchor = start.t + R @ (rest + start.gamma @ offs)
        t = anchor - y @ R.T
    return t, np.repeat(np.asarray(start.quat, float)[None], F, axis=0), gamma


def handover_state(body, start, key_times, key_values, time, step, hold_uvw=None):
    """The state at `time` with velocities from backward differences over `step` (eq. 4.22),
    so the key-framed motion's momentum carries into the simulation."""
    t, q, g = keyframed(body, start, key_times, key_values, [time - step, time], hold_uvw)
    R = quat_matrix(q[1])
    return State(t[1], q[1], g[1], R.T @ (t[1] - t[0]) / step, np.zeros(3), (g[1] - g[0]) / step)


def animate(simulator, start, duration, fps, keys=None, handover_time=0.0, hold_uvw=None):
    """Key-framed motion until `handover_time`, then simulation until `duration`, sampled at
    `fps`; a step generator returning (Track, simulation Result or None). `keys` is
    (key_times, key_values) or None (simulate from `start` at once)."""
    frame = 1.0 / fps
    frames = int(round(duration * fps)) + 1
    times = np.arange(frames) * frame
    h = simulator.settings.dt
    per_frame = max(1, int(round(frame / h)))
    if abs(per_frame * h - frame) > 1e-9 * max(frame, 1):
        raise FlexibleError(f"the time step ({h:g} s) must divide the frame time (1/{fps:g} s)")
    if keys is not None:
        handover = int(round(handover_time * fps))
        handover = min(max(handover, 0), frames - 1)
        t, q, g = keyframed(simulator.body, start, keys[0], keys[1], times[:handover + 1], hold_uvw)
        state = handover_state(simulator.body, start, keys[0], keys[1], times[handover], frame, hold_uvw) \
            if handover > 0 else State(t[0], q[0], g[0], start.v, start.w, start.gdot)
    else:
        handover = 0
        state = start.copy()
        t = q = g = None
    remaining = times[-1] - times[handover]
    result = None
    if remaining > 0:
        result = yield from simulator.iter_run(state, remaining, per_frame, start_time=times[handover])
        st, sq, sg = result.t[1:], result.quat[1:], result.gamma[1:]
    else:
        st = np.zeros((0, 3)); sq = np.zeros((0, 4)); sg = np.zeros((0, simulator.body.mode_count))
    if t is None:
        t, q, g = result.t[:1], result.quat[:1], result.gamma[:1]
    track = Track(times, np.vstack([t, st]), np.vstack([q, sq]), np.vstack([g, sg]), handover + 1)
    return track, result
