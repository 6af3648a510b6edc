"""The body's hierarchy over deform bones that hang from mechanism bones (no bpy)."""

import numpy as np
import pytest

from humananim.solver.body_roles import RoleMap
from humananim.solver.errors import RigError
from humananim.solver.rig.hierarchy import body_parents, parents_first

# a control rig in miniature: mechanism bones (no deform) carry the deform leg, a twist segment
# keeps its own parent, a palm-like extra deform bone with no deform ancestor hangs from the nearest role
NAMES = ["root", "mch_torso", "hips", "spine", "mch_leg", "thigh", "thigh_twist", "shin", "foot", "pad"]
PARENTS = [-1, 0, 1, 2, 1, 4, 5, 6, 7, 0]
DEFORM = [False, False, True, True, False, True, True, True, True, True]
HEADS = np.array([[0, 0, 0], [0, 0, 1], [0, 0, 1], [0, 0, 1.1], [0.1, 0, 1], [0.1, 0, 0.98], [0.1, 0, 0.75],
                  [0.1, 0, 0.52], [0.1, 0, 0.1], [0.1, -0.05, 0.05]], float)
TAILS = np.array([[0, 0.3, 0], [0, 0.2, 1], [0, 0, 1.1], [0, 0, 1.4], [0.1, 0, 0.9], [0.1, 0, 0.75], [0.1, 0, 0.52],
                  [0.1, 0, 0.1], [0.1, -0.1, 0.03], [0.1, -0.12, 0.03]], float)
ROLES = RoleMap({"pelvis": ("hips",), "spine": ("spine",), "thigh.L": ("thigh",), "shin.L": ("shin",),
                 "foot.L": ("foot",)})


def test_limbs_hang_from_the_body_whatever_the_rig_hangs_them_from():
    body = body_parents(NAMES, PARENTS, HEADS, TAILS, DEFORM, ROLES)
    named = {NAMES[j]: (NAMES[p] if p >= 0 else None) for j, p in enumerate(body) if DEFORM[j]}
    assert named == {"hips": None, "spine": "hips", "thigh": "hips", "thigh_twist": "thigh",
                     "shin": "thigh_twist", "foot": "shin", "pad": "foot"}
    assert all(body[j] == -1 for j in range(len(NAMES)) if not DEFORM[j])


def test_order_is_parents_first():
    body = body_parents(NAMES, PARENTS, HEADS, TAILS, DEFORM, ROLES)
    order = parents_first(body, np.flatnonzero(DEFORM))
    seen = set()
    for j in order:
        assert body[j] < 0 or body[j] in seen
        seen.add(j)
    assert sorted(order) == list(np.flatnonzero(DEFORM))


def test_roles_on_bones_that_do_not_deform_are_refused():
    roles = RoleMap({**ROLES.bones, "pelvis": ("mch_torso",)})
    with pytest.raises(RigError, match="mch_torso"):
        body_parents(NAMES, PARENTS, HEADS, TAILS, DEFORM, roles)


def test_a_loop_is_refused():
    with pytest.raises(RigError, match="loop"):
        parents_first(np.array([1, 0]), [0, 1])


def test_an_order_already_parents_first_is_kept():
    assert parents_first(np.array([-1, 0, 0, 2]), [0, 1, 2, 3]) == [0, 1, 2, 3]
    assert parents_first(np.array([-1, 3, 0, 0]), [0, 1, 2, 3]) == [0, 2, 3, 1]
