"""The controlled body: a dynamics model (one set of active loads) and what the control steps need
of it, made once per model (index arrays of the legs and feet, the contact spheres and capsules,
the strength and the control states' shared constants)."""

from dataclasses import replace

import numpy as np

from ..dynamics import kinematics
from ..dynamics.closed_loop import SimulationError
from ..dynamics.ground_contact import default_contacts
from ..dynamics.inertia_matrix import crba
from ..dynamics.model import build_model
from ..dynamics.strength import default_strength
from .comfort_control import body_parts, state_constants


class ControlBody:
    """A model and what the steps need of it (see the module notes)."""

    def __init__(self, model, strength):
        self.model = model
        self.data = model.create_data()
        self.contacts = default_contacts(model)
        self.parts = p = body_parts(model, self.contacts)
        self.strength = strength
        self.constants = state_constants(model, self.parts, strength)  # the control states'
        self.spheres = self.contacts.on(model)  # bodies (k,), body-frame centres (k, 3)
        self.sphere_hom = np.c_[self.spheres[1], np.ones(len(self.spheres[1]))]
        self.capsules = capsules(self.contacts)
        # per side: the foot's body and frame offset, the DOFs of the foot's ancestors (its
        # Jacobian's columns), and where the leg's own DOFs lie among them
        self.foot_body = [int(model.joint_body[f]) for f in p.feet]
        self.feet_rows = np.array(self.foot_body, np.intp)
        self.root_feet_rows = np.array([0] + self.foot_body, np.intp)
        self.foot_offset = [model.joint_offset[f] for f in p.feet]
        self.leg_cols = [np.asarray(c, int) for c in p.legs]
        self.leg_dofs = [np.flatnonzero(model.ancestors[b][model.dof_body] != 0) for b in self.foot_body]
        self.leg_pos = [np.searchsorted(dofs, cols) for dofs, cols in zip(self.leg_dofs, self.leg_cols)]
        # both legs batched when they have the same layout (a symmetric rig): the feet's bodies,
        # frame offsets, Jacobian columns (2, k) and the leg's own columns among them (l,)
        same = (len(self.leg_dofs[0]) == len(self.leg_dofs[1])
                and np.array_equal(self.leg_pos[0], self.leg_pos[1]))
        self.legs_batched = (self.feet_rows, np.array(self.foot_offset), np.array(self.leg_dofs),
                             self.leg_pos[0]) if same else None
        # per foot (2, nb) its ancestors and (2, nv) their DOFs (as 0 / 1)
        self.feet_ancestors = np.ascontiguousarray(model.ancestors[self.foot_body], float)
        self.feet_dof_mask = (self.feet_ancestors[:, model.dof_body] != 0.0).astype(float)
        # per contact set: the root's and the planted legs' joints (feet.predicted_resolve)
        self.landing_dofs = {(a, b): np.concatenate([np.arange(3)] + [c for c, on in zip(self.leg_cols, (a, b)) if on])
                             for a in (False, True) for b in (False, True)}
        # both feet's sole points on their bodies, as (x, y, z, 1) rows
        self.sole_bodies, sole_local = kinematics.points_on_bodies(
            model, np.concatenate(p.sole_joints), np.concatenate(p.sole_points))
        self.sole_split = len(p.sole_joints[0])
        self.sole_hom = np.c_[sole_local, np.ones(len(sole_local))]
        # per contact set (left, right on the ground): the sides' indices and their feet's bodies
        self.contact_sets = {}
        for contact in ((True, True), (True, False), (False, True)):
            sides = np.flatnonzero(contact)
            self.contact_sets[contact] = (sides, model.joint_body[np.asarray(p.feet)[sides]])
        # per (left lifted, right lifted): the contact spheres of the lifted feet (swing_spheres)
        self.swing_masks = {}
        for key in ((False, False), (False, True), (True, False), (True, True)):
            out = np.zeros(len(self.spheres[0]), bool)
            for s, foot in enumerate(p.feet):
                if key[s]:
                    out |= model.ancestors[self.spheres[0]][:, model.joint_body[foot]] != 0
            self.swing_masks[key] = out if out.any() else None

    def swing_spheres(self, planted):
        """(k,) bool: the contact spheres on the foot (and toes, heel) of each side not planted, or
        None when there is none."""
        return self.swing_masks[planted[0] is None, planted[1] is None]


def capsules(contacts):
    """Sphere index pairs (a, b) of the contact geometry as capsules: a bone's two spheres of one
    radius (default_contacts puts them at its head and tail) and the segment between them; any
    other sphere is a capsule of zero length (a == b)."""
    ia, ib = [], []
    joints, radii = np.asarray(contacts.joints), np.asarray(contacts.radii)
    for j in dict.fromkeys(joints.tolist()):
        ks = np.flatnonzero(joints == j)
        if len(ks) == 2 and radii[ks[0]] == radii[ks[1]] and radii[ks[0]] > 0.0:
            ia.append(ks[0]), ib.append(ks[1])
        else:
            ia.extend(ks), ib.extend(ks)
    return np.array(ia, int), np.array(ib, int)


class LoadedBodies:
    """The ControlBody of each set of active loads, made once: a load acts from its start_time,
    its mass rising to the whole over ControlSettings.grip_time in grip_steps steps (a key is the
    tuple of each load's share of its mass)."""

    def __init__(self, skeleton, settings, reference_basis, q0, kinematic_mass):
        self.skeleton, self.settings = skeleton, settings
        self.reference_basis, self.q0, self.kinematic_mass = reference_basis, q0, kinematic_mass
        self.bodies = {}

    def active(self, t):
        """The share of each load's mass acting at time t (a tuple of floats in [0, 1]): 0 before
        its start_time, then rising in grip_steps equal steps to 1 at start_time + grip_time."""
        st = self.settings
        steps = max(1, int(st.grip_steps))
        shares = []
        for l in st.loads:
            if t < l.start_time - 1e-9:
                shares.append(0.0)
            elif st.grip_time <= 0.0:
                shares.append(1.0)
            else:
                rise = (t - l.start_time) / st.grip_time
                shares.append(min(1.0, (np.floor(rise * steps + 1e-9) + 1.0) / steps))
        return tuple(shares)

    def unloaded(self):
        return self.get(tuple(0.0 for _ in self.settings.loads))

    def at(self, t):
        return self.get(self.active(t))

    def get(self, active):
        if active not in self.bodies:
            st = self.settings
            loads = {}
            for l, share in zip(st.loads, active):
                if share > 0.0:
                    loads[l.bone] = loads.get(l.bone, 0.0) + share * float(l.mass)
            m = build_model(self.skeleton, reference_basis=self.reference_basis, loads=loads, gravity=st.gravity,
                            kinematic_mass=self.kinematic_mass)
            if self.bodies:
                ref = next(iter(self.bodies.values())).model
                if m.nv != ref.nv or not np.array_equal(m.body_joint, ref.body_joint):
                    raise SimulationError("a load changes which bones carry dynamics: put loads on bones "
                                          "with mass (hands, forearms, trunk)")
            if st.armature_ratio > 0.0:
                m.set_armature(st.armature_ratio * np.diag(crba(m, m.create_data(), self.q0(m))))
            strength = default_strength(m)
            strength = replace(strength, scale=strength.scale * st.strength_scale)
            self.bodies[active] = ControlBody(m, strength)
        return self.bodies[active]


def inertia(model, data, q):
    """H (the model's armature included, ControlSettings.armature_ratio)."""
    h = crba(model, data, q)
    h.flat[::model.nv + 1] += 1e-12
    return h
