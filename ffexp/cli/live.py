"""``ffexp run --live``: the live server around one run, and serving on after it.

A simulated run is over in a second or two, long before a person has opened the
Foxglove app, so after the run the server stays up until the viewer has left
(every viewer that subscribed has gone) or the user presses Ctrl-C (or sends
SIGTERM); the run's own exit code stands. foxglove is imported only here, when
``--live`` is given.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ffexp.cli._common import StopFlag
    from ffexp.live import LiveOptions, LiveServer

#: Where a viewer's layout is (Foxglove: Layouts -> Import from file).
LAYOUT_FILE = "layouts/ffexp-layout.json"


def _say(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def how_to_connect(server: LiveServer) -> list[str]:
    """The console lines that tell a user how to watch: the URL, the app and the layout."""
    from ffexp.live.server import SUBPROTOCOL

    lines = [
        f"live: Foxglove WebSocket server on {server.url} (subprotocol {SUBPROTOCOL})",
        f"live: in the Foxglove app (desktop or https://app.foxglove.dev): Open connection -> "
        f"Foxglove WebSocket -> {server.url}; layout: {LAYOUT_FILE}",
    ]
    app_url = server.app_url()
    if app_url:
        lines.append(f"live: or open {app_url}")
    return lines


@contextmanager
def live_view(options: LiveOptions | None) -> Iterator[LiveServer | None]:
    """The started server (None without ``--live``); closed when the block ends.
    A bad or busy address is an AddressError before anything runs."""
    if options is None:
        yield None
        return
    from ffexp.live.server import LiveServer

    server = LiveServer(options)
    server.start()
    try:
        for line in how_to_connect(server):
            _say(line)
        yield server
    finally:
        server.close()


def serve_after_run(server: LiveServer, flag: StopFlag) -> None:
    """Keep serving the ended run until its viewer has gone or a signal comes."""
    if flag():
        return  # the run was stopped by a signal: stop serving with it
    _say(f"live: the run has ended; still serving {server.url} until the viewer "
         "disconnects (Ctrl-C to stop)")
    why = server.linger(flag)
    _say(f"live: stopped serving ({why})")
