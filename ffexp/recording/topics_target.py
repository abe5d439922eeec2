"""Topics of the target tracker and the alignment verdict: a group of :mod:`ffexp.recording.topics`.

Message specs and topics are defined here with the classes of
:mod:`ffexp.recording.schema`; ``topics.py`` puts them in the one registry
(``CDR_TOPICS``, ``JSON_TOPICS``), so every recorder, reader and ``ffexp topics``
sees them.
"""

from __future__ import annotations

from ffexp.recording.schema import CdrTopic, JsonTopic

CDR: tuple[CdrTopic, ...] = ()
JSON: tuple[JsonTopic, ...] = ()
