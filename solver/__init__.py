"""The HumanAnim engine: numpy and scipy only, never bpy. SI units, Z up, quaternions (w, x, y, z)."""

from .body_roles import RoleMap
from .errors import HumanAnimError, MotionError, RigError
from .skeleton import Skeleton
from .trajectories import Trajectories

__all__ = ["HumanAnimError", "MotionError", "RigError", "RoleMap", "Skeleton", "Trajectories"]
