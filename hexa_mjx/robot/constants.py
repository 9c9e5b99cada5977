"""Everything specific to the report's hexapod, in one place.

The converter, the environment and the tests read names, limits and
physical constants from here; nothing else hard-codes them.
"""

from __future__ import annotations

from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
MODEL_XML = REPO_ROOT / "models" / "hexapod.xml"
# Reference data, read at conversion time only; never copied into the project.
SEED_URDF = REPO_ROOT.parent / "shared" / "robots" / "seed_hexapod" / "hexapod.urdf"

# Kinematic names. By default the converter finds a leg as revolute joints `<leg>_<kind>` with
# every kind present; `--legs` maps any other names (a 4- or 8-legged robot works too).
LEG_JOINT_PATTERN = r"^(leg\d+)_(hip|knee|ankle)$"
JOINT_KINDS = ("hip", "knee", "ankle")
LEGS = tuple(f"leg{i}" for i in range(1, 7))
JOINT_NAMES = tuple(f"{leg}_{kind}" for leg in LEGS for kind in JOINT_KINDS)
TORSO_BODY = "base_link"  # the report URDF's root link (the environment uses the free joint's body)
TORSO_GEOM = "torso"
FLOOR_GEOM = "floor"
GOAL_BODY = "goal"
# The model's userdata holds a task's command: (vx m/s, vy m/s, yaw rate rad/s, heading mode 0/1)
# for the velocity task, zeros for the others (hexa_mjx.tasks.velocity).
COMMAND_SIZE = 4
TRACKING_CAMERA = "track"


FOOT_SUFFIX = "_foot"  # the environment finds legs by their foot spheres, `<leg>_foot`


def foot_geom(leg: str) -> str:
    """Name of the sphere at the tip of `leg`."""
    return leg + FOOT_SUFFIX


# Actuation: the report's PyBullet position control capped each joint at 5 N*m.
TORQUE_LIMIT = 5.0  # N*m
KP = 20.0  # N*m/rad, position gain: saturates at 0.25 rad of error
JOINT_DAMPING = 0.5  # N*m*s/rad, about critical for the ankle with the armature below
ARMATURE = 0.005  # kg*m^2, reflected rotor inertia of a geared hobby servo; steadies 240 Hz Euler

# Collision primitives.
FOOT_RADIUS = 0.012  # m
CAPSULE_RADIUS_PERCENTILE = 90  # a capsule covers this share of a link's mesh vertices radially
FRICTION = 1.0  # sliding friction coefficient, robot on floor

# Simulation.
PHYSICS_DT = 1.0 / 240.0  # s, the report's PyBullet rate
SOLVER_ITERATIONS = 1  # MJX speed setting; tests compare against TIGHT_SOLVER
SOLVER_LS_ITERATIONS = 4
TIGHT_SOLVER = {"iterations": 100, "ls_iterations": 50}
