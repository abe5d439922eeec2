"""Watching a run live in Foxglove: ``ffexp run ... --live [HOST:PORT]``.

:class:`LiveServer` is a Foxglove WebSocket server (the foxglove-sdk, imported
only when a live run starts) that republishes what the run's
:class:`~ffexp.recording.Recorder` writes, with the file's own schemas and
bytes, decimated to a viewer's rate. :func:`parse_address` reads ``HOST:PORT``.
The layout of ``layouts/ffexp-layout.json`` is built by :mod:`ffexp.live.layout`.
"""

from __future__ import annotations

from ffexp.live.address import DEFAULT_ADDRESS, LiveOptions, parse_address
from ffexp.live.server import LiveServer

__all__ = ["DEFAULT_ADDRESS", "LiveOptions", "LiveServer", "parse_address"]
