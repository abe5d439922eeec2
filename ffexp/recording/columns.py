"""Decoding a finished recording's messages (:mod:`ffexp.recording.chunks`) into a
:class:`~ffexp.recording.data.Recording`, a topic at once.

The same result as decoding mcap's ``Message`` objects one list per channel
(:func:`ffexp.recording.reader.load_with_mcap`): each channel's messages are put in
log-time order by a stable sort of their file order (only when they are not in order
already); a fixed-layout CDR topic is its payloads gathered into one byte array and
viewed through the message's structured dtype (:attr:`MessageSpec.dtype`: the CDR
alignment counted from after the header, no variable-length field; a schema that is not
such a flat message is skipped with a warning, as is a topic whose payloads are not all
the dtype's size), each field copied out; a JSON topic is each payload parsed as
``json.loads`` parses it (:func:`json_messages`).
"""

from __future__ import annotations

import json
import re
from json.scanner import make_scanner
from typing import Any

import numpy as np
from mcap.records import Channel, Schema

from ffexp.recording.chunks import ChannelMessages
from ffexp.recording.data import JsonData, Recording, TopicData, spec_from_schema

__all__ = ["decode_channels", "json_messages"]

#: The scanner of a default ``JSONDecoder`` (json.loads's: the same defaults), which its
#: ``raw_decode`` calls.
_SCAN = make_scanner(json.JSONDecoder())  # type: ignore[arg-type]  # a decoder is its context
_BLANKS = " \t\n\r"
_SPACE = re.compile(f"[{_BLANKS}]*")  # what json.loads skips around a document


def decode_channels(rec: Recording, channels: dict[int, Channel], schemas: dict[int, Schema],
                    messages: dict[int, ChannelMessages]) -> None:
    """Every channel of ``channels`` (in its order) into ``rec.topics`` or ``rec.json``."""
    for cid, channel in channels.items():
        msgs = messages.get(cid) or ChannelMessages()
        schema = schemas.get(channel.schema_id)
        times = msgs.log_time_ns
        order = None
        if times.size > 1 and np.any(np.diff(times) < 0):
            order = np.argsort(times, kind="stable")
            times = times[order]
        if channel.message_encoding == "cdr" and schema is not None:
            spec = spec_from_schema(schema)
            if spec is None:
                rec.warnings.append(f"{rec.path}: {channel.topic}: schema {schema.name} skipped")
                continue
            dtype = spec.dtype
            if np.any(msgs.sizes != dtype.itemsize):
                rec.warnings.append(
                    f"{rec.path}: {channel.topic}: messages do not match {schema.name}; skipped"
                )
                continue
            rows = msgs.rows(dtype.itemsize)
            if order is not None:
                rows = rows[order]
            arr = rows.view(dtype)
            rec.topics[channel.topic] = TopicData(
                times, {f.name: arr[f.name].copy() for f in spec.fields}
            )
        elif channel.message_encoding == "json":
            payloads = msgs.payloads()
            if order is not None:
                payloads = [payloads[i] for i in order.tolist()]
            try:
                decoded = json_messages(payloads)
            except (json.JSONDecodeError, UnicodeDecodeError):
                rec.warnings.append(f"{rec.path}: {channel.topic}: invalid JSON; skipped")
                continue
            rec.json[channel.topic] = JsonData(times, decoded)
        else:
            rec.warnings.append(
                f"{rec.path}: {channel.topic}: encoding {channel.message_encoding!r} skipped"
            )


def json_messages(payloads: list[bytes]) -> list[Any]:
    """``[json.loads(p) for p in payloads]``, the same values and errors, faster.

    When every payload is ASCII (so each is read as UTF-8 and a character is a byte),
    they are decoded to text at once and each is parsed where it lies in that text by
    the decoder's scanner; a payload's value must end within it, followed by nothing but
    whitespace, or the payloads are parsed one by one by ``json.loads`` (which then also
    raises what it raises for a bad one)."""
    joined = b"".join(payloads)
    if not joined.isascii() or b"\x00" in joined:
        return [json.loads(p) for p in payloads]
    text = joined.decode("ascii")
    out: list[Any] = []
    pos = 0
    for p in payloads:
        end = pos + len(p)
        first = pos if pos < end and text[pos] not in _BLANKS else _skip_space(text, pos, end)
        try:
            if first == end:
                raise StopIteration
            value, stop = _SCAN(text, first)
        except (StopIteration, json.JSONDecodeError):
            return [json.loads(p) for p in payloads]
        if stop != end and (stop > end or _skip_space(text, stop, end) != end):
            return [json.loads(p) for p in payloads]
        out.append(value)
        pos = end
    return out


def _skip_space(text: str, pos: int, end: int) -> int:
    """Where the whitespace from ``pos`` (not beyond ``end``) ends."""
    m = _SPACE.match(text, pos, end)
    return pos if m is None else m.end()
