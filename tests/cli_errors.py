"""Running the command line in-process and holding it to the promise on bad input: exit
status 2, one line on stderr, no traceback."""

from __future__ import annotations

from compact_distributions.bench.commands.cli import main


def one_error(argv, capsys) -> str:
    """The one error line of ``cvtbench argv`` (arguments may be paths or numbers)."""
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, (code, err)
    return lines[0]
