"""Motion synthesis (thesis ch. 5): a cyclic pose graph drives PD controllers of the active
modes; simulated annealing (Fig. 5.2) searches poses, durations or both for the controller
that minimises a cost of the motion (Table 5.1, or a custom weighted cost)."""

from dataclasses import dataclass, field

import numpy as np

from .body import FlexibleError

OPTIMIZE = ("poses", "durations", "both")
COSTS = {
    "distance": "1 / q_x: hops with unrealistic jumps",
    "energy_distance": "consumed energy / q_x: normal hops",
    "energy_speed": "consumed energy / (scale sqrt(q_x qdot_x)): bounding",
    "energy_sqrt_distance": "consumed energy / (scale sqrt(q_x)): worm-like",
    "custom": "weighted: energy - distance - speed + tilt",
}
HIGH_COST = 1e6


@dataclass
class CostSpec:
    name: str = "energy_speed"
    direction: tuple = (1.0, 0.0, 0.0)
    scale: float = 1.0                 # the thesis's 1e7 / 5e7 constants, in our units
    w_energy: float = 0.0001           # custom: per joule
    w_distance: float = 1.0            # custom: per metre forward
    w_speed: float = 0.0               # custom: per m/s forward at the end
    w_tilt: float = 0.0                # custom: per radian of tilt at the end

    def __post_init__(self):
        if self.name not in COSTS:
            raise FlexibleError(f"cost must be one of {', '.join(COSTS)}")
        d = np.asarray(self.direction, float)
        if not np.isfinite(d).all() or np.linalg.norm(d) < 1e-12:
            raise FlexibleError("the cost's direction needs a non-zero vector")
        self.direction = d / np.linalg.norm(d)


def motion_measures(result, direction):
    """Distance and end speed of the centre of mass along `direction`, consumed energy, tilt."""
    distance = float((result.com[-1] - result.com[0]) @ direction)
    speed = float(result.end_com_velocity @ direction)
    w, x, y, z = result.final.quat
    up_z = 1 - 2 * (x * x + y * y)             # body z axis . world z
    tilt = float(np.arccos(np.clip(up_z, -1, 1)))
    return {"distance_m": distance, "speed_m_s": speed, "energy_j": float(result.consumed_energy),
            "tilt_rad": tilt}


def cost_of(spec, result):
    m = motion_measures(result, spec.direction)
    d, v, e = m["distance_m"], m["speed_m_s"], m["energy_j"]
    name = spec.name
    if name == "custom":
        return (spec.w_energy * e - spec.w_distance * d - spec.w_speed * v + spec.w_tilt * m["tilt_rad"]), m
    # standing still (under a millimetre, a millimetre per second) counts as not moving
    bad = d <= 1e-3 or (name == "energy_speed" and v <= 1e-3)
    if bad:  # "if q_x qdot_x < 0, the cost is set to a high value"; further back is worse still
        return HIGH_COST * (1.0 + max(-d, 0.0)), m
    if name == "distance":
        return 1.0 / d, m
    if name == "energy_distance":
        return e / d, m
    if name == "energy_speed":
        return e / (spec.scale * np.sqrt(d * v)), m
    return e / (spec.scale * np.sqrt(d)), m


@dataclass
class AnnealSettings:
    optimize: str = "both"
    trials: int = 60                   # forward simulations, the first one included
    duration: float = 12.0             # t_f of each forward simulation (s)
    start_temperature: float = 0.2     # T0 as a fraction of the first cost
    frozen_temperature: float = 0.002  # T_frozen as a fraction of the first cost
    pose_step: float = 0.3             # neighbour: sd of a pose amplitude change
    duration_step: float = 0.3         # neighbour: sd of a duration change, relative
    duration_range: tuple = (0.05, 2.0)
    change_fraction: float = 0.3       # neighbour: share of the parameters changed
    seed: int = 0

    def __post_init__(self):
        if self.optimize not in OPTIMIZE:
            raise FlexibleError(f"optimize must be one of {OPTIMIZE}")
        if self.trials < 1:
            raise FlexibleError("annealing needs at least one trial")
        if not 0 < self.frozen_temperature <= self.start_temperature:
            raise FlexibleError("temperatures: 0 < frozen <= start")


