"""Reward terms (report eq. 1 and section 3.2) and the scale tables that weight them.

Each term is a pure function of explicit arrays returning an unscaled value, so it
can be tested without MuJoCo. Terms use only operators and array methods, so the same
code scores the MJX environment (JAX) and the native-MuJoCo one (NumPy). A reward variant is a scales table; an ablation sets
some scales to zero, and a zero scale drops the term from the computation.
"""

from __future__ import annotations

from hexa_mjx.robot.kinematics import namespace, roll_pitch



def goal_approach(prev_dist, dist, most=None):
    """Metres of distance to the goal closed this step (report: x1000), at `most` metres if given."""
    closed = prev_dist - dist
    return closed if most is None else namespace(closed).minimum(closed, most)


def goal_reached(completed):
    """1 on the step a goal is completed (navigation: the next goal is drawn then)."""
    return completed.astype("float32")


def velocity_alignment(vel_xy, goal_dir_xy, most=None):
    """|v| * (v_hat . g_hat) = planar speed toward the goal, m/s, at `most` m/s if given."""
    toward = vel_xy @ goal_dir_xy
    return toward if most is None else namespace(toward).minimum(toward, most)


def goal_bonus(dist, success_radius, non_foot_contacts=0):
    """1 while the torso is within the success radius of the goal with only its feet on the floor."""
    return ((dist < success_radius) & (non_foot_contacts == 0)).astype("float32")


def stability(roll, pitch):
    """|roll| + |pitch| of the torso, rad."""
    return abs(roll) + abs(pitch)


def height(z, target):
    """|z - target| of the torso origin above the ground under it, m."""
    return abs(z - target)


def energy(joint_vel):
    """Sum of squared joint velocities, (rad/s)^2."""
    return (joint_vel * joint_vel).sum()


def mechanical_power(power):
    """Servo power, sum over joints of |torque x joint velocity|, W (Fu et al.'s energy term)."""
    return power


def contact_quality(bad_leg_contacts):
    """Leg contacts with the floor while that leg's foot is lifted (leg-side dragging)."""
    return bad_leg_contacts.astype("float32")


def body_contact(non_foot_contacts):
    """Floor contacts of any geom that is not a foot."""
    return non_foot_contacts.astype("float32")


IDLE_AIR_TIME = 1.0  # s: four strides of the navigation gaits (about 4 Hz); a foot up longer is a leg left out


def idle_feet(air_time, working):
    """Working feet (0/1 each) that have been off the floor for more than IDLE_AIR_TIME; `air_time`
    is each foot's time since it last touched the floor, s. A failed leg is not counted."""
    return (working * (air_time > IDLE_AIR_TIME)).sum()


MIN_DUTY = 0.2  # share of the time each working foot should be on the floor (tripod gaits: about 0.3)
DUTY_WINDOW = 1.0  # s, time constant of the running average of each foot's stance


def running_stance(avg, stance, dt):
    """Each foot's share of time on the floor, `avg` updated with this step's `stance` (0/1): an
    exponential average with time constant DUTY_WINDOW, s; `dt` is the control period, s."""
    return avg + (stance - avg) * (dt / DUTY_WINDOW)


def low_duty(stance_avg, working):
    """Shortfall of each working foot's running share of time on the floor (`stance_avg`, averaged
    over DUTY_WINDOW) below MIN_DUTY, as a fraction of it, summed: 1 per leg that carries no load.
    Unlike idle_feet, a foot that only taps the floor now and then still counts."""
    return (working * (MIN_DUTY - stance_avg).clip(0.0, None) / MIN_DUTY).sum()


# Playground's Go1 swing window (0.2 to 0.5 s), scaled by the square root of the leg-length ratio
# (0.16 m here against about 0.42 m): steps of equal Froude number.
AIR_TIME_MIN = 0.12  # s: a shorter swing costs, a longer one pays
AIR_TIME_MAX = 0.3  # s: a longer swing pays no more
MOVING = 0.1  # norm of the commanded (vx, vy, yaw rate) above which the gait terms count (Playground's)


def feet_air_time(swing, working, moving=1.0):
    """Playground's feet_air_time: summed over working feet that touch down this step, the swing
    just ended (`swing`, s; 0 for a foot not touching down) less AIR_TIME_MIN, at most
    AIR_TIME_MAX - AIR_TIME_MIN; only while `moving` (commanded to walk or turn)."""
    return moving * (working * (swing > 0) * (swing - AIR_TIME_MIN).clip(None, AIR_TIME_MAX - AIR_TIME_MIN)).sum()


def foot_slip(foot_speed, stance, moving=1.0):
    """Playground's feet_slip: summed over feet on the floor (`stance`, 0/1), the square of each
    one's planar speed (`foot_speed`, m/s), (m/s)^2; only while `moving`."""
    return moving * (stance * foot_speed * foot_speed).sum()


def termination(flipped):
    """1 on the step the episode ends by a fall (or a non-finite physics state)."""
    return flipped.astype("float32")


def forward_progress(prev_xy, xy):
    """d_moved * cos(theta) toward +x, m: the report's forward-motion baseline."""
    return xy[0] - prev_xy[0]


