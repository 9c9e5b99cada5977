"""Training recipes: named settings files in recipes/, each saying what it is for and what it produced.

    python train.py --recipe rough_terrain --seed 2      # flags on the command line override it

A recipe is a TOML file with a `description` and a `[settings]` table of train.py settings
(TrainConfig field names); `--recipe` takes a name in recipes/ or the path of a file.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from hexa_mjx.robot.constants import REPO_ROOT

RECIPES_DIR = REPO_ROOT / "recipes"


class RecipeError(ValueError):
    """A recipe that cannot be read or names an unknown setting."""


def names() -> list[str]:
    """The recipes in recipes/."""
    return sorted(p.stem for p in RECIPES_DIR.glob("*.toml"))


def path_of(recipe: str) -> Path:
    """The file of a recipe name or path."""
    path = Path(recipe)
    if path.suffix != ".toml":
        path = RECIPES_DIR / f"{recipe}.toml"
    if not path.is_file():
        raise RecipeError(f"no recipe {recipe!r}: choose one of {', '.join(names())}, or give a .toml file")
    return path


def load(recipe: str, known: set[str]) -> dict:
    """A recipe's settings; RecipeError naming the file for bad TOML or a setting not in `known`."""
    path = path_of(recipe)
    try:
        doc = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise RecipeError(f"{path} is not valid TOML ({e}); fix or replace the file") from None
    settings = doc.get("settings")
    if not isinstance(settings, dict):
        raise RecipeError(f"{path} has no [settings] table")
    unknown = sorted(set(settings) - known)
    if unknown:
        raise RecipeError(f"{path} sets unknown setting(s) {unknown}; see `python train.py --help`")
    return settings


def description(recipe: str) -> str:
    """A recipe's one-line description."""
    return tomllib.loads(path_of(recipe).read_text()).get("description", "")
