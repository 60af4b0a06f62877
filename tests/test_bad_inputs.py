"""Every bad input of tests/bad_inputs.py gets exactly its documented outcome, and the README says so.

Each entry is its own test: it is tried, and must raise its error class (a
subclass of ``fe.FemElasticError``) with a message naming the problem and the
fix, or issue its warning and go on, or, for the command, exit with its
status and print the message without a traceback. The README's table "Bad
input and what you get" must be exactly the one generated from the list.
"""

from __future__ import annotations

import importlib.util
import re
import warnings
from pathlib import Path

import pytest

import fem_elastic as fe
from bad_inputs import BAD_INPUTS, END_MARKER, START_MARKER, markdown_table
from fem_elastic.app.cli import main

ROOT = Path(__file__).resolve().parent.parent


def _message_pattern(entry) -> str:
    """A regex matching a message that holds both fragments, in any order."""
    return f"(?s)(?=.*{re.escape(entry.problem)})(?=.*{re.escape(entry.fix)})"


def _params():
    return [
        pytest.param(e, id=e.name,
                     marks=[pytest.mark.xfail(reason=e.xfail_reason, strict=True)] if e.xfail_reason else [])
        for e in BAD_INPUTS
    ]


def test_entries_are_distinct_and_complete():
    names = [e.name for e in BAD_INPUTS]
    assert len(names) == len(set(names)), "two entries share a name (the test ids would clash)"
    for e in BAD_INPUTS:
        assert e.problem and e.fix, e.name
        assert not e.note or e.check is not None, f"{e.name}: what the note claims must be checked"
        if e.kind == "raises":
            assert issubclass(e.outcome, fe.FemElasticError), f"{e.name}: an untyped error"


@pytest.mark.parametrize("entry", _params())
def test_bad_input_gets_its_documented_outcome(entry, tmp_path, capsys):
    if entry.kind == "raises":
        with warnings.catch_warnings():
            # a warning on the way (an explicit scheme's StabilityWarning) is not the outcome here
            warnings.simplefilter("ignore", fe.StabilityWarning)
            with pytest.raises(entry.outcome, match=_message_pattern(entry)) as info:
                entry.attempt(tmp_path)
        if entry.check is not None:
            entry.check(info.value)
    elif entry.kind == "warns":
        with pytest.warns(entry.outcome, match=_message_pattern(entry)):
            result = entry.attempt(tmp_path)  # the call goes on and returns
        if entry.check is not None:
            entry.check(result)
    else:
        argv = entry.attempt(tmp_path)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", fe.StabilityWarning)
            try:
                status = main(argv)
            except SystemExit as stop:  # argparse's own usage errors
                status = stop.code
        out = capsys.readouterr()
        said = out.err + out.out
        assert "Traceback" not in said, said
        assert status == entry.outcome, (status, said)
        assert entry.problem in said and entry.fix in said, said


def test_readme_holds_the_generated_table():
    readme = (ROOT / "README.md").read_text()
    assert readme.count(START_MARKER) == 1 and readme.count(END_MARKER) == 1, \
        f"README.md needs one {START_MARKER} and one {END_MARKER}"
    section = readme.split(START_MARKER, 1)[1].split(END_MARKER, 1)[0]
    assert section == "\n" + markdown_table(), (
        "README.md's table of bad inputs is not the one tests/bad_inputs.py generates; "
        "regenerate it with `python scripts/bad_inputs_table.py --write`"
    )


def test_the_script_rewrites_only_between_the_markers(tmp_path):
    spec = importlib.util.spec_from_file_location("bad_inputs_table", ROOT / "scripts" / "bad_inputs_table.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    readme = tmp_path / "README.md"
    before, after = "# title\n\nintro\n\n", "\n## Layout\n\ntail\n"
    readme.write_text(f"{before}{START_MARKER}\n| stale | table |\n{END_MARKER}{after}")
    table = markdown_table()
    assert script.write_readme(readme, table, START_MARKER, END_MARKER)
    assert readme.read_text() == f"{before}{START_MARKER}\n{table}{END_MARKER}{after}"
    assert not script.write_readme(readme, table, START_MARKER, END_MARKER)  # already up to date
    readme.write_text(before + after)
    with pytest.raises(SystemExit, match="needs exactly one"):
        script.write_readme(readme, table, START_MARKER, END_MARKER)
