"""A Foxglove WebSocket server fed by the recorder's taps, never blocking the loop.

The control loop's thread only calls :meth:`LiveServer.tap` (a
:attr:`Recorder.taps <ffexp.recording.Recorder.taps>` callable): it decides
whether a message goes out and, if so, appends ``(topic, log time, bytes)`` to
a bounded queue (a ``collections.deque``: no lock, no wake-up of another
thread); when the queue is full the message is dropped and counted. A
publisher thread wakes every ``flush_period_s`` (20 ms), takes out what has
queued and hands it to the foxglove-sdk server (its own
:class:`foxglove.Context`, so nothing else of the process is published),
which sends it to every subscribed viewer from its own threads and drops the
oldest message per slow client (``message_backlog_size``). Waking on a timer
instead of per message keeps the loop's thread from handing the interpreter
lock to the publisher a thousand times a second (``benchmarks/bench_live.py``).

What goes out: every message of the low-rate JSON topics (events, phases,
the verdict, the 3-D scene) and, of every high-rate topic (the CDR topics and
``/tf``), at most ``rate_hz`` log-time instants per second: the first message
at or after each period, plus every further message with the same log time
(all ``/tf`` frames of one cycle share its time, so a viewer gets all of them
or none). Schemas and bytes are the file's (``ros2msg``/``cdr`` and
``jsonschema``/``json``, the names of :mod:`ffexp.recording.topics`); every
topic of the registry is advertised from the start.

After the run (``ffexp run --live``), :meth:`LiveServer.linger` keeps serving
until the viewers have left or the user stops it: a simulated run is over in
seconds, long before a person has opened the connection. A viewer who
subscribes once the run has ended gets each topic's last instant again (the
final pose on ``/tf``, the rig's 3-D scene, the verdict), repeated every
second while it watches.

Subprotocol: the foxglove-sdk server accepts only :data:`SUBPROTOCOL`
(``foxglove.sdk.v1``, the Foxglove app offers it beside the older
``foxglove.websocket.v1``); a client that offers only ``foxglove.websocket.v1``
(the ws-protocol specification's name, older viewers) is refused with
HTTP 400 before it reaches this code.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from types import TracebackType
from typing import TYPE_CHECKING, Any, cast

from drivers.base.types import NS_PER_S
from drivers.errors import AddressError
from ffexp.live.address import LiveOptions
from ffexp.recording.topics import CDR_TOPICS, JSON_TOPICS

if TYPE_CHECKING:
    import foxglove
    from foxglove.websocket import ServerListener

#: Messages the queue holds between the loop and the publisher (about 4 s of a
#: run's decimated topics at 50 Hz); more are dropped, never waited for.
QUEUE_SIZE = 4096
#: Messages the server buffers per viewer before it drops that viewer's oldest.
BACKLOG_PER_CLIENT = 1024
#: How long :meth:`LiveServer.close` waits for the server to stop.
STOP_TIMEOUT_S = 2.0
#: How often the publisher hands what has queued to the server [s].
FLUSH_PERIOD_S = 0.02
#: The WebSocket subprotocol the foxglove-sdk server (0.30) accepts; a viewer must offer it.
SUBPROTOCOL = "foxglove.sdk.v1"
#: How often :meth:`LiveServer.linger` looks at its stop condition [s].
LINGER_POLL_S = 0.1
#: After the run: how often each subscribed topic's last instant goes out again [s].
REPEAT_PERIOD_S = 1.0


def _decimated_topics() -> frozenset[str]:
    """High-rate topics: every CDR topic and ``/tf``."""
    return frozenset((*CDR_TOPICS, "/tf"))


class LiveServer:
    """The live view of one run. :meth:`start`, give :meth:`tap` to the recorder,
    :meth:`close` when the run has ended (also as a context manager).

    Args:
        options: address, port (0: any free one) and rate per high-rate topic.
        queue_size: bound of the queue between the loop and the publisher.
        flush_period_s: how often the publisher empties the queue.
    """

    def __init__(self, options: LiveOptions, *, queue_size: int = QUEUE_SIZE,
                 flush_period_s: float = FLUSH_PERIOD_S) -> None:
        if not options.rate_hz > 0.0:
            raise ValueError(f"{options.where}: rate_hz must be positive")
        self.options = options
        self.period_ns = max(1, round(NS_PER_S / options.rate_hz))
        self.queue_size = queue_size
        self.flush_period_s = flush_period_s
        self._queue: deque[tuple[str, int, bytes]] = deque()
        self._stop = threading.Event()
        self._wake = threading.Event()  # sets the publisher going before its period is up
        self._decimated = _decimated_topics()
        self._next_ns: dict[str, int] = {}
        self._last_ns: dict[str, int] = {}
        self._server: Any = None
        self._thread: threading.Thread | None = None
        self._channels: dict[str, foxglove.Channel] = {}
        self.dropped = 0
        """Messages the full queue refused (the loop never waits for the viewer)."""
        self.queued = 0
        """Messages handed to the publisher."""
        self.published = 0
        """Messages the publisher gave the server."""
        self.error = ""
        """The publisher's first failure ('' when none); it goes on with the next message."""
        self._lock = threading.Lock()
        self._subscribed: set[tuple[int, int]] = set()  # (client id, channel id)
        self._viewers_changed = threading.Event()
        self._ever_viewed = False
        self._ended = False  # the run has ended: new subscribers get each topic's last instant
        self._latched: dict[str, tuple[int, list[bytes]]] = {}
        self._resend: deque[int] = deque()  # channel ids a late viewer subscribed to
        self._topic_of: dict[int, str] = {}
        self._next_repeat = 0.0

    # -- lifetime -------------------------------------------------------------
    def start(self) -> None:
        """Bind and start serving; a bad or busy address is an :class:`AddressError`."""
        import foxglove

        opts = self.options
        self._context = foxglove.Context()
        try:
            self._server = foxglove.start_server(
                name="ffexp", host=opts.host, port=opts.port, context=self._context,
                message_backlog_size=BACKLOG_PER_CLIENT,
                server_listener=cast("ServerListener", _Listener(self)),
            )
        except RuntimeError as exc:
            reason = str(exc).removeprefix("FoxgloveError: ")
            raise AddressError(opts.where, opts.address, reason) from None
        # every topic's channel now, before a viewer can connect: a channel created while
        # a viewer is connected is advertised to it before the server accepts subscribing
        # to it (foxglove-sdk 0.30: "unknown channel"), and a viewer that subscribes at
        # once would never get that topic
        # (a family's topics, ``/sim/body/*``, are named by the run: each gets its channel
        # with its first message)
        for topic in (*CDR_TOPICS, *JSON_TOPICS):
            if not topic.endswith("/*"):
                self._add_channel(topic)
        self._thread = threading.Thread(target=self._publish, name="ffexp-live", daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        """The port the server listens on (the free one chosen for port 0)."""
        if self._server is None:
            return self.options.port
        return int(self._server.port)

    @property
    def url(self) -> str:
        """``ws://HOST:PORT``, what Foxglove's "Open connection" asks for."""
        host = self.options.host
        host = f"[{host}]" if ":" in host else host
        return f"ws://{host}:{self.port}"

    def end_run(self) -> None:
        """The run has ended: from now on a viewer that subscribes to a topic gets its
        last instant again (the publisher still empties the queue first)."""
        self._ended = True
        self._wake.set()

    def linger(self, stop_requested: Callable[[], bool]) -> str:
        """After the run: serve until the viewers have left (a viewer came, during or after
        the run, and none is left) or ``stop_requested()`` (Ctrl-C); returns which."""
        self.end_run()
        while True:
            if stop_requested():
                return "stopped"
            with self._lock:
                left = self._ever_viewed and not self._subscribed
            if left:
                return "the viewer disconnected"
            self._viewers_changed.wait(LINGER_POLL_S)
            self._viewers_changed.clear()

    def app_url(self) -> str:
        """The Foxglove web app's address that opens this server ('' once it stopped)."""
        if self._server is None:
            return ""
        return str(self._server.app_url() or "")

    def close(self) -> None:
        """Publish what is queued, stop the publisher and the server; idempotent."""
        thread, self._thread = self._thread, None
        if thread is not None:
            self._stop.set()  # the publisher empties the queue once more, then ends
            self._wake.set()
            thread.join()
        for channel in self._channels.values():
            channel.close()
        self._channels.clear()
        server, self._server = self._server, None
        if server is not None:
            # foxglove-sdk 0.30's stop() waits for a client that opened a connection
            # but never finished its WebSocket handshake: bounded here, never the run's end
            stopper = threading.Thread(target=server.stop, name="ffexp-live-stop", daemon=True)
            stopper.start()
            stopper.join(STOP_TIMEOUT_S)
            if stopper.is_alive():
                self.error = self.error or (
                    f"the server did not stop within {STOP_TIMEOUT_S:g} s (a client connected "
                    "without finishing its WebSocket handshake); left to the process's exit")

    def __enter__(self) -> LiveServer:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # -- the loop's side ------------------------------------------------------
    def tap(self, topic: str, log_time_ns: int, data: bytes) -> None:
        """A message the recorder wrote: queue it if it is due, never wait."""
        fast = topic in self._decimated or CDR_TOPICS.family(topic) is not None
        if fast and log_time_ns != self._last_ns.get(topic):
            if log_time_ns < self._next_ns.get(topic, log_time_ns):
                return
            self._next_ns[topic] = log_time_ns + self.period_ns
            self._last_ns[topic] = log_time_ns
        if len(self._queue) >= self.queue_size:
            self.dropped += 1
            return
        self._queue.append((topic, log_time_ns, data))  # only this thread appends
        self.queued += 1

    # -- the publisher's side -------------------------------------------------
    def _publish(self) -> None:
        pending = self._queue
        latched = self._latched
        while True:
            self._wake.wait(self.flush_period_s)
            self._wake.clear()
            stopping = self._stop.is_set()
            while pending:
                topic, log_time_ns, data = pending.popleft()
                last = latched.get(topic)
                if last is not None and last[0] == log_time_ns:
                    last[1].append(data)
                else:
                    latched[topic] = (log_time_ns, [data])
                self._log(topic, log_time_ns, data)
            if self._ended and not stopping:
                self._repeat_last_instant()
            if stopping:
                return

    def _repeat_last_instant(self) -> None:
        """After the run: each subscribed topic's last instant again, at once for a new
        subscription and every :data:`REPEAT_PERIOD_S` for all (the server calls
        ``on_subscribe`` just before it routes the channel to the new viewer, so a message
        logged at once may miss it; the repetition makes sure it does not)."""
        now = time.monotonic()
        channels: set[int] = set()
        while self._resend:
            channels.add(self._resend.popleft())
        if now >= self._next_repeat:
            self._next_repeat = now + REPEAT_PERIOD_S
            with self._lock:
                channels.update(channel for _, channel in self._subscribed)
        for channel_id in channels:
            topic = self._topic_of[channel_id]
            log_time_ns, messages = self._latched.get(topic, (0, []))
            for data in messages:
                self._log(topic, log_time_ns, data)

    def _add_channel(self, topic: str) -> foxglove.Channel:
        channel = self._channels[topic] = self._channel(topic)
        self._topic_of[channel.id()] = topic
        return channel

    def _log(self, topic: str, log_time_ns: int, data: bytes) -> None:
        try:
            channel = self._channels.get(topic)
            if channel is None:
                channel = self._add_channel(topic)
            channel.log(data, log_time=log_time_ns)
            self.published += 1
        except Exception as exc:  # a viewer must never end the run
            self.error = self.error or f"{topic}: {exc}"

    # -- the server's side (its own threads) ---------------------------------------------
    def _subscribe(self, client_id: int, channel_id: int) -> None:
        with self._lock:
            self._subscribed.add((client_id, channel_id))
            self._ever_viewed = True
        if self._ended:
            self._resend.append(channel_id)  # the publisher's next tick: after the routing
        self._viewers_changed.set()

    def _unsubscribe(self, client_id: int, channel_id: int) -> None:
        with self._lock:
            self._subscribed.discard((client_id, channel_id))
        self._viewers_changed.set()

    def _channel(self, topic: str) -> foxglove.Channel:
        """The topic's channel with the recording's schema and encoding."""
        import foxglove

        if topic in CDR_TOPICS:
            spec = CDR_TOPICS[topic].spec
            schema = foxglove.Schema(name=spec.name, encoding="ros2msg",
                                     data=spec.ros2msg.encode())
            encoding = "cdr"
        else:
            jt = JSON_TOPICS[topic]
            schema = foxglove.Schema(name=jt.schema_name, encoding="jsonschema",
                                     data=jt.schema_bytes)
            encoding = "json"
        return foxglove.Channel(topic, schema=schema, message_encoding=encoding,
                                context=self._context)



class _Listener:
    """The server's callbacks (the two of foxglove's ``ServerListener`` protocol it
    needs; the server calls only those a listener has): who watches what. A
    disconnecting viewer is unsubscribed from every channel it had."""

    def __init__(self, server: LiveServer) -> None:
        self._server = server

    def on_subscribe(self, client: Any, channel: Any) -> None:
        self._server._subscribe(int(client.id), int(channel.id))

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        self._server._unsubscribe(int(client.id), int(channel.id))
