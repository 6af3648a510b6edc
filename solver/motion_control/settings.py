"""What the control loop is asked (ControlSettings, the loads, pushes and colliders of the
environment) and what it answers (ControlResult)."""

from dataclasses import dataclass, field

import numpy as np

from ..trajectories import Trajectories
from .comfort_control import Settings as CriteriaSettings


@dataclass
class Load:
    """`mass` kg carried at the centre of mass of bone `bone` (dynamics.model.build_model) from
    `start_time` (seconds from the clip's start); its weight is taken up over
    ControlSettings.grip_time from then."""

    bone: str
    mass: float
    start_time: float = 0.0


@dataclass
class Impulse:
    """At `time` (s from the clip's start), on `bone` at `point` (bone frame, metres) along the
    world unit vector `direction`: `magnitude` N s at once when duration == 0 (changes the
    velocities), else `magnitude` newtons for `duration` seconds (an external force in inverse
    dynamics)."""

    time: float
    bone: str
    point: tuple
    direction: tuple
    magnitude: float
    duration: float = 0.0


@dataclass
class Collider:
    """Moving spheres (another character's bones, a fist): world centres (F, k, 3) per frame of
    the clip, radii (k,), velocities (F, k, 3); kinematic unless `mass` (kg) is finite."""

    positions: np.ndarray
    radii: np.ndarray
    velocities: np.ndarray
    mass: float = np.inf


@dataclass
class ControlSettings:
    gravity: tuple = (0.0, 0.0, -9.81)
    ground_height: float = None  # None: the input's floor (contacts.contact_floor)
    loads: tuple = ()  # Load
    # s over which a load's mass rises from 0 to its whole from its start_time, in grip_steps equal
    # steps, as a hand takes up a weight it grips: a load of full weight at one frame, with the arm
    # moving as captured unloaded, over-stressed the clavicles and made them give way (3 kg per hand
    # on Bandai Namco's bow: the shoulder turned 9.5 deg in one frame where the capture has 1.4)
    grip_time: float = 0.25
    grip_steps: int = 8
    impulses: tuple = ()  # Impulse
    colliders: tuple = ()  # Collider
    strength_scale: float = 1.0
    substeps: int = 1  # Euler steps per frame
    tracking_only: bool = False  # no comfort, balance or falling
    support_overrides: tuple = ()  # contacts.Contact
    # --- beyond the interface (documented defaults) ---
    restitution: float = 0.2  # colliders
    friction: float = 0.8  # Coulomb, colliders and the fallen body on the ground
    fall_time: float = 0.1  # s the falling criterion must hold before the figure falls
    fall_rate: float = 480.0  # Hz: steps per second once falling (at least `substeps` a frame): a
    # body knocked over hits the ground fast; at 120 Hz (4 a frame at 30 fps) a hand sank 4 cm
    fall_damping: float = 2.0  # 1/s, ragdoll joint damping as a rate on each DOF's H_ii
    fall_correction: float = 0.2  # share of a sphere's depth below the ground removed per step
    limit_stiffness: float = 300.0  # N m/rad, ragdoll joint limits
    limit_damping: float = 10.0
    contact_iterations: int = 30  # projected Gauss-Seidel sweeps
    # Gauss-Newton iterations of the planted legs' position re-solve after the step; 0 (default):
    # one, predicted from the step's own frames instead (feet.PlantedFeet.predicted_resolve: no forward
    # kinematics at the integrated configuration, ~9 % fewer instructions per CMU step; the feet
    # land within ~1e-6 m of the exact re-solve's, every thesis experiment gives the same outcome)
    foot_iterations: int = 0
    foot_damping: float = 1e-3  # damped least squares of the legs' IK (a straight knee is singular)
    # near a straight knee (the leg Jacobian's smallest singular value below singular_band, m) the
    # damping grows to singular_damping (feet.PlantedFeet.damping)
    singular_band: float = 0.1
    singular_damping: float = 0.1
    kinematic_fraction: float = 0.0015  # as closed_loop.Settings: fingers follow the input
    # joint armature as a share of each DOF's own inertia H_ii in the first frame (closed_loop's
    # armature_ratio): regularises DOF pairs that turn the same mass about nearly the same axis
    # (CMU's massless lower neck twisting with the neck: passive control asked 1e4 rad/s^2 of them)
    armature_ratio: float = 0.02
    # rad/s^2 (m/s^2 on the root): the largest change dynamic control may make to any DOF in a
    # step (the whole change is scaled down). Passive control makes a stressed joint give way at
    # (excess torque) / H_ii, which a glitch of a captured motion (CMU 131_01's first frames ask
    # 2.4 kN of the ground) turns into 1e4 rad/s^2 of a light neck
    max_dynamic_acceleration: float = 200.0
    # s over which a change of control mode (a part's kind, comfort or balance; how much of the
    # tracking's return is kept) is blended (modes.ModeBlend); 0 (default): switched at once. 0.1 s
    # is the intended value, but the blend delays the feedback: the thesis's 15 kg box squat then
    # falls (docs/physics.md, "Predictable results")
    mode_blend_time: float = 0.0
    weld_static_helpers: bool = True
    lump_made_up_tails: bool = True  # as closed_loop.Settings: an End Site at zero offset has no segment
    min_horizon: float = None  # tracking (TrackingController)
    max_horizon: float = 0.5
    # the input is taken as feasible for the performer (Oshita: "our method assumes that input
    # motion is already realistic"): the stress and ZMP excursion the input motion itself has, with
    # this body model and the detected support, are allowed at its frames (+-1), so control acts on
    # what loads, pushes and collisions add, not on the capture's and the model's errors
    input_allowance: bool = True
    # a captured supporting foot often slides (CMU 131_01: up to 10 cm while planted): the whole
    # input is moved with it (root offset, ControlResult.foot_skate) so planted feet stay put
    remove_foot_skate: bool = True
    criteria: CriteriaSettings = field(default_factory=CriteriaSettings)  # comfort/balance tolerances


@dataclass
class ControlResult:
    trajectories: Trajectories  # at the input's frames
    stress: np.ndarray  # (F, J, 3) N m per bone axis at the output acceleration
    # (F,) m, ZMP outside the support polygon, beyond the input's own excursion at that frame (0
    # inside or without support, NaN falling)
    balance_error: np.ndarray
    zmp: np.ndarray  # (F, 2) NaN without support
    mmp: np.ndarray  # (F, 2) NaN without support
    support: np.ndarray  # (F, 2) bool (left, right) feet planted
    polygon: list  # per frame (k, 2) support polygon
    control: np.ndarray  # (F, J) int8: 0 none, 1 passive, 2 comfort, 3 balance
    falling: np.ndarray  # (F,) bool
    foot_slide: np.ndarray  # (F, 2) m, horizontal travel of each planted foot's contact point since landing
    foot_skate: np.ndarray = None  # (F, 2) m, the root offset that removed the input's foot skate
    model: object = None
    ground_height: float = None  # m, the ground the body stood and fell on
