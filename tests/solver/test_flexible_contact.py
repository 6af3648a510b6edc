"""Ground, friction, springs and key-framing of flexible characters (thesis §4.6, §4.9, §4.10.1)."""

import numpy as np
import pytest

from humananim.solver.flexible import (FlexibleBody, FlexibleError, Ground, ModeGains, Settings, Simulator,
                                       Spring)
from humananim.solver.flexible.body import quat_matrix
from humananim.solver.flexible.demo import table_body
from humananim.solver.flexible.ffd import grid_points
from humananim.solver.flexible.keyframe import animate, keyframed
from humananim.solver.flexible.simulate import State
from humananim.solver.progress import run_to_end


def box_body(size=(0.4, 0.4, 0.2), mass=5.0):
    """A rigid box (no modes): its 8 corners in a 2x2x2 lattice."""
    rest = grid_points((2, 2, 2), size, -0.5 * np.asarray(size))
    return FlexibleBody((2, 2, 2), rest, np.zeros((0, 8, 3)), [],
                        grid_points((2, 2, 2)), np.full(8, mass / 8))


def lowest(body, st):
    return body.positions(st.t, quat_matrix(st.quat), st.gamma)[:, 2].min()


def test_dropped_table_comes_to_rest_without_sinking():
    body = table_body()
    sim = Simulator(body, ModeGains.from_frequency(body, 3.0, 0.3), Settings(ground=Ground.flat()))
    start = State.rest(4, t=(0, 0, 0.3 + 0.5))
    result = sim.run(start, 4.0, record_every=10)
    end = result.final
    assert result.com[:, 2].min() < 0.3                      # it did fall
    assert np.linalg.norm(sim.com_velocity(end)) < 0.01       # and rests
    assert -0.01 < lowest(body, end) < 0.0                   # sinking under 1 cm
    assert np.abs(end.gamma).max() < 0.2                      # sagging under its weight only


@pytest.mark.parametrize("mu", [0.25, 0.6])
def test_friction_on_a_slope_holds_or_slides_as_coulomb_says(mu):
    angle = np.radians(20.0)                                  # tan = 0.364
    body = box_body()
    ground = Ground.slope(angle, friction=mu)
    sim = Simulator(body, settings=Settings(ground=ground))
    q = np.array([np.cos(-angle / 2), 0.0, np.sin(-angle / 2), 0.0])  # aligned with the slope
    normal = np.array([-np.sin(angle), 0, np.cos(angle)])
    downhill = np.array([-np.cos(angle), 0, -np.sin(angle)])
    start = State(0.1 * normal, q, np.zeros(0), np.zeros(3), np.zeros(3), np.zeros(0))
    result = sim.run(start, 2.5, record_every=20)
    along = (result.com - result.com[0]) @ downhill
    t = result.times
    if mu > np.tan(angle):
        assert abs(along[-1] - along[t >= 0.5][0]) < 0.005    # holds: no creep after settling
    else:
        # slides with a = g (sin - mu cos): fit along = a/2 t^2 + v0 t + x0 after settling
        sel = t >= 0.5
        a = 2 * np.polyfit(t[sel], along[sel], 2)[0]
        expected = 9.81 * (np.sin(angle) - mu * np.cos(angle))
        assert abs(a - expected) < 0.05 * expected
    # resting on the slope, not in it
    pts = body.positions(result.final.t, quat_matrix(result.final.quat), result.final.gamma)
    assert (pts @ normal).min() > -0.01


def test_spring_to_a_point_holds_the_weight():
    body = table_body()
    anchor = (0.0, 0.0, 2.0)
    k = 2000.0
    spring = Spring(uvw=(0.5, 0.5, 1.0), anchor=anchor, stiffness=k, damping=80.0)
    sim = Simulator(body, ModeGains.from_frequency(body, 4.0, 0.5), Settings(springs=[spring]))
    start = State.rest(4, t=(0, 0, 2.0 - 0.3))               # top centre at the anchor
    result = sim.run(start, 6.0)
    end = result.final
    from humananim.solver.flexible.ffd import lattice_weights
    w = lattice_weights([spring.uvw], body.dims)[0]
    attached = end.t + quat_matrix(end.quat) @ (w @ body.lattice_points(end.gamma))
    stretch = 2.0 - attached[2]
    assert np.abs(attached[:2]).max() < 1e-6
    assert abs(stretch - body.total_mass * 9.81 / k) < 0.01 * body.total_mass * 9.81 / k + 2e-3


