"""Every ``--help`` of the fdikit command is written for users.

Plain text (no reST roles or double backticks, no notes meant for developers), a description
for every parser, papers named by their author tags, and a unit for every option whose value has
one.
"""

import argparse
import re

import pytest

from fdikit.cli import build_parser

#: Markup and developer notes that must not reach a user's terminal.
FORBIDDEN = ("``", ":func:", ":mod:", ":class:", ":data:", ":meth:", ":attr:", "Wire it", "wire it",
             "later issue", "Later issue", "register themselves", "paper 1", "paper 2", "paper 3",
             "Paper 1", "Paper 2", "Paper 3")
#: Any other reST role, e.g. :obj:`x`.
REST_ROLE = re.compile(r":[a-z]+:`")

#: Options whose value has a unit; where a parser has one, its help must name the unit.
UNIT_OPTIONS = ("--t-final", "--h", "--settle", "--snr", "--t-brake", "--t-end", "--v0", "--speed",
                "--gate", "--window", "--noise-hold", "--pedal-ramp", "--meas-var", "--f-max", "--rate",
                "--block")
#: A unit word on its own (not the "s" of "Table III's"), or (rad/s)^2.
UNIT = re.compile(r"(?<![\w'/])(s|Hz|dB|m/s|rad/s|samples|runs)(?![\w/])|\(rad/s\)\^2")


def _walk(parser: argparse.ArgumentParser, path: tuple[str, ...] = ("fdikit",)):
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _walk(sub, (*path, name))


PARSERS = dict((" ".join(path), p) for path, p in _walk(build_parser()))


def _option_help(parser: argparse.ArgumentParser, option: str) -> str | None:
    for action in parser._actions:
        if option in action.option_strings:
            return parser._get_formatter()._expand_help(action) if action.help else ""
    return None


def test_every_command_is_walked():
    for name in ("fdikit", "fdikit demo", "fdikit reconstruct", "fdikit abs", "fdikit abs simulate",
                 "fdikit abs campaign", "fdikit abs detectability", "fdikit car", "fdikit car linearize",
                 "fdikit car fit", "fdikit car scenario", "fdikit car monitor-log", "fdikit design",
                 "fdikit monitor"):
        assert name in PARSERS, name


@pytest.mark.parametrize("name", sorted(PARSERS))
def test_help_is_plain_text_for_users(name):
    text = PARSERS[name].format_help()
    for bad in FORBIDDEN:
        assert bad not in text, f"{name} --help contains {bad!r}:\n{text}"
    assert not REST_ROLE.search(text), f"{name} --help contains a reST role:\n{text}"


@pytest.mark.parametrize("name", sorted(PARSERS))
def test_every_parser_has_a_description(name):
    p = PARSERS[name]
    assert p.description and p.description.strip(), f"{name} has no description"
    if _option_help(p, "--json") is not None:
        assert "JSON" in p.description, f"{name}: the description does not say what --json prints"


@pytest.mark.parametrize("name", sorted(PARSERS))
def test_options_with_units_state_the_unit(name):
    p = PARSERS[name]
    for option in UNIT_OPTIONS:
        text = _option_help(p, option)
        if text is None:
            continue
        assert UNIT.search(text), f"{name} {option}: no unit in {text!r}"


@pytest.mark.parametrize("name", sorted(PARSERS))
def test_every_option_has_help(name):
    p = PARSERS[name]
    for action in p._actions:
        if isinstance(action, argparse._SubParsersAction):
            continue
        assert action.help, f"{name} {action.option_strings or action.dest}: no help text"


def test_unit_pattern():
    assert UNIT.search("simulated time, s (default 15)")
    assert UNIT.search("measurement noise variance, (rad/s)^2")
    assert UNIT.search("GLRT window, samples")
    assert not UNIT.search("default Table III's 50/10")
    assert not UNIT.search("ramp over SECONDS")