@dataclass
class AnnealResult:
    poses: np.ndarray
    durations: np.ndarray
    cost: float
    measures: dict
    initial_cost: float
    costs: list = field(default_factory=list)        # cost of every trial
    best_costs: list = field(default_factory=list)   # best so far after every trial
    accepted: int = 0
    uphill: int = 0
    trials: int = 0


def neighbour(rng, poses, durations, settings):
    """A random neighbour: a random share of the optimised parameters moved by Gaussian steps,
    poses kept in [-1, 1] and durations in their range."""
    poses, durations = poses.copy(), durations.copy()
    params = []
    if settings.optimize in ("poses", "both"):
        params += [("p", i) for i in range(poses.size)]
    if settings.optimize in ("durations", "both"):
        params += [("d", i) for i in range(durations.size)]
    count = max(1, int(round(settings.change_fraction * len(params))))
    for k in rng.choice(len(params), size=count, replace=False):
        kind, i = params[k]
        if kind == "p":
            flat = poses.reshape(-1)
            flat[i] = np.clip(flat[i] + rng.normal(0.0, settings.pose_step), -1.0, 1.0)
        else:
            lo, hi = settings.duration_range
            durations[i] = np.clip(durations[i] * np.exp(rng.normal(0.0, settings.duration_step)), lo, hi)
    return poses, durations


def anneal(make_simulator, controller, initial_state, cost, settings):
    """Simulated annealing of Fig. 5.2 as a step generator: yields progress, returns an
    AnnealResult. make_simulator(controller) -> Simulator."""
    rng = np.random.default_rng(settings.seed)
    n = settings.trials

    def evaluate(poses, durations, trial):
        """A forward simulation, yielding overall progress as it goes (so Esc is quick)."""
        sim = make_simulator(controller.with_parameters(poses, durations))
        steps = sim.iter_run(initial_state, settings.duration)
        try:
            while True:
                yield (trial + next(steps)) / n
        except StopIteration as done:
            result = done.value
        except FlexibleError:  # a controller that blows the simulation up is just bad
            return HIGH_COST * 10, {"distance_m": 0.0, "speed_m_s": 0.0, "energy_j": 0.0, "tilt_rad": 0.0}
        return cost_of(cost, result)

    P, Dur = controller.poses.copy(), controller.durations.copy()
    c, m = yield from evaluate(P, Dur, 0)
    out = AnnealResult(P, Dur, c, m, c, [c], [c], trials=1)
    # geometric cooling T_k = T0 r^k from T0 to T_frozen over the trials, both relative to the
    # cost scale: the first cost, or the first one below the "high value" when the start
    # configuration doesn't move forward at all
    r = (settings.frozen_temperature / settings.start_temperature) ** (1.0 / max(settings.trials - 1, 1))

    def temperature(trial, scale):
        return settings.start_temperature * scale * r ** trial
    scale = abs(c) if c != 0 else 1.0
    scaled_high = c >= HIGH_COST
    yield 1.0 / settings.trials
    cur_P, cur_D, cur_c = P, Dur, c
    for trial in range(1, settings.trials):
        new_P, new_D = neighbour(rng, cur_P, cur_D, settings)
        new_c, new_m = yield from evaluate(new_P, new_D, trial)
        if scaled_high and new_c < HIGH_COST:
            scale, scaled_high = abs(new_c) if new_c != 0 else 1.0, False
        T = temperature(trial - 1, scale)
        delta = new_c - cur_c
        accept = delta <= 0 or rng.random() < np.exp(-delta / T)
        if accept:
            out.accepted += 1
            out.uphill += int(delta > 0)
            cur_P, cur_D, cur_c = new_P, new_D, new_c
        if new_c < out.cost:
            out.poses, out.durations, out.cost, out.measures = new_P, new_D, new_c, new_m
        out.costs.append(new_c)
        out.best_costs.append(out.cost)
        out.trials += 1
        yield (trial + 1) / settings.trials
    return out
