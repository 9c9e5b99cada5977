"""Docs that cannot rot: every `python ...` command in README.md and docs/ parses against the
current flags of its script, every recipe named there exists, and no page narrates history."""

import argparse
import re
import runpy
import shlex
import sys

import pytest

from hexa_mjx.robot import constants as robot
from hexa_mjx.training import config, recipes

ROOT = robot.REPO_ROOT
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SCRIPTS = ("train.py", "eval.py", "play.py")
SEPARATORS = {"&&", "||", ";", ";;", "|", "&", "do", "done", ">", ">>", "2>&1", "&>"}
PYTHON = re.compile(r"^(\.venv/bin/)?python3?$")


def code_lines(text: str):
    """(line number, command text, block number) of fenced code lines (continuations joined) and
    of inline code spans (block None)."""
    fence, pending, start, block = False, "", 0, 0
    for n, line in enumerate(text.splitlines(), 1):
        if line.startswith("```"):
            fence, block = not fence, block + 1
            continue
        if fence:
            pending, start = (pending + " " + line.strip(), start) if pending else (line.strip(), n)
            if pending.endswith("\\"):
                pending = pending[:-1]
                continue
            yield start, pending, block
            pending = ""
        else:
            for span in re.findall(r"`([^`]+)`", line):
                # Usage synopses with alternatives or optional parts are not commands.
                if not any(mark in span for mark in ("[", "|", "...", "…")):
                    yield n, span, None


def shell_words(text: str, env: dict) -> list[str]:
    """The words of a shell line, its variables expanded from `env` (a loop's first value, an
    assignment's value); `for X in a b; do` and `X=value` set `env`."""
    lexer = shlex.shlex(text, posix=True, punctuation_chars=";&|>")
    lexer.whitespace_split, lexer.commenters = True, "#"
    try:
        tokens = list(lexer)
    except ValueError:
        return []
    words = []
    for i, token in enumerate(tokens):
        if token == "in" and i >= 2 and tokens[i - 2] == "for" and i + 1 < len(tokens):
            env[tokens[i - 1]] = tokens[i + 1]
        match = re.fullmatch(r"([A-Za-z_]\w*)=(.*)", token)
        if match and (not words or words[-1] in SEPARATORS):
            env[match[1]] = match[2]
        whole = re.fullmatch(r"\$\{?(\w+)\}?", token)
        if whole and whole[1] in env:
            words.extend(env[whole[1]].split())
        else:
            words.append(re.sub(r"\$\{?(\w+)\}?", lambda m: env.get(m[1], m[0]), token))
    return words


def commands():
    """(page, line, argv) of every command of ours (train.py, eval.py, play.py, python -m
    hexa_mjx...) in the pages, argv starting at the script."""
    out = []
    for page in PAGES:
        env, current = {}, None
        for n, text, block in code_lines(page.read_text()):
            if block != current:
                env, current = {}, block
            argv = None
            for token in shell_words(text, env) + [";"]:
                if argv is None:
                    argv = [] if PYTHON.match(token) else None
                elif token in SEPARATORS or token.startswith(">"):
                    ours = argv and (argv[0] in SCRIPTS or argv[0] == "-m" and argv[1:2] and argv[1].startswith("hexa_mjx."))
                    if ours and not any(c in t for t in argv for c in "$<["):
                        out.append((page.name, n, argv))
                    argv = None
                else:
                    argv.append(token)
    return out


class Parsed(Exception):
    """Raised by the patched parser once the command line has parsed."""


def parse_only(argv: list[str], monkeypatch) -> argparse.Namespace:
    """Run the script or module of `argv` until its argument parser has parsed them."""
    original = argparse.ArgumentParser.parse_args

    def parse(self, args=None, namespace=None):
        raise Parsed(original(self, args, namespace))

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", parse)
    monkeypatch.chdir(ROOT)
    if argv[0] == "-m":
        monkeypatch.setattr(sys, "argv", [argv[1], *argv[2:]])
        target = lambda: runpy.run_module(argv[1], run_name="__main__", alter_sys=True)  # noqa: E731
    else:
        monkeypatch.setattr(sys, "argv", argv)
        target = lambda: runpy.run_path(str(ROOT / argv[0]), run_name="__main__")  # noqa: E731
    try:
        target()
    except Parsed as parsed:
        return parsed.args[0]
    except SystemExit as e:
        if e.code == 0 and "--help" in argv:
            return argparse.Namespace()
        raise AssertionError(f"{' '.join(argv)} does not parse (exit {e.code})") from None
    raise AssertionError(f"{' '.join(argv)} ran without parsing a command line")


COMMANDS = commands()


def test_the_pages_hold_commands():
    scripts = {argv[0] if argv[0] != "-m" else argv[1] for _, _, argv in COMMANDS}
    assert {"train.py", "eval.py", "play.py"} <= scripts and len(COMMANDS) > 50


@pytest.mark.parametrize("page,line,argv", COMMANDS, ids=[f"{p}:{n}" for p, n, _ in COMMANDS])
def test_documented_command_parses(page, line, argv, monkeypatch, capsys):
    args = parse_only(argv, monkeypatch)
    recipe = getattr(args, "recipe", None)
    if recipe:
        recipes.load(recipe, config.FIELDS)  # a recipe that exists and sets known settings


def test_no_page_narrates_development_history():
    pattern = re.compile(r"session [0-9]|sessions [0-9]|session-[0-9]", re.IGNORECASE)
    for path in [*PAGES, *sorted((ROOT / "hexa_mjx").rglob("*.py")), *sorted((ROOT / "tests").glob("*.py")),
                 *sorted((ROOT / "scripts").glob("*")), *sorted((ROOT / "recipes").glob("*"))]:
        for n, line in enumerate(path.read_text().splitlines(), 1):
            assert not pattern.search(line) or path.name == "test_docs.py", f"{path.name}:{n}: {line.strip()}"
