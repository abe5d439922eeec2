"""An RTDE client over TCP (protocol version 2): the remote side of a UR controller's port 30004.

Sequence, as the RTDE Guide describes it: :meth:`RtdeClient.connect` opens the
socket and negotiates protocol version 2; then :meth:`~RtdeClient.controller_version`,
:meth:`~RtdeClient.setup_outputs` (frequency and variable names),
:meth:`~RtdeClient.setup_inputs`, :meth:`~RtdeClient.start`; then
:meth:`~RtdeClient.receive` returns each output data package (or
:meth:`~RtdeClient.receive_latest` the newest, skipping those a slow reader missed) and
:meth:`~RtdeClient.send` writes inputs; :meth:`~RtdeClient.pause` stops the
stream. Text messages from the controller are kept in
:attr:`~RtdeClient.messages` (the newest ``MESSAGES_KEPT``).

Errors name the controller's address (``host:port``):

- no answer within ``timeout_s``: :class:`~drivers.errors.DriverTimeoutError`;
- a refused protocol version, start or pause, or a recipe with variables
  NOT_FOUND or IN_USE: :class:`~drivers.ur.errors.RtdeRefusedError`
  (the names listed);
- a package that does not decode (truncated, oversized, unknown type or
  recipe), or a connection that closes inside a package:
  :class:`~drivers.errors.MalformedPacketError`;
- a connection refused, reset or closed between packages:
  :class:`~drivers.errors.LinkLostError`.
"""

from __future__ import annotations

import select
import socket
from collections import deque
from collections.abc import Mapping, Sequence
from typing import Final, TypeVar

import numpy as np

from drivers.base.guards import requires_open
from drivers.errors import DriverTimeoutError, LinkLostError, MalformedPacketError
from drivers.ur.errors import RtdeRefusedError
from drivers.ur.rtde import codec
from drivers.ur.rtde.codec import PackageType
from drivers.ur.rtde.fields import FIELD_TYPES, IN_USE, NOT_FOUND, Recipe

#: The controller's RTDE port (fixed on a real controller).
RTDE_PORT: Final = 30004
MESSAGES_KEPT: Final = 100

M = TypeVar("M")