def forward_velocity(vel_xy):
    """Speed along +x, m/s: the baseline's velocity term."""
    return vel_xy[0]


TERMS = {
    f.__name__: f
    for f in (goal_approach, goal_reached, velocity_alignment, goal_bonus, stability, height, energy, mechanical_power,
              contact_quality, body_contact, idle_feet, low_duty, feet_air_time, foot_slip, termination,
              forward_progress, forward_velocity)
}

def terms(names, config, prev_qpos, qpos, qvel, goal_xy, bad_contacts, non_foot_contacts, done, completed,
          power, ground=0.0, air_time=0.0, working=1.0, stance_avg=1.0, swing=0.0, stance=0.0, foot_speed=0.0,
          moving=1.0) -> dict:
    """Unscaled values of the terms `names` for the transition prev_qpos -> (qpos, qvel), with
    `goal_xy` the step's goal, contact counts and servo power (W) of the new state, `ground` the
    terrain's height (m) under the torso, each foot's `air_time` (s), running share of time on the
    floor `stance_avg`, swing ending now (s), `stance` (0/1), planar `foot_speed` (m/s) and whether
    its leg is `working` (0/1), whether the command asks to move (`moving`, 0/1), and `config` an EnvConfig.
    Either engine's arrays; under jit, XLA drops the inputs no named term uses."""
    xp = namespace(qpos)
    xy, prev_xy, vel_xy = qpos[:2], prev_qpos[:2], qvel[:2]
    dist = xp.linalg.norm(goal_xy - xy)
    goal_dir = (goal_xy - xy) / xp.maximum(dist, 1e-6)
    # The previous position's distance to this step's goal (the goal only moves after the terms).
    dist_prev = xp.linalg.norm(goal_xy - prev_xy)
    roll, pitch = roll_pitch(qpos[3:7])
    cap = config.goal_speed_cap  # m/s; 0 leaves the report's terms as they were
    inputs = {
        "goal_approach": (dist_prev, dist, cap / config.ctrl_hz if cap else None),
        "goal_reached": (completed,),
        "velocity_alignment": (vel_xy, goal_dir, cap if cap else None),
        "goal_bonus": (dist, config.success_radius, non_foot_contacts if config.bonus_on_feet_only else 0),
        "stability": (roll, pitch),
        "height": (qpos[2] - ground, config.target_height),
        "energy": (qvel[6:],),
        "mechanical_power": (power,),
        "contact_quality": (bad_contacts,),
        "body_contact": (non_foot_contacts,),
        "idle_feet": (air_time, working),
        "low_duty": (stance_avg, working),
        "feet_air_time": (swing, working, moving),
        "foot_slip": (foot_speed, stance, moving),
        "termination": (done,),
        "forward_progress": (prev_xy, xy),
        "forward_velocity": (vel_xy,),
    }
    return {name: TERMS[name](*inputs[name]) for name in names}


# The report's goal terms (section 3.2): approach the goal, at speed, and stay there on the feet.
GOAL_TERMS = {"goal_approach": 1000.0, "velocity_alignment": 5.0, "goal_bonus": 100.0, "goal_reached": 0.0,
              "forward_progress": 0.0, "forward_velocity": 0.0}
GOAL_BONUS = GOAL_TERMS["goal_bonus"]  # the per-step bonus eval.py reports, whatever the variant pays

# The report's contact-aware shaping, shared by every task's reward table.
SHAPING = {
    "mechanical_power": 0.0,
    "stability": -0.5,
    "height": -2.0,
    "energy": -1e-4,
    "contact_quality": -0.5,
    "body_contact": -1.0,
    "idle_feet": 0.0,  # off unless asked for (--reward_scale idle_feet=-5): a stance for every working leg
    "low_duty": 0.0,  # off unless asked for (--reward_scale low_duty=-5): load on every working leg
    "feet_air_time": 0.0,  # off unless asked for (Playground's Go1: 0.1 x its tracking weight, here 1)
    "foot_slip": 0.0,  # off unless asked for (Playground's Go1: -0.1 x its tracking weight, here -1)
    "termination": -200.0,  # the report's code: -200 for a flip
}

ABLATIONS: dict[str, tuple[str, ...]] = {
    "contact": ("contact_quality", "body_contact"),
    "height": ("height",),
    "stability": ("stability",),
    "velocity": ("velocity_alignment", "forward_velocity"),
}


def make_scales(table: dict[str, float], ablate=(), overrides: dict | None = None,
                extra_terms=()) -> dict[str, float]:
    """A task's scales `table` with ablated terms zeroed and explicit overrides applied;
    `extra_terms` names the task's own terms besides TERMS."""
    scales = dict(table)
    for name in ablate:
        if name not in ABLATIONS:
            raise ValueError(f"unknown ablation {name!r}; choose from {sorted(ABLATIONS)}")
        scales.update({term: 0.0 for term in ABLATIONS[name]})
    for term, value in (overrides or {}).items():
        if term not in TERMS and term not in extra_terms:
            raise ValueError(f"unknown reward term {term!r}; terms are {sorted([*TERMS, *extra_terms])}")
        scales[term] = float(value)
    return scales
