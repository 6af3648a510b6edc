"""Cloth materials: what the animator picks (light cotton, denim, leather) in SI units."""

from dataclasses import dataclass, replace

import numpy as np

GRAVITY = (0.0, 0.0, -9.81)


@dataclass
class ClothParams:
    density: float = 0.15  # kg per square metre of cloth
    stretch: float = 40.0  # N/m: k_elastic of eq. 4.1 (kept moderate: elongation is a constraint, §4.4.3)
    bend: float = 0.5  # N/m: springs across adjacent faces
    damping: float = 0.02  # N s/m along each edge (relative velocity of its particles)
    drag: float = 1.0  # air drag coefficient of the cloth's normal motion (C_d, dimensionless)
    air_damping: float = 0.2  # 1/s: damping of the absolute velocity
    wind: tuple = (0.0, 0.0, 0.0)  # m/s
    gravity: tuple = GRAVITY
    thickness: float = 0.008  # m kept between the cloth and the body
    substeps: int = 2  # RK4 steps per frame (at 30 fps: 60 Hz; the thesis took 3 Euler steps)
    stretch_limit: float = 0.01  # elongation allowed before the Provot correction moves particles
    # shortening beyond this is pushed back in the simulation too; up to it the smoothing turns
    # shortened edges into folds (0: all of it left to the smoothing, as in the thesis). 0.05 let the
    # benchmark's skirt shorten by 1.8-2.4 % on average even with collisions inside the frame-end
    # sweeps (simulation._settle); 0.04 keeps it at 1.5 %
    compress_limit: float = 0.04
    constraint_iterations: int = 3  # Jacobi sweeps of the Provot correction per substep
    final_iterations: int = 12  # ... and at a frame's end (the frame that is shown), Chebyshev-accelerated
    friction: float = 0.0  # share of the tangential relative speed lost in a contact (0: keep it all)

    def with_changes(self, **changes):
        return replace(self, **changes)


AIR_DENSITY = 1.2  # kg/m^3

PRESETS = {
    # light cotton: light, soft, waves freely
    "COTTON": ClothParams(density=0.12, stretch=30.0, bend=0.2, damping=0.01, drag=1.2, air_damping=0.15),
    # denim: heavier and stiffer in bending
    "DENIM": ClothParams(density=0.40, stretch=120.0, bend=3.0, damping=0.05, drag=1.0, air_damping=0.2),
    # leather: heavy, stiff, little air influence
    "LEATHER": ClothParams(density=0.90, stretch=300.0, bend=12.0, damping=0.15, drag=0.7, air_damping=0.3),
}


def preset(name, **changes):
    try:
        base = PRESETS[name.upper()]
    except KeyError:
        raise KeyError(f"unknown cloth preset {name!r}: {', '.join(PRESETS)}") from None
    return base.with_changes(**changes)


def as_vector(v):
    return np.asarray(v, float).reshape(3)
