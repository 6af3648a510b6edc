"""Articulated-body dynamics of a Skeleton with a floating base: kinematics, inverse dynamics
(RNEA), the inertia matrix (CRBA), forward dynamics (ABA), balance (ZMP, support polygon, MMP),
muscle strength, ground contact and Huang's closed-loop simulation. numpy and scipy only."""

from .balance import convex_hull, minimum_moment_point, support_polygon, zmp
from .closed_loop import Push, Result, Settings, SimulationError, desired_motion, iter_simulate, motion_floor, simulate
from .figures import oshita_figure
from .forward_dynamics import aba, forward_dynamics_dense, rk4_step
from .ground_contact import ContactGeometry, GroundModel, default_contacts
from .inertia_matrix import bias_forces, crba, external_forces, gravity_forces, inertia_block
from .inverse_dynamics import external_wrenches, rnea
from .kinematics import (center_of_mass, com_jacobian, difference, integrate, joint_frames,
                         point_accelerations, point_jacobian, point_positions, point_velocities,
                         segment_jacobian, update_frames)
from .model import Data, Model, build_model
from .strength import StrengthModel, default_strength, limit_torques

__all__ = [
    "ContactGeometry", "Data", "GroundModel", "Model", "Push", "Result", "Settings", "SimulationError",
    "iter_simulate", "motion_floor",
    "StrengthModel", "aba", "bias_forces", "build_model", "center_of_mass", "com_jacobian",
    "convex_hull", "crba", "default_contacts", "default_strength", "desired_motion", "difference",
    "external_forces", "external_wrenches", "forward_dynamics_dense", "gravity_forces",
    "inertia_block", "integrate", "joint_frames", "limit_torques", "minimum_moment_point",
    "oshita_figure", "point_accelerations", "point_jacobian", "point_positions",
    "point_velocities", "rk4_step", "rnea", "segment_jacobian", "simulate", "support_polygon",
    "update_frames", "zmp",
]
