"""`uwlab console --sim` as a real process on 127.0.0.1 for the tests: started with ``--json --port 0 --no-browser``,
its URL read from the first line, stopped with Ctrl-C (SIGINT), as `tests.support.explorer_process.Explorer`."""

from __future__ import annotations

from tests.support.explorer_process import Explorer


class Console(Explorer):
    VERB = "console"
    STOP_TIMEOUT_S = 60  # a run in progress is stopped and its light put in its safe state first
