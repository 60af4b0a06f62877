"""Print the README's table of bad inputs, generated from tests/bad_inputs.py.

    python scripts/bad_inputs_table.py            # print the markdown table
    python scripts/bad_inputs_table.py --write    # put it in README.md, between its markers

``--write`` reads README.md afresh and replaces only what lies between
``<!-- bad-inputs:start -->`` and ``<!-- bad-inputs:end -->``;
``tests/test_bad_inputs.py`` checks that the README holds exactly this table
and tries every entry.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"


def _bad_inputs():
    spec = importlib.util.spec_from_file_location("_bad_inputs_for_the_table", ROOT / "tests" / "bad_inputs.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def write_readme(path: Path, table: str, start: str, end: str) -> bool:
    """Replace the text between the markers in ``path`` by ``table``; True if it changed."""
    text = path.read_text()
    if text.count(start) != 1 or text.count(end) != 1 or text.index(start) > text.index(end):
        raise SystemExit(f"{path} needs exactly one {start} followed by one {end}")
    head, rest = text.split(start, 1)
    _, tail = rest.split(end, 1)
    new = f"{head}{start}\n{table}{end}{tail}"
    if new == text:
        return False
    path.write_text(new)
    return True


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="rewrite the table in README.md in place")
    args = parser.parse_args(argv)
    bad = _bad_inputs()
    table = bad.markdown_table()
    if not args.write:
        sys.stdout.write(table)
        return 0
    changed = write_readme(README, table, bad.START_MARKER, bad.END_MARKER)
    sys.stdout.write(f"{README}: {'table rewritten' if changed else 'already up to date'}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
