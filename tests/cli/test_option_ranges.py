"""Every numeric option of every command is range-checked before any
conversion (docs/reliability.md, "Arguments"): the test walks the whole
command tree from `cdm --help`, so an option added without a check fails
here, not in a user's hands.

For each option whose value is a number (INT, UINT, FLOAT in CLI11's help),
the help must show a validator (`TYPE:in [lo, hi]` or another `TYPE:...`),
and values no range holds (NaN, infinities, overflowing integers, a
negative count) must be refused with exit status 2 and a message naming the
option, before anything runs.
"""
import re

import pytest

from conftest import cdm

OPTION = re.compile(r"^\s+(?:-\w,)?(--[\w-]+)(?:,-\w)? (INT|UINT|FLOAT)(\S*)")
POSITIONAL = re.compile(r"^\s+([A-Za-z_]\w*) (TEXT|INT|UINT|FLOAT)\b.*REQUIRED")
REQUIRED_OPTION = re.compile(r"^\s+(?:-\w,)?(--[\w-]+)(?:,-\w)? (TEXT|INT|UINT|FLOAT)\S*.*REQUIRED")
HOSTILE = ["nan", "inf", "-inf", "1e400", "-1e400", "18446744073709551616", "-18446744073709551617", "0x10",
           "1,5", ""]


def subcommands(path):
    """Every command path below `path` (a list of words), depth first."""
    out = cdm(*path, "--help").stdout
    names = []
    in_subs = False
    for line in out.splitlines():
        if line.startswith("Subcommands:"):
            in_subs = True
            continue
        if in_subs:
            m = re.match(r"^  (\w[\w-]*)\s", line)
            if m:
                names.append(m.group(1))
            elif line and not line.startswith(" "):
                in_subs = False
    found = [path]
    for n in names:
        found += subcommands(path + [n])
    return found


COMMANDS = subcommands([])


def numeric_options(path):
    """(option, type, validator suffix) of a command's help; its required
    positionals; its required options with their types."""
    opts, positionals, required = [], [], []
    for line in cdm(*path, "--help").stdout.splitlines():
        m = OPTION.match(line)
        if m:
            opts.append(m.groups())
        p = POSITIONAL.match(line)
        if p:
            positionals.append(p.group(1))
        q = REQUIRED_OPTION.match(line)
        if q:
            required.append(q.groups())
    return opts, positionals, required


def test_the_walk_finds_the_commands():
    assert ["calib", "diagnose"] in COMMANDS and ["record"] in COMMANDS and ["bridge"] in COMMANDS
    total = sum(len(numeric_options(c)[0]) for c in COMMANDS)
    assert total >= 30, total  # the tree has dozens of numeric options: a parsing failure would find none


@pytest.mark.parametrize("path", COMMANDS, ids=lambda p: " ".join(p) or "cdm")
def test_every_numeric_option_is_range_checked(path, tmp_path):
    opts, positionals, required = numeric_options(path)
    for name, kind, suffix in opts:
        assert suffix.startswith(":"), "cdm %s %s %s has no range check in its help" % (" ".join(path), name, kind)
        # Required positionals and options get values that name nothing real
        # (a valid count for a numeric one): the option under test must be
        # refused before any of them is used.
        given = [str(tmp_path / ("missing_" + p)) for p in positionals]
        for opt, t in required:
            if opt != name:
                given += [opt, "1" if t != "TEXT" else str(tmp_path / ("missing" + opt))]
        for bad in HOSTILE + (["-1"] if kind == "UINT" else []):
            args = [*path, *given, name + "=" + bad]
            r = cdm(*args, timeout=30)
            assert r.returncode == 2, (args, r.returncode, r.stdout[-300:], r.stderr[-300:])
            assert name in r.stderr, (args, r.stderr)
