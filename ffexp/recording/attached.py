"""Named frames fixed on a free body, written once and resolved on reading.

A simulator's truth writes a frame fixed on one of its free bodies (the funnel's
mouth on the target) not every cycle but once, as its offset in the body's frame,
on ``<prefix>/attached`` (:attr:`drivers.base.types.GroundTruth.attached`). On
reading, :func:`resolve` gives the frame its ``<prefix>/site/<name>`` topic back:
the body's pose of every cycle (``<prefix>/body/<body>``) times the offset, at the
body's log times. A recording that wrote the frame every cycle (before the
offset was written once) keeps its own topic, so both kinds read alike.
Pure: no I/O.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ffexp.recording.reader import Recording

__all__ = ["ATTACHED", "FRAME_SCHEMA", "helpers", "is_attached", "resolve", "sites_of"]

#: The last name of the topic that holds the attached frames (under the truth's prefix).
ATTACHED = "attached"
#: The schema of a named frame's topic (``<prefix>/site/<name>``).
FRAME_SCHEMA = "ffexp_msgs/msg/Frame"
_KINDS = ("truth", "body", "site")


def _prefix(topic: str) -> str | None:
    """The truth's prefix of one of its topics (``/sim`` of ``/sim/body/target``)."""
    for kind in _KINDS:
        marker = f"/{kind}"
        at = topic.rfind(marker)
        if at > 0 and (topic.endswith(marker) if kind == "truth"
                       else topic[at + len(marker):].startswith("/")):
            return topic[:at]
    return None


def is_attached(topic: str) -> bool:
    """``topic`` holds a truth's attached frames (``/sim/attached``)."""
    pre, _, last = topic.rpartition("/")
    return last == ATTACHED and bool(pre)


def helpers(wanted: list[str] | None, present: Iterable[str]) -> list[str]:
    """The topics besides ``wanted`` that resolving its frames needs (``present``: the
    file's topics): the prefix's attached frames and, for a wanted frame the file does
    not hold as a topic, every body of that prefix. Nothing when all is wanted."""
    if wanted is None:
        return []
    have = set(present)
    extra: list[str] = []
    for topic in wanted:
        pre = _prefix(topic)
        if pre is None:
            continue
        fixed = f"{pre}/{ATTACHED}"
        if fixed in have and fixed not in wanted and fixed not in extra:
            extra.append(fixed)
        if topic.startswith(f"{pre}/site/") and topic not in have:
            extra += [t for t in sorted(have) if t.startswith(f"{pre}/body/")
                      and t not in wanted and t not in extra]
    return extra


def _parse(message: object) -> dict[str, tuple[str, np.ndarray]]:
    """``{name: (body, 4x4 offset)}`` of an attached frames' message (``ValueError``: it
    is not one)."""
    try:
        frames = dict(message["frames"])  # type: ignore[index]
        return {str(name): (str(f["body"]),
                            np.asarray(f["offset"], dtype=np.float64).reshape(4, 4))
                for name, f in frames.items()}
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError("not a set of attached frames") from exc


def sites_of(messages: dict[str, bytes]) -> dict[str, str]:
    """``{site topic: body topic}`` of the attached frames' messages (JSON, by topic);
    one that is not such a message resolves nothing."""
    out: dict[str, str] = {}
    for topic, data in messages.items():
        pre = topic.rpartition("/")[0]
        try:
            frames = _parse(json.loads(data))
        except (ValueError, UnicodeDecodeError):
            continue
        out.update({f"{pre}/site/{name}": f"{pre}/body/{body}"
                    for name, (body, _offset) in frames.items()})
    return out


def resolve(rec: Recording, drop: Iterable[str] = ()) -> None:
    """Give every attached frame of ``rec`` its ``<prefix>/site/<name>`` topic (unless the
    recording has its own), then drop the topics ``drop`` (loaded only for this). A
    malformed attached message is a warning and resolves nothing."""
    for topic, data in list(rec.json.items()):
        if not is_attached(topic) or not data.messages:
            continue
        pre = topic.rpartition("/")[0]
        try:
            parsed = _parse(data.messages[-1])
        except ValueError:
            rec.warnings.append(f"{rec.path}: {topic}: not a set of attached frames; skipped")
            continue
        from ffexp.recording.reader import TopicData

        for name, (body, offset) in parsed.items():
            site = f"{pre}/site/{name}"
            poses = rec.topics.get(f"{pre}/body/{body}")
            if site in rec.topics or poses is None:
                continue
            pose = poses["pose"].reshape(-1, 4, 4) @ offset
            rec.topics[site] = TopicData(poses.log_time_ns.copy(),
                                         {"pose": pose.reshape(-1, 16)})
    for topic in drop:
        rec.topics.pop(topic, None)
        rec.json.pop(topic, None)
