"""MuJoCo C's physics step with heightfield contacts made as MJX makes them.

Both engines collide a geom with each triangle prism of a heightfield under it and agree on which
feet touch and how deep (`python -m hexa_mjx.evaluation.contact_check`). They differ in what they
keep. MuJoCo C keeps every prism's contact, including those through a prism's vertical side wall:
a foot beside a rising cell (a stair's riser, a slope) gets a horizontal contact that pushes it
back, and one near any cell's edge a shallow contact tilted far off the vertical. MJX
(`mjx/_src/collision_convex.py`, `_hfield_collision` and `hfield_sphere`) turns a normal that is
horizontal or points down into the prism's top face normal, then keeps a geom's contacts within
DEEPEST_TOL of its deepest. `step` does both on MuJoCo C before the constraints are made. Where
nothing changes (a plane floor, or no such contact) it is `mj_step` exactly.
"""

from __future__ import annotations

import mujoco
import numpy as np

DEEPEST_TOL = 1e-3  # m: MJX keeps a geom's heightfield contacts within this of its deepest
FLAT_NORMAL = 1e-6  # MJX replaces a normal whose upward component is below this
MODES = ("all", "mjx")  # MuJoCo C's own contacts; or as MJX makes them


def shallow(geom1: np.ndarray, geom2: np.ndarray, dist: np.ndarray, hfield_geom: int, ngeom: int,
            tol: float = DEEPEST_TOL) -> np.ndarray:
    """Which contacts MJX would not keep: those with `hfield_geom` no deeper than their geom's
    deepest one with it plus `tol` m (or not penetrating at all)."""
    on = (geom1 == hfield_geom) | (geom2 == hfield_geom)
    other = np.where(geom1 == hfield_geom, geom2, geom1)
    deepest = np.full(ngeom, np.inf)
    np.minimum.at(deepest, other[on], dist[on])
    return on & (dist >= np.minimum(0.0, deepest[other] + tol))


def face_normal(model: mujoco.MjModel, data: mujoco.MjData, hfield_geom: int, pos: np.ndarray) -> np.ndarray:
    """The upward unit normal, world frame, of the heightfield triangle under world point `pos`
    (MuJoCo's triangulation: each cell cut along its diagonal from (x0, y0) to (x1, y1))."""
    field = model.geom_dataid[hfield_geom]
    nrow, ncol = model.hfield_nrow[field], model.hfield_ncol[field]
    sx, sy, sz = model.hfield_size[field][:3]
    heights = model.hfield_data[model.hfield_adr[field]: model.hfield_adr[field] + nrow * ncol].reshape(nrow, ncol)
    mat = data.geom_xmat[hfield_geom].reshape(3, 3)
    local = mat.T @ (pos - data.geom_xpos[hfield_geom])
    dx, dy = 2 * sx / (ncol - 1), 2 * sy / (nrow - 1)
    fx, fy = (local[0] + sx) / dx, (local[1] + sy) / dy
    c, r = int(np.clip(np.floor(fx), 0, ncol - 2)), int(np.clip(np.floor(fy), 0, nrow - 2))
    h = lambda i, j: heights[j, i] * sz  # noqa: E731 - height at column i, row j, m
    if fy - r > fx - c:  # the triangle (c, r), (c+1, r+1), (c, r+1)
        normal = np.array([-(h(c + 1, r + 1) - h(c, r + 1)) / dx, -(h(c, r + 1) - h(c, r)) / dy, 1.0])
    else:  # the triangle (c, r), (c+1, r), (c+1, r+1)
        normal = np.array([-(h(c + 1, r) - h(c, r)) / dx, -(h(c + 1, r + 1) - h(c + 1, r)) / dy, 1.0])
    return mat @ (normal / np.linalg.norm(normal))


def frame_of(normal: np.ndarray) -> np.ndarray:
    """A contact frame (normal, then two tangents; 9 values) with the given unit normal."""
    other = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(normal, other)
    t1 /= np.linalg.norm(t1)
    return np.concatenate([normal, t1, np.cross(normal, t1)])


def step(model: mujoco.MjModel, data: mujoco.MjData, hfield_geom: int, tol: float = DEEPEST_TOL) -> int:
    """One `mj_step` whose contacts with `hfield_geom` are made as MJX makes them; returns how many
    of MuJoCo C's contacts it turned or excluded. A geom that is not a heightfield (a plane floor):
    plain `mj_step`. Euler and implicit integrators (RK4 collides again inside its step)."""
    if model.geom_type[hfield_geom] != mujoco.mjtGeom.mjGEOM_HFIELD:
        mujoco.mj_step(model, data)
        return 0
    if model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4:
        raise ValueError("terrain contacts as MJX makes them need the Euler or an implicit integrator, not RK4")
    mujoco.mj_checkPos(model, data)
    mujoco.mj_checkVel(model, data)
    mujoco.mj_fwdPosition(model, data)  # kinematics, collision, constraints
    n, c = data.ncon, data.contact
    geom1, geom2 = c.geom1[:n], c.geom2[:n]
    on = (geom1 == hfield_geom) | (geom2 == hfield_geom)
    sign = np.where(geom1 == hfield_geom, 1.0, -1.0)  # the frame's normal points from geom1 to geom2
    axis = data.geom_xmat[hfield_geom].reshape(3, 3)[:, 2]
    turned = np.flatnonzero(on & (sign * (c.frame[:n, :3] @ axis) < FLAT_NORMAL) & (c.exclude[:n] == 0))
    for i in turned:
        c.frame[i] = frame_of(sign[i] * face_normal(model, data, hfield_geom, c.pos[i]))
    drop = shallow(geom1, geom2, c.dist[:n], hfield_geom, model.ngeom, tol) & (c.exclude[:n] == 0)
    if drop.any():
        c.exclude[:n] = np.where(drop, 1, c.exclude[:n])
    if drop.any() or len(turned):  # make the constraints again (mj_fwdPosition's own last steps)
        mujoco.mj_makeConstraint(model, data)
        mujoco.mj_island(model, data)
        mujoco.mj_projectConstraint(model, data)
    mujoco.mj_forwardSkip(model, data, mujoco.mjtStage.mjSTAGE_POS, 0)  # velocity, actuation, acceleration
    mujoco.mj_checkAcc(model, data)
    if model.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER:
        mujoco.mj_Euler(model, data)
    else:
        mujoco.mj_implicit(model, data)
    return int(drop.sum() + len(turned))