def test_keyframed_amplitudes_hold_a_point_in_place():
    body = table_body()
    start = State.rest(4, t=(0.2, 0.1, 0.3))
    start.quat = np.array([np.cos(0.2), 0, 0, np.sin(0.2)])
    keys = ([0.0, 1.0], [[0, 0, 0, 0], [0.0, 0.8, -0.5, 0.6]])   # bend, squash, stretch
    hold = (1.0, 0.0, 0.0)                                        # the front-left foot... of the lattice
    times = np.linspace(0, 1, 11)
    t, q, g = keyframed(body, start, *keys, times, hold_uvw=hold)
    from humananim.solver.flexible.ffd import lattice_weights
    w = lattice_weights([hold], body.dims)[0]
    pts = [t[i] + quat_matrix(q[i]) @ (w @ body.lattice_points(g[i])) for i in range(len(times))]
    assert np.abs(np.array(pts) - pts[0]).max() < 1e-12
    assert np.abs(t - t[0]).max() > 0.01                          # the body moved to keep it there
    t2, _, _ = keyframed(body, start, *keys, times)
    assert np.allclose(t2, start.t)                               # without: the body stays put


def test_table_hops_off_a_ledge():
    """Key-framed squash and spring (thesis Fig. 4.12), then the simulation takes over: the
    table leaves the ledge, falls past its edge and comes to rest on the ground below (top
    heavy and spinning forward from its shear, it lands on its front and tips over)."""
    body = table_body()
    height, edge = 0.5, 0.5
    sim = Simulator(body, ModeGains.from_frequency(body, 3.0, 0.3),
                    Settings(dt=0.005, ground=Ground.ledge(height, edge)))
    start = State.rest(4, t=(0, 0, height + 0.3))
    keys = ([0.0, 0.4, 0.5], [[0, 0, 0, 0], [-0.2, 0, 0.8, 0], [0.2, 0, -0.8, 0]])
    track, result = run_to_end(animate(sim, start, 8.0, 50, keys, handover_time=0.5))
    assert track.handover == 26 and len(track.times) == 401
    assert np.allclose(track.gamma[25], [0.2, 0, -0.8, 0])        # key-framed up to the handover
    assert track.t[:, 2].max() > height + 0.3 + 0.2              # it jumped
    assert result.com[-1][0] > edge + 0.5                         # off the ledge
    end = result.final
    assert -0.01 < lowest(body, end) < 0.0                        # resting on the lower ground
    assert np.linalg.norm(sim.com_velocity(end)) < 0.05


def test_ground_needs_a_time_step_that_divides_the_frame():
    body = table_body()
    sim = Simulator(body, settings=Settings(dt=0.003))
    with pytest.raises(FlexibleError, match="divide"):
        run_to_end(animate(sim, State.rest(4), 1.0, 24))


def test_springs_and_ground_together():
    """Spring attachment points ride along as massless points that don't touch the ground."""
    body = table_body()
    spring = Spring(uvw=(0.5, 0.5, 1.0), anchor=lambda t: (0.0, 0.0, 0.6 + 0.5 * min(t, 1.0)),
                    stiffness=3000.0, damping=100.0)
    sim = Simulator(body, ModeGains.from_frequency(body, 4.0, 0.5),
                    Settings(ground=Ground.flat(), springs=[spring]))
    result = sim.run(State.rest(4, t=(0, 0, 0.3)), 3.0)
    assert result.final.t[2] > 0.3 + 0.2           # lifted off the ground by the moving anchor