class RtdeClient:
    """One RTDE connection to ``host:port``; every error names that address."""

    def __init__(self, host: str, port: int = RTDE_PORT, *, timeout_s: float = 1.0) -> None:
        self.host = host
        self.port = port
        self.timeout_s = timeout_s
        self.address = f"{host}:{port}"
        self.messages: deque[codec.TextMessage] = deque(maxlen=MESSAGES_KEPT)
        self.output_recipes: dict[int, Recipe] = {}
        self.input_recipes: dict[int, Recipe] = {}
        self.streaming = False
        self.received = 0
        self.skipped = 0
        self.skipped_on_pause = 0
        self._sock: socket.socket | None = None
        self._framer = codec.Framer(self.address)
        self._rx = bytearray(65536)

    @property
    def is_open(self) -> bool:
        return self._sock is not None

    # ------------------------------------------------------------------ connection

    def connect(self, protocol_version: int = codec.PROTOCOL_VERSION) -> None:
        """Open the connection and negotiate ``protocol_version`` (only 2 is implemented)."""
        if self._sock is not None:
            return
        try:
            sock = socket.create_connection((self.host, self.port), timeout=self.timeout_s)
        except TimeoutError:
            raise DriverTimeoutError(
                f"{self.address}: no RTDE controller answered the connection within "
                f"{self.timeout_s:g} s") from None
        except OSError as exc:
            raise LinkLostError(
                f"{self.address}: cannot connect to the RTDE controller: "
                f"{exc.strerror or exc}") from None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock = sock
        self._framer = codec.Framer(self.address)
        try:
            reply = self._request(codec.RequestProtocolVersion(protocol_version),
                                  codec.Accepted, f"protocol version {protocol_version}")
            if not reply.accepted:
                raise RtdeRefusedError(self.address, f"protocol version {protocol_version}",
                                       "the controller does not speak it" + self._last_words())
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Close the socket (no pause is sent; the controller drops the recipes)."""
        sock, self._sock = self._sock, None
        self.streaming = False
        if sock is not None:
            sock.close()

    def __enter__(self) -> RtdeClient:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ setup

    @requires_open("RTDE client")
    def controller_version(self) -> codec.ControllerVersion:
        """URControl's version (major, minor, bugfix, build)."""
        return self._request(codec.GetControllerVersion(), codec.ControllerVersion,
                             "the controller version")

    @requires_open("RTDE client")
    def setup_outputs(self, names: Sequence[str], frequency_hz: float) -> Recipe:
        """Set up an output recipe; refused names raise :class:`RtdeRefusedError`."""
        reply = self._request(codec.SetupOutputs(float(frequency_hz), tuple(names)),
                              codec.RecipeReply, "an output recipe")
        recipe = self._recipe(reply, tuple(names), "output recipe")
        self.output_recipes[recipe.recipe_id] = recipe
        return recipe

    @requires_open("RTDE client")
    def setup_inputs(self, names: Sequence[str]) -> Recipe:
        """Set up an input recipe; NOT_FOUND or IN_USE names raise :class:`RtdeRefusedError`."""
        reply = self._request(codec.SetupInputs(tuple(names)), codec.RecipeReply,
                              "an input recipe")
        recipe = self._recipe(reply, tuple(names), "input recipe")
        self.input_recipes[recipe.recipe_id] = recipe
        return recipe

    def _recipe(self, reply: codec.RecipeReply, names: tuple[str, ...], what: str) -> Recipe:
        expected = (PackageType.CONTROL_PACKAGE_SETUP_OUTPUTS if what.startswith("output")
                    else PackageType.CONTROL_PACKAGE_SETUP_INPUTS)
        if reply.request != expected:
            raise MalformedPacketError(
                self.address, "unexpected",
                f"answer to {chr(expected)!r} came as {chr(reply.request)!r}")
        for word in (NOT_FOUND, IN_USE):
            bad = tuple(n for n, t in zip(names, reply.types, strict=False) if t == word)
            if bad:
                raise RtdeRefusedError(self.address, f"an {what}",
                                       f"{word}: {', '.join(bad)}" + self._last_words(), bad)
        if len(reply.types) != len(names):
            raise MalformedPacketError(
                self.address, "bad_value",
                f"{len(names)} variables set up, {len(reply.types)} types answered")
        unknown = [t for t in reply.types if t not in FIELD_TYPES]
        if unknown:
            raise MalformedPacketError(self.address, "bad_value",
                                       f"unknown field type(s) {', '.join(unknown)}")
        if reply.recipe_id == 0:
            raise RtdeRefusedError(self.address, f"an {what}",
                                   "recipe id 0 (invalid recipe)" + self._last_words())
        return Recipe(reply.recipe_id, names, reply.types)

    @requires_open("RTDE client")
    def start(self) -> None:
        """Start the data stream (outputs at the recipe's frequency; inputs are taken)."""
        if not self._request(codec.Start(), codec.Accepted, "start").accepted:
            raise RtdeRefusedError(self.address, "start", "not accepted" + self._last_words())
        self.streaming = True

    @requires_open("RTDE client")
    def pause(self) -> None:
        """Pause the stream; data packages still in flight are counted and dropped."""
        if not self._request(codec.Pause(), codec.Accepted, "pause").accepted:
            raise RtdeRefusedError(self.address, "pause", "not accepted" + self._last_words())
        self.streaming = False

    # ------------------------------------------------------------------ data

    @requires_open("RTDE client")
    def receive(self, timeout_s: float | None = None) -> codec.DataPackage:
        """The next output data package (text messages meanwhile go to :attr:`messages`)."""
        while True:
            msg = self._read(timeout_s, "the next data package")
            if isinstance(msg, codec.DataPackage):
                self.received += 1
                return msg
            if not isinstance(msg, codec.TextMessage):
                raise MalformedPacketError(self.address, "unexpected",
                                           f"{type(msg).__name__} while streaming")

    @requires_open("RTDE client")
    def receive_latest(self, timeout_s: float | None = None) -> codec.DataPackage:
        """The newest output data package: waits for one, then takes every package that
        has already arrived and keeps the last (the others are counted in :attr:`skipped`),
        so that a reader that fell behind catches up instead of lagging."""
        newest = self.receive(timeout_s)
        sock = self._sock
        assert sock is not None
        while True:
            got = self._framer.next()
            if got is None:
                if not select.select([sock], [], [], 0.0)[0]:
                    return newest
                try:
                    n = sock.recv_into(self._rx)
                except OSError:
                    n = 0
                if n == 0:
                    return newest  # a close or reset is reported by the next call
                self._framer.feed(memoryview(self._rx)[:n])
                continue
            msg = codec.decode_from_controller(got[0], got[1], self.output_recipes, self.address)
            if isinstance(msg, codec.TextMessage):
                self.messages.append(msg)
            elif isinstance(msg, codec.DataPackage):
                self.received += 1
                self.skipped += 1
                newest = msg
            else:
                raise MalformedPacketError(self.address, "unexpected",
                                           f"{type(msg).__name__} while streaming")

    @requires_open("RTDE client")
    def send(self, recipe: Recipe, values: Mapping[str, object] | np.ndarray) -> None:
        """Send one input data package of ``recipe`` (every variable of it given)."""
        self._send(codec.package(PackageType.DATA_PACKAGE,
                                 bytes((recipe.recipe_id,)) + recipe.encode(values)))

    @requires_open("RTDE client")
    def send_message(self, message: str, source: str = "ffexp",
                     level: int = codec.MessageLevel.INFO) -> None:
        """Send a text message to the controller's log."""
        self._send(codec.encode(codec.TextMessage(message, source, level)))

    # ------------------------------------------------------------------ plumbing

    def _last_words(self) -> str:
        return f" (controller said: {self.messages[-1].message})" if self.messages else ""

    def _send(self, data: bytes) -> None:
        assert self._sock is not None
        try:
            self._sock.sendall(data)
        except TimeoutError:
            raise DriverTimeoutError(f"{self.address}: RTDE controller takes no data "
                                     f"(send blocked {self.timeout_s:g} s)") from None
        except OSError as exc:
            raise LinkLostError(
                f"{self.address}: RTDE connection lost while sending: "
                f"{exc.strerror or exc}") from None

    def _request(self, msg: codec.ClientMessage, reply_type: type[M], what: str) -> M:
        """Send ``msg`` and read until its answer; data packages meanwhile are dropped."""
        self._send(codec.encode(msg))
        while True:
            reply = self._read(None, f"the request for {what}")
            if isinstance(reply, reply_type):
                return reply
            if isinstance(reply, codec.DataPackage):
                self.skipped_on_pause += 1
                continue
            if isinstance(reply, codec.TextMessage):
                continue
            raise MalformedPacketError(self.address, "unexpected",
                                       f"{type(reply).__name__} in answer to {what}")

    def _read(self, timeout_s: float | None, what: str) -> codec.ControllerMessage:
        """The next package from the controller, decoded (text messages are also kept)."""
        sock = self._sock
        assert sock is not None
        while True:
            got = self._framer.next()
            if got is not None:
                msg = codec.decode_from_controller(got[0], got[1], self.output_recipes,
                                                   self.address)
                if isinstance(msg, codec.TextMessage):
                    self.messages.append(msg)
                return msg
            limit = self.timeout_s if timeout_s is None else timeout_s
            sock.settimeout(limit)
            try:
                n = sock.recv_into(self._rx)
            except TimeoutError:
                raise self._stall(limit, what) from None
            except OSError as exc:
                raise LinkLostError(f"{self.address}: RTDE connection lost waiting for {what}: "
                                    f"{exc.strerror or exc}") from None
            if n == 0:
                raise self._closed(what)
            self._framer.feed(memoryview(self._rx)[:n])

    def _stall(self, limit: float, what: str) -> Exception:
        if self._framer.pending:
            return MalformedPacketError(
                self.address, "truncated",
                f"{self._framer.pending} of {self._framer.pending_need()} bytes of a package "
                f"came, then nothing for {limit:g} s")
        return DriverTimeoutError(
            f"{self.address}: RTDE controller sent nothing for {limit:g} s waiting for {what}")

    def _closed(self, what: str) -> Exception:
        if self._framer.pending:
            err: Exception = MalformedPacketError(
                self.address, "truncated",
                f"connection closed after {self._framer.pending} of "
                f"{self._framer.pending_need()} bytes of a package")
        else:
            err = LinkLostError(
                f"{self.address}: RTDE controller closed the connection waiting for {what}")
        self.close()
        return err
