"""Reading a robot's URDF: its legs by joint name, its meshes beside it, MuJoCo's import of it.

`hexa_mjx.robot.convert` builds the MJCF from what this module reads.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import mujoco

from hexa_mjx.robot import constants as robot


class ConversionError(ValueError):
    """The URDF cannot be converted; the message says why and what to do."""


@dataclass(frozen=True)
class Leg:
    name: str
    joints: tuple[str, ...]  # proximal first (robot.JOINT_KINDS order when found by name)


# ---------------------------------------------------------------------------
# Reading and validating the URDF


def _resolve_mesh(filename: str, urdf_dir: Path) -> Path:
    """Find a mesh named by a URDF: an absolute path, or package:// and relative paths from the
    URDF's folder, or meshes/ beside it. Never the current directory: a stray meshes/ folder
    there must not change the robot."""
    stripped = re.sub(r"^package://[^/]+/", "", filename)
    stripped = re.sub(r"^file://", "", stripped)
    candidates = [urdf_dir / stripped, urdf_dir / "meshes" / Path(stripped).name]
    if Path(stripped).is_absolute():
        candidates.insert(0, Path(stripped))
    for c in candidates:
        if c.is_file():
            return c.resolve()
    raise ConversionError(
        f"mesh {filename!r} not found (looked in: {', '.join(str(c) for c in candidates)}); "
        "put the meshes beside the URDF or in a meshes/ folder next to it"
    )


def parse_legs(text: str) -> list[Leg]:
    """Legs from a mapping "NAME:JOINT,JOINT,... NAME:..." (joints proximal first)."""
    legs, seen = [], set()
    for item in text.split():
        name, sep, joints = item.partition(":")
        joint_list = tuple(j for j in joints.split(",") if j)
        if not sep or not re.fullmatch(r"[A-Za-z0-9]+", name) or not joint_list:
            raise ConversionError(f"--legs entry {item!r} is not NAME:JOINT,JOINT,... (a leg name of letters and "
                                  "digits, then its joints from the body outward)")
        if name in {leg.name for leg in legs}:
            raise ConversionError(f"--legs names leg {name!r} twice")
        repeated = sorted(seen & set(joint_list))
        if repeated:
            raise ConversionError(f"--legs gives joint(s) {repeated} to more than one leg")
        seen |= set(joint_list)
        legs.append(Leg(name, joint_list))
    if not legs:
        raise ConversionError("--legs is empty; give NAME:JOINT,JOINT,... for each leg")
    return legs


def check_legs(legs: list[Leg], joint_names: list[str]) -> list[Leg]:
    """A --legs mapping checked against the URDF's revolute joints."""
    missing = [j for leg in legs for j in leg.joints if j not in joint_names]
    if missing:
        raise ConversionError(f"--legs names joint(s) {missing} that are not revolute joints of the URDF; "
                              f"its revolute joints are {sorted(joint_names)}")
    return legs


def find_legs(joint_names: list[str]) -> list[Leg]:
    """Group revolute joints named `<leg>_<kind>` into legs; every leg needs every kind."""
    found: dict[str, dict[str, str]] = {}
    for name in joint_names:
        match = re.match(robot.LEG_JOINT_PATTERN, name)
        if match:
            found.setdefault(match.group(1), {})[match.group(2)] = name
    if not found:
        raise ConversionError(
            "no leg joints found: expected revolute joints named like "
            f"'leg1_hip', 'leg1_knee', 'leg1_ankle' (pattern {robot.LEG_JOINT_PATTERN}); "
            f"the URDF's revolute joints are {sorted(joint_names)}"
        )
    legs = []
    for leg in sorted(found, key=lambda s: int(re.sub(r"\D", "", s))):
        missing = [k for k in robot.JOINT_KINDS if k not in found[leg]]
        if missing:
            raise ConversionError(
                f"leg {leg!r} lacks joint(s) {[f'{leg}_{k}' for k in missing]}; "
                f"each leg needs revolute joints {list(robot.JOINT_KINDS)}"
            )
        legs.append(Leg(leg, tuple(found[leg][k] for k in robot.JOINT_KINDS)))
    return legs


def _prepare_urdf(urdf_path: Path, legs: list[Leg] | None = None) -> tuple[str, str, list[Leg]]:
    """Validate the URDF and rewrite it so MuJoCo's importer loads it with a free root. Legs are
    `legs` (a --legs mapping) or else found by the `<leg>_<kind>` naming."""
    if not urdf_path.is_file():
        raise ConversionError(f"URDF {urdf_path} does not exist")
    try:
        tree = ET.parse(urdf_path)
    except ET.ParseError as e:
        raise ConversionError(f"malformed URDF {urdf_path}: {e}") from e
    root_el = tree.getroot()
    if root_el.tag != "robot":
        raise ConversionError(f"{urdf_path} is not a URDF: root element is <{root_el.tag}>, not <robot>")
    for el in list(root_el):  # xacro includes are build-time only
        if "xacro" in el.tag or el.tag in ("gazebo", "transmission"):
            root_el.remove(el)

    links = [el.get("name") for el in root_el.findall("link")]
    joints = root_el.findall("joint")
    children = set()
    for j in joints:
        parent, child = j.find("parent"), j.find("child")
        if parent is None or child is None or j.get("name") is None:
            raise ConversionError(f"malformed URDF {urdf_path}: a <joint> lacks a name, <parent> or <child>")
        for end in (parent.get("link"), child.get("link")):
            if end not in links:
                raise ConversionError(f"malformed URDF {urdf_path}: joint {j.get('name')!r} names unknown link {end!r}")
        children.add(child.get("link"))
    roots = [name for name in links if name not in children]
    if len(roots) != 1:
        raise ConversionError(f"malformed URDF {urdf_path}: expected one root link, found {roots}")
    revolute = [j.get("name") for j in joints if j.get("type") in ("revolute", "continuous")]
    legs = check_legs(legs, revolute) if legs else find_legs(revolute)

    for mesh in root_el.iter("mesh"):
        mesh.set("filename", str(_resolve_mesh(mesh.get("filename", ""), urdf_path.parent)))

    # A world link and a floating joint give the root a free joint in MuJoCo.
    root_el.insert(0, ET.fromstring('<mujoco><compiler fusestatic="true" discardvisual="true" strippath="false"/></mujoco>'))
    root_el.insert(1, ET.Element("link", name="world"))
    floating = ET.fromstring(f'<joint name="floating" type="floating"><parent link="world"/><child link="{roots[0]}"/></joint>')
    root_el.insert(2, floating)
    return ET.tostring(root_el, encoding="unicode"), roots[0], legs


def load_urdf(urdf_path: str | Path, legs: list[Leg] | None = None) -> tuple[mujoco.MjModel, str, list[Leg]]:
    """Compile a URDF with MuJoCo (fixed joints fused); returns model, root link and legs."""
    text, root_link, legs = _prepare_urdf(Path(urdf_path), legs)
    try:
        model = mujoco.MjSpec.from_string(text).compile()
    except Exception as e:  # MuJoCo raises ValueError with its own message
        raise ConversionError(f"MuJoCo could not load {urdf_path}: {e}") from e
    if model.nmesh == 0:
        raise ConversionError(f"{urdf_path} has no mesh geometry to fit collision primitives to")
    return model, root_link, legs


# ---------------------------------------------------------------------------
# Fitting primitives to mesh vertices (all in the owning body's frame)
